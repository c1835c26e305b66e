#include "bank/bank.h"

#include <csignal>
#include <cstdio>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include "assetgen/asset.h"
#include "assetgen/canonical.h"
#include "core/error.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "io/mesh_io.h"
#include "testing/testing.h"

namespace sd::bank {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

// A canonical asset folder from one of the repo's meshes (what `synthdrive asset import` does).
fs::path ImportRepoAsset(const fs::path& root, const std::string& name, const std::string& category, double height) {
  CanonicalizeOptions o;
  o.up = "+y";
  o.target_height = height;
  const CanonicalizeResult c = Canonicalize(LoadMesh(testing::RepoData("assets/" + name + "/scene.gltf")), o);
  Asset a;
  a.mesh = c.mesh;
  a.mesh.ComputeVertexNormals();
  a.info.id = name;
  a.info.name = name;
  a.info.category = category;
  a.info.extent = c.extent;
  a.info.licence = "see data/assets/" + name + "/license.txt";
  a.info.source = "data/assets/" + name;
  a.info.attribution = "MetaDrive";
  a.info.stages = nlohmann::json::array({{{"stage", "import"}, {"version", "test"}}});
  a.info.quality = {{"views", 0}};
  SaveAsset(a, root / name, false);
  return root / name;
}

// An axis-aligned box asset resting on z = 0, with a solid-colour preview (so the colour CLIP sees `rgb`).
fs::path BoxAsset(const fs::path& root, const std::string& id, const std::string& category,
                  const Eigen::Vector3d& extent, const nlohmann::json& quality = nlohmann::json::object(),
                  const std::array<uint8_t, 3>& rgb = {128, 128, 128}, const std::string& name = "") {
  Asset a;
  TriangleMesh& m = a.mesh;
  const Eigen::Vector3f h = (0.5 * extent).cast<float>();
  for (int i = 0; i < 8; ++i)
    m.positions.emplace_back((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? 2 * h.z() : 0.0f);
  const int f[12][3] = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                        {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  for (const auto& t : f) m.faces.emplace_back(t[0], t[1], t[2]);
  m.ComputeVertexNormals();
  a.info.id = id;
  a.info.name = name.empty() ? id : name;
  a.info.category = category;
  a.info.extent = extent;
  a.info.source = "bank_test";
  a.info.licence = "CC0-1.0";
  a.info.quality = quality;
  SaveAsset(a, root / id, true);
  ImageU8 preview(64, 64, 3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x)
      for (int c = 0; c < 3; ++c) preview.at(x, y, c) = rgb[c];
  WriteImage(root / id / "preview.png", preview);
  return root / id;
}

std::vector<std::string> Ids(const std::vector<BankEntry>& entries) {
  std::vector<std::string> ids;
  for (const BankEntry& e : entries) ids.push_back(e.id);
  return ids;
}

std::string IntegrityCheck(const fs::path& bank) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open_v2(bank.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  std::string result;
  sqlite3_stmt* s = nullptr;
  EXPECT_EQ(sqlite3_prepare_v2(db, "PRAGMA integrity_check", -1, &s, nullptr), SQLITE_OK);
  while (sqlite3_step(s) == SQLITE_ROW) result += reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
  sqlite3_finalize(s);
  sqlite3_close(db);
  return result;
}

int64_t CountRows(const fs::path& bank, const std::string& table) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open_v2(bank.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  const std::string sql = "SELECT count(*) FROM " + table;
  EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr), SQLITE_OK);
  EXPECT_EQ(sqlite3_step(s), SQLITE_ROW);
  const int64_t n = sqlite3_column_int64(s, 0);
  sqlite3_finalize(s);
  sqlite3_close(db);
  return n;
}

TEST(Bank, Sha256MatchesTheFips180Vectors) {
  TempDir tmp;
  WriteFileAtomic(tmp / "abc", "abc");
  EXPECT_EQ(Sha256File(tmp / "abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  WriteFileAtomic(tmp / "empty", "");
  EXPECT_EQ(Sha256File(tmp / "empty"), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  // Longer than one 1 MiB read: a million 'a's (FIPS 180-2 appendix B.3).
  WriteFileAtomic(tmp / "million", std::string(1000000, 'a'));
  EXPECT_EQ(Sha256File(tmp / "million"), "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST(Bank, AddListShowRoundTripOnRepoAssets) {
  TempDir tmp;
  const fs::path cone = ImportRepoAsset(tmp.path() / "assets", "metadrive_traffic_cone", "traffic_cone", 0.7);
  const fs::path barrier = ImportRepoAsset(tmp.path() / "assets", "metadrive_road_barrier", "barrier", 0.9);
  Bank bank = Bank::Open(tmp / "bank.sqlite", true);
  EXPECT_EQ(bank.Add(barrier).status, AddStatus::kAdded);
  const AddResult r = bank.Add(cone);
  EXPECT_EQ(r.id, "metadrive_traffic_cone");
  EXPECT_EQ(r.status, AddStatus::kAdded);

  const std::vector<BankEntry> all = bank.Query({});
  EXPECT_EQ(Ids(all), (std::vector<std::string>{"metadrive_road_barrier", "metadrive_traffic_cone"}));

  // Reopened from the file: every asset.json field and every file's size and hash as on disk.
  Bank again = Bank::Open(tmp / "bank.sqlite", false);
  const BankEntry e = again.Show("metadrive_traffic_cone");
  const Asset a = LoadAsset(cone);
  EXPECT_EQ(e.dir, fs::canonical(cone));
  EXPECT_TRUE(e.dir.is_absolute());
  EXPECT_EQ(e.category, "traffic_cone");
  EXPECT_EQ(e.name, a.info.name);
  for (int k = 0; k < 3; ++k) EXPECT_DOUBLE_EQ(e.extent[k], a.info.extent[k]);
  EXPECT_NEAR(e.extent.z(), 0.7, 1e-6);
  EXPECT_EQ(e.source, "data/assets/metadrive_traffic_cone");
  EXPECT_EQ(e.licence, a.info.licence);
  EXPECT_EQ(e.attribution, "MetaDrive");
  EXPECT_EQ(e.stages, a.info.stages);
  EXPECT_EQ(e.quality, a.info.quality);
  EXPECT_EQ(e.added_at.size(), 20u);  // 2026-01-01T00:00:00Z
  EXPECT_TRUE(e.clip_embedding.empty());
  ASSERT_EQ(e.files.size(), 3u);
  const char* names[3] = {"asset.json", "mesh.glb", "preview.png"};
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(e.files[i].path, names[i]);
    EXPECT_EQ(e.files[i].size, static_cast<int64_t>(fs::file_size(cone / names[i])));
    EXPECT_EQ(e.files[i].sha256, Sha256File(cone / names[i]));
  }
  const nlohmann::json j = BankEntryToJson(e, true);
  EXPECT_EQ(j["files"].size(), 3u);
  EXPECT_EQ(j["extent_m"][2].get<double>(), e.extent.z());
  EXPECT_THROW(bank.Show("nope"), InputError);
  EXPECT_EQ(IntegrityCheck(tmp / "bank.sqlite"), "ok");
}

TEST(Bank, QueryByCategoryExtentQualityAndLimit) {
  TempDir tmp;
  Bank bank = Bank::Open(tmp / "bank.sqlite", true);
  bank.Add(BoxAsset(tmp.path(), "cone_small", "traffic_cone", {0.3, 0.3, 0.5}, {{"views", 6}, {"loss", 0.1}}));
  bank.Add(BoxAsset(tmp.path(), "cone_large", "traffic_cone", {0.4, 0.4, 1.0}, {{"views", 2}, {"loss", 0.3}}));
  bank.Add(BoxAsset(tmp.path(), "cone_none", "traffic_cone", {0.35, 0.35, 0.7}));
  bank.Add(BoxAsset(tmp.path(), "barrier_a", "barrier", {2.5, 0.5, 1.0}, {{"views", 6}}));

  BankQuery q;
  q.category = "traffic_cone";
  EXPECT_EQ(Ids(bank.Query(q)), (std::vector<std::string>{"cone_large", "cone_none", "cone_small"}));
  q.max_extent = Eigen::Vector3d(1, 1, 0.7);  // inclusive: 0.7 m tall passes
  EXPECT_EQ(Ids(bank.Query(q)), (std::vector<std::string>{"cone_none", "cone_small"}));
  q.category.clear();
  q.max_extent.reset();
  q.min_extent = Eigen::Vector3d(0.35, 0, 0.6);
  EXPECT_EQ(Ids(bank.Query(q)), (std::vector<std::string>{"barrier_a", "cone_large", "cone_none"}));
  q.min_extent.reset();
  q.min_quality = {{"views", 6}};
  EXPECT_EQ(Ids(bank.Query(q)), (std::vector<std::string>{"barrier_a", "cone_small"}));
  q.min_quality.clear();
  q.max_quality = {{"loss", 0.2}};  // entries without the figure fail the filter
  EXPECT_EQ(Ids(bank.Query(q)), (std::vector<std::string>{"cone_small"}));
  BankQuery l;
  l.limit = 2;
  EXPECT_EQ(Ids(bank.Query(l)), (std::vector<std::string>{"barrier_a", "cone_large"}));
  BankQuery none;
  none.category = "car";
  EXPECT_TRUE(bank.Query(none).empty());
  BankQuery text;
  text.text = "red";
  EXPECT_THROW(bank.Query(text), InputError);  // no CLIP model given
}

TEST(Bank, TheQualityGateRefusesAssetsBelowItNamingTheFigureAndQueriesFilterOnTheFigures) {
  TempDir tmp;
  Bank bank = Bank::Open(tmp / "bank.sqlite", true);
  const QualityGate gate = DefaultQualityGate();
  AddOptions gated;
  gated.gate = &gate;
  const nlohmann::json good = {{"watertight", 1}, {"heldout_silhouette_iou", 0.8}, {"lidar_p2m_median_m", 0.012},
                               {"real_texture_fraction", 0.4}};
  bank.Add(BoxAsset(tmp.path(), "good", "traffic_cone", {0.4, 0.4, 0.7}, good), gated);
  // An imported mesh carries none of the figures: nothing to check.
  bank.Add(BoxAsset(tmp.path(), "imported", "traffic_cone", {0.4, 0.4, 0.7}), gated);
  nlohmann::json off_its_returns = good;
  off_its_returns["lidar_p2m_median_m"] = 0.09;
  try {
    bank.Add(BoxAsset(tmp.path(), "off", "traffic_cone", {0.4, 0.4, 0.7}, off_its_returns), gated);
    FAIL() << "an asset 9 cm off its own returns entered the bank";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("off/asset.json"), std::string::npos) << what;
    EXPECT_NE(what.find("lidar_p2m_median_m 0.09 > 0.05"), std::string::npos) << what;
  }
  nlohmann::json holed = good;
  holed["watertight"] = 0;
  EXPECT_THROW(bank.Add(BoxAsset(tmp.path(), "holed", "traffic_cone", {0.4, 0.4, 0.7}, holed), gated), InputError);
  EXPECT_EQ(Ids(bank.Query({})), (std::vector<std::string>{"good", "imported"}));
  // The user moves the bar; without a gate anything loadable goes in.
  QualityGate lenient = gate;
  ParseGateRule("lidar_p2m_median_m<=0.1", "--gate", &lenient);
  AddOptions lenient_options;
  lenient_options.gate = &lenient;
  bank.Add(tmp / "off", lenient_options);
  bank.Add(tmp / "holed");
  EXPECT_THROW(ParseGateRule("watertight=1", "--gate", &lenient), InputError);
  EXPECT_THROW(ParseGateRule(">=1", "--gate", &lenient), InputError);
  EXPECT_THROW(ParseGateRule("iou>=high", "--gate", &lenient), InputError);
  // Queries filter on the same figures.
  BankQuery q;
  q.max_quality = {{"lidar_p2m_median_m", 0.05}};
  EXPECT_EQ(Ids(bank.Query(q)), (std::vector<std::string>{"good", "holed"}));
  EXPECT_EQ(GateFailure(good, gate), std::nullopt);
}

TEST(Bank, VerifyFindsChangedMissingAndUnloadableFiles) {
  TempDir tmp;
  Bank bank = Bank::Open(tmp / "bank.sqlite", true);
  for (const char* id : {"intact", "edited", "no_preview", "corrupt"})
    bank.Add(BoxAsset(tmp.path(), id, "barrier", {2, 0.5, 1}));
  VerifyReport clean = bank.Verify();
  EXPECT_EQ(clean.entries, 4u);
  EXPECT_EQ(clean.files, 12u);
  EXPECT_TRUE(clean.problems.empty());

  // Same size, still loadable, one byte different (the glTF generator string).
  std::string glb = ReadFileToString(tmp / "edited/mesh.glb");
  const size_t at = glb.find("synthdrive");
  ASSERT_NE(at, std::string::npos);
  glb[at] = 'S';
  WriteFileAtomic(tmp / "edited/mesh.glb", glb);
  ASSERT_NO_THROW(LoadAsset(tmp / "edited"));
  fs::remove(tmp / "no_preview/preview.png");
  WriteFileAtomic(tmp / "corrupt/mesh.glb", "glTF garbage");

  const VerifyReport r = bank.Verify();
  EXPECT_EQ(r.entries, 4u);
  std::map<std::string, std::vector<std::string>> by_id;
  for (const VerifyProblem& p : r.problems) by_id[p.id].push_back(fs::path(p.path).filename().string() + ": " + p.what);
  EXPECT_EQ(by_id.count("intact"), 0u);
  EXPECT_EQ(by_id["edited"], (std::vector<std::string>{"mesh.glb: SHA-256 changed"}));
  EXPECT_EQ(by_id["no_preview"], (std::vector<std::string>{"preview.png: missing"}));
  ASSERT_EQ(by_id["corrupt"].size(), 2u);
  EXPECT_EQ(by_id["corrupt"][0].rfind("mesh.glb: size changed", 0), 0u) << by_id["corrupt"][0];
  EXPECT_EQ(by_id["corrupt"][1].rfind("corrupt: not loadable: ", 0), 0u) << by_id["corrupt"][1];

  const VerifyReport one = bank.Verify({"intact"});
  EXPECT_EQ(one.entries, 1u);
  EXPECT_TRUE(one.problems.empty());
  EXPECT_THROW(bank.Verify({"nope"}), InputError);
}

TEST(Bank, ReAddIsIdempotentAndChangedContentNeedsReplace) {
  TempDir tmp;
  Bank bank = Bank::Open(tmp / "bank.sqlite", true);
  const fs::path dir = BoxAsset(tmp.path(), "crate", "barrier", {1, 1, 1});
  EXPECT_EQ(bank.Add(dir).status, AddStatus::kAdded);
  const BankEntry first = bank.Show("crate");
  EXPECT_EQ(bank.Add(dir).status, AddStatus::kUnchanged);
  EXPECT_EQ(bank.Add(dir / "asset.json").status, AddStatus::kUnchanged);
  EXPECT_EQ(bank.Show("crate").added_at, first.added_at);
  EXPECT_EQ(CountRows(tmp / "bank.sqlite", "assets"), 1);
  EXPECT_EQ(CountRows(tmp / "bank.sqlite", "files"), 3);

  BoxAsset(tmp.path(), "crate", "barrier", {1, 1, 1}, {}, {128, 128, 128}, "Renamed crate");
  try {
    bank.Add(dir);
    ADD_FAILURE() << "changed contents were accepted without replace";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("already in the bank"), std::string::npos) << e.what();
  }
  EXPECT_EQ(bank.Show("crate").name, "crate");
  AddOptions replace;
  replace.replace = true;
  EXPECT_EQ(bank.Add(dir, replace).status, AddStatus::kReplaced);
  EXPECT_EQ(bank.Show("crate").name, "Renamed crate");
  EXPECT_EQ(bank.Show("crate").files[0].sha256, Sha256File(dir / "asset.json"));
  EXPECT_EQ(CountRows(tmp / "bank.sqlite", "files"), 3);

  // Not an asset folder: refused, nothing catalogued.
  fs::create_directories(tmp / "empty");
  EXPECT_THROW(bank.Add(tmp / "empty"), InputError);
  EXPECT_EQ(CountRows(tmp / "bank.sqlite", "assets"), 1);
}

TEST(Bank, RemoveDropsTheEntryAndOptionallyTheFolder) {
  TempDir tmp;
  Bank bank = Bank::Open(tmp / "bank.sqlite", true);
  const fs::path keep = BoxAsset(tmp.path(), "keep", "barrier", {1, 1, 1});
  const fs::path drop = BoxAsset(tmp.path(), "drop", "barrier", {1, 1, 1});
  bank.Add(keep);
  bank.Add(drop);
  bank.Remove("keep", false);
  EXPECT_TRUE(fs::exists(keep / "asset.json"));
  bank.Remove("drop", true);
  EXPECT_FALSE(fs::exists(drop));
  EXPECT_TRUE(bank.Query({}).empty());
  EXPECT_EQ(CountRows(tmp / "bank.sqlite", "files"), 0);
  EXPECT_THROW(bank.Remove("keep", false), InputError);
}

TEST(Bank, OpenRefusesMissingAndForeignFiles) {
  TempDir tmp;
  EXPECT_THROW(Bank::Open(tmp / "none.sqlite", false), InputError);
  EXPECT_FALSE(fs::exists(tmp / "none.sqlite"));
  WriteFileAtomic(tmp / "notes.txt", "my notes, not a bank\n");
  EXPECT_THROW(Bank::Open(tmp / "notes.txt", true), InputError);
  EXPECT_EQ(ReadFileToString(tmp / "notes.txt"), "my notes, not a bank\n");
  // An SQLite file of something else is not taken over either.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((tmp / "other.sqlite").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "CREATE TABLE t(x)", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  try {
    Bank::Open(tmp / "other.sqlite", true);
    ADD_FAILURE() << "a foreign SQLite file was opened as a bank";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not a SynthDrive bank"), std::string::npos) << e.what();
  }
}

// Two processes adding to one bank at once, each with its own connection: every add lands.
TEST(Bank, ConcurrentProcessesBothLand) {
  TempDir tmp;
  const int per_child = 6;
  auto folder = [&](int c, int i) {
    return tmp.path() / (Msg() << "c" << c).str() / (Msg() << "a" << c << "_" << i).str();
  };
  for (int c = 0; c < 2; ++c)
    for (int i = 0; i < per_child; ++i)
      BoxAsset(folder(c, i).parent_path(), folder(c, i).filename().string(), "barrier", {1, 1, 1.0 + 0.1 * i});
  Bank::Open(tmp / "bank.sqlite", true);
  // Child 0 parks inside its first transaction (holding the write lock) until child 1 has started, so child 1
  // meets a locked bank and must wait (busy timeout) rather than fail.
  int in_txn[2], release[2];
  ASSERT_EQ(pipe(in_txn), 0);
  ASSERT_EQ(pipe(release), 0);
  std::vector<pid_t> children;
  for (int c = 0; c < 2; ++c) {
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      int rc = 0;
      try {
        Bank bank = Bank::Open(tmp / "bank.sqlite", false);
        for (int i = 0; i < per_child; ++i) {
          AddOptions o;
          if (c == 0 && i == 0)
            o.inside_transaction = [&] {
              char x = 'x';
              if (write(in_txn[1], &x, 1) != 1 || read(release[0], &x, 1) != 1) _exit(4);
            };
          if (bank.Add(folder(c, i), o).status != AddStatus::kAdded) rc = 3;
        }
      } catch (const std::exception& e) {
        std::fprintf(stderr, "child %d: %s\n", c, e.what());
        rc = 2;
      }
      _exit(rc);
    }
    children.push_back(pid);
    if (c == 0) {
      char x = 0;
      ASSERT_EQ(read(in_txn[0], &x, 1), 1);  // child 0 holds the write lock now
    }
  }
  // Not a timing assertion: only gives child 1 time to reach the lock before child 0 lets go.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_EQ(write(release[1], "x", 1), 1);
  for (pid_t pid : children) {
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "child status " << status;
  }
  Bank bank = Bank::Open(tmp / "bank.sqlite", false);
  EXPECT_EQ(bank.Query({}).size(), 2u * per_child);
  EXPECT_EQ(CountRows(tmp / "bank.sqlite", "files"), 3 * 2 * per_child);
  EXPECT_TRUE(bank.Verify().problems.empty());
  EXPECT_EQ(IntegrityCheck(tmp / "bank.sqlite"), "ok");
}

