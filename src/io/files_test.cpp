#include "io/files.h"

#include <sys/stat.h>

#include <gtest/gtest.h>

#include "core/error.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {
namespace fs = std::filesystem;

size_t CountEntries(const fs::path& dir) {
  size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}

TEST(Files, WriteFileAtomicLeavesOnlyTheFile) {
  testing::TempDir tmp;
  const fs::path p = tmp / "sub/dir/a.bin";  // parents are created
  const std::string bytes("abc\0def", 7);
  WriteFileAtomic(p, bytes);
  EXPECT_EQ(ReadFileToString(p), bytes);
  WriteFileAtomic(p, "replaced");
  EXPECT_EQ(ReadFileToString(p), "replaced");
  EXPECT_EQ(CountEntries(tmp / "sub/dir"), 1u);  // no *.tmp-* siblings left
}

TEST(Files, ReadMissingFileNamesIt) {
  testing::TempDir tmp;
  try {
    ReadFileToString(tmp / "missing.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.txt"), std::string::npos);
    EXPECT_EQ(e.where(), tmp / "missing.txt");
  }
  EXPECT_THROW(ReadFileToString(tmp.path()), InputError);  // a directory
}

TEST(Files, AFifoOrADeviceIsNotReadAsData) {
  // A FIFO named as a sweep blocked for ever; /dev/zero ended in std::bad_alloc with no file named.
  testing::TempDir tmp;
  const fs::path fifo = tmp / "sweep.pcd.bin";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (const fs::path& p : {fifo, fs::path("/dev/zero")}) {
    try {
      ReadFileToString(p);
      ADD_FAILURE() << p;
    } catch (const InputError& e) {
      EXPECT_EQ(e.where(), p);
      EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
    }
  }
}

TEST(Files, TemporarySiblingsAreDistinct) {
  const fs::path a = TemporarySibling("/x/y/out.json"), b = TemporarySibling("/x/y/out.json");
  EXPECT_NE(a, b);
  EXPECT_EQ(a.parent_path(), fs::path("/x/y"));
  EXPECT_EQ(a.filename().string().rfind("out.json.tmp-", 0), 0u);
}

TEST(Files, StagingWithoutCommitLeavesNothing) {
  testing::TempDir tmp;
  const fs::path out = tmp / "run";
  {
    StagingDirectory stage(out, false);
    WriteFileAtomic(stage.path() / "x.txt", "x");
    EXPECT_TRUE(fs::exists(stage.path() / "x.txt"));
    EXPECT_FALSE(fs::exists(out));
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(CountEntries(tmp.path()), 0u);  // temporary tree removed
}

TEST(Files, StagingCommitPublishes) {
  testing::TempDir tmp;
  const fs::path out = tmp / "run";
  {
    StagingDirectory stage(out, false);
    WriteFileAtomic(stage.path() / "x.txt", "x");
    stage.Commit();
  }
  EXPECT_EQ(ReadFileToString(out / "x.txt"), "x");
  EXPECT_EQ(CountEntries(tmp.path()), 1u);
}

TEST(Files, StagingRefusesExistingOutputUnlessOverwrite) {
  testing::TempDir tmp;
  const fs::path out = tmp / "run";
  WriteFileAtomic(out / "old.txt", "old");
  try {
    StagingDirectory stage(out, false);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("run"), std::string::npos);
  }
  EXPECT_EQ(ReadFileToString(out / "old.txt"), "old");
  {
    // With overwrite, the old tree stays intact until Commit ...
    StagingDirectory stage(out, true);
    WriteFileAtomic(stage.path() / "new.txt", "new");
    EXPECT_TRUE(fs::exists(out / "old.txt"));
    EXPECT_FALSE(fs::exists(out / "new.txt"));
    stage.Commit();
  }
  // ... and is replaced as a whole at Commit, leaving no temporaries.
  EXPECT_FALSE(fs::exists(out / "old.txt"));
  EXPECT_EQ(ReadFileToString(out / "new.txt"), "new");
  EXPECT_EQ(CountEntries(tmp.path()), 1u);
  {
    // Overwrite without Commit: the existing output is untouched.
    StagingDirectory stage(out, true);
    WriteFileAtomic(stage.path() / "other.txt", "o");
  }
  EXPECT_EQ(ReadFileToString(out / "new.txt"), "new");
  EXPECT_FALSE(fs::exists(out / "other.txt"));
  EXPECT_EQ(CountEntries(tmp.path()), 1u);
}

// The message RefuseOutputOverInputs gives, or "" when it lets `out` through.
std::string OverInputs(const fs::path& out, const std::vector<fs::path>& inputs) {
  try {
    RefuseOutputOverInputs(out, inputs);
    return "";
  } catch (const InputError& e) {
    return e.what();
  }
}