// A process killed (SIGKILL) inside its add transaction leaves the catalogue as it was.
TEST(Bank, KilledMidAddLeavesTheCatalogueIntact) {
  TempDir tmp;
  const fs::path before = BoxAsset(tmp.path(), "before", "barrier", {1, 1, 1});
  const fs::path victim = BoxAsset(tmp.path(), "victim", "barrier", {2, 1, 1});
  Bank::Open(tmp / "bank.sqlite", true).Add(before);
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    close(fds[0]);
    try {
      Bank bank = Bank::Open(tmp / "bank.sqlite", false);
      AddOptions o;
      o.inside_transaction = [&] {
        const char c = 'x';
        if (write(fds[1], &c, 1) != 1) _exit(4);
        for (;;) pause();  // rows written, not committed: wait for the kill
      };
      bank.Add(victim, o);
    } catch (...) {
    }
    _exit(5);
  }
  close(fds[1]);
  char c = 0;
  ASSERT_EQ(read(fds[0], &c, 1), 1);  // the child is inside the transaction
  close(fds[0]);
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);

  Bank bank = Bank::Open(tmp / "bank.sqlite", false);
  EXPECT_EQ(Ids(bank.Query({})), (std::vector<std::string>{"before"}));
  EXPECT_EQ(CountRows(tmp / "bank.sqlite", "files"), 3);
  EXPECT_EQ(IntegrityCheck(tmp / "bank.sqlite"), "ok");
  // The dead writer's lock is gone: the same add now succeeds.
  EXPECT_EQ(bank.Add(victim).status, AddStatus::kAdded);
  EXPECT_EQ(Ids(bank.Query({})), (std::vector<std::string>{"before", "victim"}));
}