TEST(Files, OutputOverInputsIsRefused) {
  testing::TempDir tmp;
  const fs::path log = tmp / "log", info = log / "info" / "x.json", photo = tmp / "photo.png";
  WriteFileAtomic(info, "{}");
  WriteFileAtomic(photo, "png");
  // The output is an input file, an input folder, holds one, or lies inside one: all refused.
  EXPECT_NE(OverInputs(photo, {photo}).find("is the input file"), std::string::npos);
  EXPECT_NE(OverInputs(log, {log}).find("is the input folder"), std::string::npos);
  EXPECT_NE(OverInputs(tmp.path(), {log}).find("holds the input"), std::string::npos);
  EXPECT_NE(OverInputs(log / "info", {info}).find("holds the input"), std::string::npos);
  EXPECT_NE(OverInputs(log / "out", {log}).find("lies inside the input folder"), std::string::npos);
  // Other spellings of the same place: "..", a trailing separator, a relative path, a symlink.
  EXPECT_NE(OverInputs(log / "info" / ".." / "info" / "x.json", {info}), "");
  EXPECT_NE(OverInputs(fs::path(log.string() + "/"), {info}), "");
  fs::create_symlink(log, tmp / "link");
  EXPECT_NE(OverInputs(tmp / "link", {info}), "");
  EXPECT_NE(OverInputs(tmp / "link" / "info" / "x.json", {info}), "");
  const fs::path cwd = fs::current_path();
  fs::current_path(tmp.path());
  EXPECT_NE(OverInputs("log", {info}), "");
  EXPECT_NE(OverInputs("photo.png", {tmp / "photo.png"}), "");
  fs::current_path(cwd);
  // Siblings, names sharing a prefix, and missing inputs pass.
  EXPECT_EQ(OverInputs(tmp / "out", {log, photo}), "");
  EXPECT_EQ(OverInputs(tmp / "lo", {log}), "");
  EXPECT_EQ(OverInputs(tmp / "logs", {log}), "");
  EXPECT_EQ(OverInputs(tmp / "photo.png.x2.png", {photo}), "");
  EXPECT_EQ(OverInputs(tmp / "nothing", {tmp / "nothing" / "missing.bin"}), "");
  // The message names the output first, as every located error does.
  EXPECT_EQ(OverInputs(photo, {photo}).rfind(photo.string(), 0), 0u);
}

TEST(Json, DeepNestingAndOutOfRangeNumbersAreLocatedErrors) {
  // 100,000-deep lists in a scenario comment parsed, then overflowed the stack when synth.json was written;
  // 1e999 printed the JSON library's own message with no file.
  testing::TempDir tmp;
  const fs::path deep = tmp / "deep.json", huge = tmp / "huge.json", fine = tmp / "fine.json";
  WriteFileAtomic(deep, "{\"_c\": " + std::string(100000, '[') + std::string(100000, ']') + "}");
  WriteFileAtomic(huge, R"({"m": [[1e999]]})");
  WriteFileAtomic(fine, "{\"a\": \"[[[[ \\\" {{\", \"b\": " + std::string(kMaxJsonDepth - 1, '[') +
                            std::string(kMaxJsonDepth - 1, ']') + "}");
  for (const auto& [file, problem] : {std::pair{deep, "nested deeper than 512 levels"}, std::pair{huge, "number overflow"}}) {
    try {
      ReadJsonFile(file);
      ADD_FAILURE() << file;
    } catch (const InputError& e) {
      EXPECT_EQ(e.where(), file);
      EXPECT_NE(std::string(e.what()).find(problem), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find("json.exception"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(ReadJsonFile(fine));  // brackets inside strings, escaped quotes, and nesting at the limit
}

TEST(JsonLines, CallsBackPerLineAndNamesTheBadLine) {
  sd::testing::TempDir tmp;
  const fs::path file = tmp / "x.jsonl";
  WriteFileAtomic(file, "{\"a\": 1}\n\n  \n[2, 3]\n{\"b\": tru}\n");
  std::vector<std::string> wheres;
  try {
    ForEachJsonLine(file, [&](const nlohmann::json& j, const std::string& where) {
      wheres.push_back(where);
      EXPECT_TRUE(j.is_object() || j.is_array());
    });
    FAIL() << "line 5 is not JSON";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(file.string() + ":5: malformed JSON", 0), 0u) << e.what();
  }
  ASSERT_EQ(wheres.size(), 2u);  // blank lines skipped, line numbers kept
  EXPECT_EQ(wheres[1], file.string() + ":4");
}

}  // namespace
}  // namespace sd