TEST(Bank, QueryFromJson) {
  const nlohmann::json j = nlohmann::json::parse(R"({"bank": "assets.sqlite", "category": "traffic_cone",
    "min_extent": [0.2, 0.2, 0.5], "max_extent": [1, 1, 1.2], "text": "red cone",
    "min_quality": {"views": 6}, "max_quality": {"loss": 0.2}, "limit": 10})");
  fs::path bank_path;
  const BankQuery q = BankQueryFromJson(j, "/scenarios/s.json", &bank_path);
  EXPECT_EQ(bank_path, fs::path("/scenarios/assets.sqlite"));
  EXPECT_EQ(q.category, "traffic_cone");
  ASSERT_TRUE(q.min_extent && q.max_extent);
  EXPECT_EQ(*q.min_extent, Eigen::Vector3d(0.2, 0.2, 0.5));
  EXPECT_EQ(*q.max_extent, Eigen::Vector3d(1, 1, 1.2));
  EXPECT_EQ(q.text, "red cone");
  EXPECT_EQ(q.min_quality.at("views"), 6);
  EXPECT_EQ(q.max_quality.at("loss"), 0.2);
  EXPECT_EQ(q.limit, 10u);
  const BankQuery empty = BankQueryFromJson(nlohmann::json::object(), "s.json", &bank_path);
  EXPECT_TRUE(bank_path.empty());
  EXPECT_TRUE(empty.category.empty() && !empty.min_extent && empty.limit == 0);

  auto error = [](const char* text) {
    try {
      BankQueryFromJson(nlohmann::json::parse(text), "s.json");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error(R"({"categroy": "car"})").find("unknown key 'categroy'"), std::string::npos);
  EXPECT_NE(error(R"({"min_extent": [1, 2]})").find("min_extent"), std::string::npos);
  EXPECT_NE(error(R"({"limit": -1})").find("limit"), std::string::npos);
  EXPECT_NE(error(R"({"min_quality": {"views": "six"}})").find("views"), std::string::npos);
  EXPECT_EQ(error(R"({"min_quality": {"views": "six"}})").rfind("s.json", 0), 0u);
}

// The tiny colour CLIP (tools/testing/make_mining_test_models.py): "red" must rank the red asset first.
TEST(Bank, TextQueryRanksByClipSimilarity) {
  SD_REQUIRE_TEST_MODEL(dir, "clip_colour");
  const models::ClipEncoder clip = models::ClipEncoder::Load(dir);
  TempDir tmp;
  Bank bank = Bank::Open(tmp / "bank.sqlite", true);
  AddOptions o;
  o.clip = &clip;
  bank.Add(BoxAsset(tmp.path(), "a_blue", "traffic_cone", {0.4, 0.4, 0.7}, {}, {30, 30, 230}), o);
  bank.Add(BoxAsset(tmp.path(), "b_green", "traffic_cone", {0.4, 0.4, 0.7}, {}, {30, 200, 30}), o);
  bank.Add(BoxAsset(tmp.path(), "c_red", "traffic_cone", {0.4, 0.4, 0.7}, {}, {230, 30, 30}), o);
  bank.Add(BoxAsset(tmp.path(), "d_plain", "traffic_cone", {0.4, 0.4, 0.7}));  // no embedding: not ranked

  const BankEntry red = bank.Show("c_red");
  EXPECT_EQ(red.clip_embedding.size(), 4u);
  EXPECT_EQ(red.clip_model, clip.Describe());
  BankQuery q;
  q.text = "red";
  const std::vector<BankEntry> r = bank.Query(q, &clip);
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r[0].id, "c_red");
  EXPECT_GT(*r[0].score, 0.7f);  // chroma (0.52, -0.26, -0.26) vs the r axis: 0.82
  EXPECT_LT(*r[1].score, 0.1f);
  q.text = "blue";
  q.limit = 1;
  EXPECT_EQ(Ids(bank.Query(q, &clip)), (std::vector<std::string>{"a_blue"}));
  // Re-adding with the model embeds an entry added without one; the files are unchanged.
  EXPECT_EQ(bank.Add(tmp / "d_plain", o).status, AddStatus::kUnchanged);
  EXPECT_EQ(bank.Show("d_plain").clip_embedding.size(), 4u);
  // A bank without any embedding cannot answer a text query.
  Bank plain = Bank::Open(tmp / "plain.sqlite", true);
  plain.Add(BoxAsset(tmp / "p", "grey", "traffic_cone", {0.4, 0.4, 0.7}));
  EXPECT_THROW(plain.Query(q, &clip), InputError);
}

}  // namespace
}  // namespace sd::bank
