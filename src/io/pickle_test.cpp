#include "io/pickle.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

#include "core/error.h"
#include "io/files.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd::pickle {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using namespace std::string_literals;

// --- the Python oracle (tools/testing/pickle_oracle.py under /usr/bin/python3 with numpy and pandas)

// The oracle with these arguments; exit status, output in *output.
int RunOracle(const std::vector<std::string>& args, std::string* output) {
  return testing::RunPython("tools/testing/pickle_oracle.py", args, output);
}

// --- the tagged form of pickle_oracle.py (see its docstring): equal tags mean equal Python values and types

json TagFloat(double d) {
  if (std::isnan(d)) return json::array({"float", "nan"});
  int64_t bits;
  std::memcpy(&bits, &d, 8);
  return json::array({"float", bits});
}

std::string DTypeTag(const Array& a) {
  return a.dtype == DType::kUnicode ? "U" + std::to_string(a.itemsize / 4) : DTypeName(a.dtype);
}

json Tagged(const Value& v);

json TagElement(const Array& a, int64_t i) {
  if (IsFloat(a.dtype)) return TagFloat(a.AsDouble(i));
  if (a.dtype == DType::kUInt64) return json::array({"int", a.At<uint64_t>(i)});
  if (IsInteger(a.dtype)) return json::array({"int", a.AsInt(i)});
  if (a.dtype == DType::kBool) return a.At<bool>(i);
  if (a.dtype == DType::kUnicode) return json::array({"str", a.StringAt(i)});
  return Tagged(a.ObjectAt(i));
}

json Tagged(const Value& v) {
  static const char* kHex = "0123456789abcdef";
  json items = json::array();
  switch (v.kind()) {
    case Kind::kNone: return nullptr;
    case Kind::kBool: return v.AsBool();
    case Kind::kInt: return json::array({"int", v.AsInt()});
    case Kind::kFloat: return TagFloat(v.AsDouble());
    case Kind::kStr: return json::array({"str", v.AsString()});
    case Kind::kBytes: {
      std::string hex;
      for (unsigned char c : v.AsBytes()) hex += kHex[c >> 4], hex += kHex[c & 15];
      return json::array({"bytes", hex});
    }
    case Kind::kList:
    case Kind::kTuple:
      for (const Value& e : v.elements()) items.push_back(Tagged(e));
      return json::array({v.kind() == Kind::kList ? "list" : "tuple", items});
    case Kind::kDict:
      for (const auto& [k, x] : v.items()) items.push_back(json::array({Tagged(k), Tagged(x)}));
      return json::array({"dict", items});
    case Kind::kArray: {
      const Array& a = v.array();
      if (a.scalar) return json::array({"scalar", DTypeTag(a), TagElement(a, 0)});
      // numpy calls an array Fortran-ordered only when it is not also C-contiguous (two dims longer than 1).
      int long_dims = 0;
      for (int64_t d : a.shape) long_dims += d > 1;
      for (int64_t i = 0; i < a.size(); ++i) items.push_back(TagElement(a, i));
      return json::array({"array", DTypeTag(a), a.shape, a.fortran_order && long_dims >= 2 && a.size() > 0, items});
    }
    case Kind::kObject: {
      const Object& o = v.object();
      if (o.module == "builtins" && (o.name == "set" || o.name == "frozenset")) {
        for (const Value& e : o.args[0].elements()) items.push_back(Tagged(e));
        return json::array({o.name, items});
      }
      if (o.Is("builtins", "slice")) return json::array({"slice", Tagged(o.args[0]), Tagged(o.args[1]), Tagged(o.args[2])});
      return json::array({"object", o.module + "." + o.name});
    }
  }
  return nullptr;
}

// JSON equality that also tells ints from floats and compares doubles exactly; *why names the first difference.
bool SameJson(const json& a, const json& b, const std::string& path, std::string* why) {
  const auto differ = [&](const std::string& what) {
    *why = (path.empty() ? "/" : path) + ": " + what + " (" + a.dump().substr(0, 200) + " vs " + b.dump().substr(0, 200) + ")";
    return false;
  };
  if (a.is_number() && b.is_number()) {
    if (a.is_number_float() != b.is_number_float()) return differ("int vs float");
    if (a.is_number_float()) return a.get<double>() == b.get<double>() ? true : differ("different numbers");
    return a == b ? true : differ("different ints");
  }
  if (a.type() != b.type()) return differ("different types");
  if (a.is_array()) {
    if (a.size() != b.size()) return differ("different lengths");
    for (size_t i = 0; i < a.size(); ++i)
      if (!SameJson(a[i], b[i], path + "/" + std::to_string(i), why)) return false;
    return true;
  }
  if (a.is_object()) {
    if (a.size() != b.size()) return differ("different key counts");
    for (auto it = a.begin(); it != a.end(); ++it) {
      if (!b.contains(it.key())) return differ("key '" + it.key() + "' missing on the right");
      if (!SameJson(it.value(), b.at(it.key()), path + "/" + it.key(), why)) return false;
    }
    return true;
  }
  return a == b ? true : differ("different values");
}

// The twins were written by Python's json with allow_nan: NaN / Infinity tokens outside strings. ToJson writes
// null for them (JSON has no NaN), which is what they read as here.
json ReadTwin(const fs::path& file) {
  const std::string text = ReadFileToString(file);
  std::string out;
  out.reserve(text.size());
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      out.push_back(c);
      if (c == '\\') out.push_back(text[++i]);
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') in_string = true;
    for (const std::string_view token : {"-Infinity", "Infinity", "NaN"}) {
      if (text.compare(i, token.size(), token) == 0) {
        out += "null";
        i += token.size();
        break;
      }
    }
    out.push_back(text[i]);
  }
  return json::parse(out);
}

std::string ErrorOf(std::string_view bytes, const LoadOptions& options = {}) {
  try {
    Load(bytes, "x.pkl", options);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

// --- reference pickles, made once for the suite

class PickleOracle : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (testing::PandasPython().empty()) return;
    dir_ = new testing::TempDir();
    std::string output;
    status_ = RunOracle({"cases", dir_->path().string()}, &output);
    if (status_ != 0) std::cerr << output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    SD_REQUIRE_PANDAS_PYTHON();
    ASSERT_EQ(status_, 0) << "pickle_oracle.py cases failed";
  }
  static std::vector<std::string> Cases() {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_->path())) {
      const std::string f = e.path().filename().string();
      if (f.size() > 5 && f.ends_with(".json") && f.find(".refuse") == std::string::npos && f.find('.') == f.size() - 5)
        names.push_back(f.substr(0, f.size() - 5));
    }
    std::sort(names.begin(), names.end());
    return names;
  }
  static fs::path Dir() { return dir_->path(); }

  static testing::TempDir* dir_;
  static int status_;
};
testing::TempDir* PickleOracle::dir_ = nullptr;
int PickleOracle::status_ = -1;

TEST_F(PickleOracle, ReadsWhatPythonWritesInEveryProtocol) {
  const std::vector<std::string> cases = Cases();
  ASSERT_GE(cases.size(), 10u);
  for (const std::string& name : cases) {
    const json want = ReadJsonFile(Dir() / (name + ".json"));
    for (int protocol = 0; protocol <= 5; ++protocol) {
      SCOPED_TRACE(name + " protocol " + std::to_string(protocol));
      const fs::path file = Dir() / (name + ".p" + std::to_string(protocol) + ".pkl");
      const std::string bytes = ReadFileToString(file);
      EXPECT_EQ(ProtocolOf(bytes), protocol);
      Value v;
      try {
        v = Load(bytes, file);
      } catch (const InputError& e) {
        ADD_FAILURE() << e.what();
        continue;
      }
      std::string why;
      EXPECT_TRUE(SameJson(Tagged(v), want, "", &why)) << why;
    }
  }
}

TEST_F(PickleOracle, KeepsSharedReferencesShared) {
  for (int protocol = 0; protocol <= 5; ++protocol) {
    SCOPED_TRACE(protocol);
    const Value v = LoadFile(Dir() / ("shared.p" + std::to_string(protocol) + ".pkl"));
    ASSERT_EQ(v.kind(), Kind::kDict);
    const Value& a = *v.Find("a");
    EXPECT_NE(a.identity(), nullptr);
    EXPECT_EQ(a.identity(), v.Find("b")->identity());
    EXPECT_EQ(a.identity(), (*v.Find("t"))[0].identity());
    EXPECT_EQ(a.identity(), (*v.Find("t"))[1].identity());
    EXPECT_EQ(v.Find("s1")->identity(), v.Find("s2")->identity());
  }
}

TEST_F(PickleOracle, RefusesWhatWouldRunCodeAndNamesTheGlobal) {
  int refused = 0;
  for (const auto& e : fs::directory_iterator(Dir())) {
    const std::string f = e.path().filename().string();
    if (!f.ends_with(".refuse.json")) continue;
    SCOPED_TRACE(f);
    const json expect = ReadJsonFile(e.path());
    const fs::path pkl = Dir() / (f.substr(0, f.size() - std::string(".refuse.json").size()) + ".pkl");
    std::string error;
    try {
      LoadFile(pkl);
    } catch (const InputError& err) {
      error = err.what();
    }
    ASSERT_FALSE(error.empty()) << "loaded " << pkl;
    EXPECT_EQ(error.rfind(pkl.string() + ": byte ", 0), 0u) << error;
    EXPECT_NE(error.find(expect["error"].get<std::string>()), std::string::npos) << error;
    if (expect.contains("global")) {
      const std::string where = Msg() << pkl.string() << ": byte " << expect["offset"].get<int64_t>()
                                      << ": refusing to load global '" << expect["global"].get<std::string>() << "'";
      EXPECT_EQ(error.rfind(where, 0), 0u) << error << "\nwant " << where;
      EXPECT_NE(error.find("(pickles are read as data; only numpy, pandas and container classes are allowed)"),
                std::string::npos);
    }
    EXPECT_FALSE(fs::exists(expect["marker"].get<std::string>())) << "the payload ran";
    ++refused;
  }
  EXPECT_GE(refused, 6 * 9);
  // The classic payload, by hand: GLOBAL 'os system', MARK, STRING, TUPLE, REDUCE, STOP.
  const fs::path marker = Dir() / "pwned-by-hand";
  const std::string payload = "cos\nsystem\n(S'touch " + marker.string() + "'\ntR.";
  EXPECT_EQ(ErrorOf(payload),
            "x.pkl: byte 0: refusing to load global 'os.system' (pickles are read as data; only numpy, pandas and "
            "container classes are allowed)");
  EXPECT_NE(ErrorOf("\x80\x04\x8c\x08\x62uiltins\x8c\x04\x65val\x93."), "");
  EXPECT_NE(ErrorOf("\x80\x04\x8c\x08\x62uiltins\x8c\x04\x65val\x93.").find("byte 18: refusing to load global 'builtins.eval'"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(marker));
}

// A value built here (not loaded) with what the writer must carry over: numpy scalar types, F order, uint64.
Value CppValue() {
  Array f32 = Array::Of<float>({1.5f, -2.0f, 3.25f, 0.1f, 1e30f, -0.0f}, {2, 3});
  Array fortran = Array::Of<double>({1, 2, 3, 4, 5, 6}, {3, 2});
  fortran.fortran_order = true;
  Array half = Array::Zeros(DType::kFloat16, {2});
  half.data = std::string("\x00\x3e\x00\xfc", 4);  // 1.5, -inf
  Object slice{"builtins", "slice", Value::Tuple({Value::Int(1), Value::Int(5), Value::None()}), Value(),
               Object::Via::kReduce};
  Object set{"builtins", "set", Value::Tuple({Value::List({Value::Int(1), Value::Int(2)})}), Value(),
             Object::Via::kReduce};
  const Value shared = Value::List({Value::Str("shared")});
  return Value::Dict({
      {Value::Str("f32"), Value::FromArray(f32)},
      {Value::Str("fortran"), Value::FromArray(fortran)},
      {Value::Str("half"), Value::FromArray(half)},
      {Value::Str("i8"), Value::FromArray(Array::Of<int8_t>({-128, 127}))},
      {Value::Str("u64"), Value::FromArray(Array::Of<uint64_t>({0, ~uint64_t(0)}))},
      {Value::Str("bools"), Value::FromArray(Array::Of<bool>({true, false, true}))},
      {Value::Str("names"), Value::FromArray(Array::Unicode({"car", "p\xc3\xa9" "destrian", ""}))},
      {Value::Str("objects"), Value::FromArray(Array::Objects({Value::Str("a"), Value::None(), Value::Float(2.5)}))},
      {Value::Str("np_f32"), Value::FromArray(Array::Scalar(0.1f))},
      {Value::Str("np_u64"), Value::FromArray(Array::Scalar(~uint64_t(0)))},
      {Value::Str("np_bool"), Value::FromArray(Array::Scalar(true))},
      {Value::Int(7), Value::Tuple({Value::Float(NAN), Value::Float(-0.0), Value::Int(INT64_MIN), Value::Int(1ll << 40)})},
      {Value::Tuple({Value::Int(1), Value::Str("k")}), Value::Bytes(std::string("\x00\xff\x80", 3))},
      {Value::Str("slice"), Value::FromObject(slice)},
      {Value::Str("set"), Value::FromObject(set)},
      {Value::Str("shared"), Value::List({shared, shared})},
      {Value::Str("long"), Value::List(std::vector<Value>(2345, Value::Str(std::string(300, 'x'))))},
  });
}

TEST_F(PickleOracle, PythonLoadsWhatWeWrite) {
  int written = 0;
  for (const std::string& name : Cases()) {
    for (int protocol = 0; protocol <= 5; ++protocol) {
      const std::string stem = name + ".p" + std::to_string(protocol);
      const Value v = LoadFile(Dir() / (stem + ".pkl"));
      for (int out : {2, 4}) {
        const std::string bytes = Dump(v, out);
        EXPECT_EQ(ProtocolOf(bytes), out);
        WriteFileAtomic(Dir() / (stem + ".w" + std::to_string(out) + ".pkl"), bytes);
        // And we read our own output back to the same value.
        EXPECT_TRUE(Load(bytes, "ours.pkl") == v) << stem << " protocol " << out;
        ++written;
      }
    }
  }
  const Value cpp = CppValue();
  WriteJsonFile(Dir() / "cpp_values.tag.json", Tagged(cpp));
  for (int out : {2, 4}) {
    DumpFile(Dir() / ("cpp_values.w" + std::to_string(out) + ".pkl"), cpp, out, /*gzip=*/false);
    EXPECT_TRUE(LoadFile(Dir() / ("cpp_values.w" + std::to_string(out) + ".pkl")) == cpp);
  }
  std::string output;
  EXPECT_EQ(RunOracle({"check", Dir().string()}, &output), 0) << output;
  EXPECT_NE(output.find("checked " + std::to_string(written + 2) + " pickles, 0 bad"), std::string::npos) << output;
}

TEST_F(PickleOracle, GzipFilesLoadLikePlainOnes) {
  const Value cpp = CppValue();
  DumpFile(Dir() / "cpp.pkl.gz", cpp, 4, /*gzip=*/true);
  const std::string raw = ReadFileToString(Dir() / "cpp.pkl.gz");
  ASSERT_GE(raw.size(), 2u);
  EXPECT_EQ(static_cast<unsigned char>(raw[0]), 0x1f);
  EXPECT_TRUE(LoadFile(Dir() / "cpp.pkl.gz") == cpp);
  std::string output;
  ASSERT_EQ(RunOracle({"tag", (Dir() / "cpp.pkl.gz").string(), (Dir() / "cpp.gz.json").string()}, &output), 0)
      << output;
  std::string why;
  EXPECT_TRUE(SameJson(Tagged(cpp), ReadJsonFile(Dir() / "cpp.gz.json"), "", &why)) << why;
}

// --- real files

void ExpectMatchesTwin(const fs::path& pkl, const fs::path& twin) {
  SCOPED_TRACE(pkl.string());
  std::string why;
  EXPECT_TRUE(SameJson(ToJson(LoadFile(pkl)), ReadTwin(twin), "", &why)) << why;
}

TEST(PickleRealFiles, RepoPklsReadToTheirJsonTwins) {
  for (const char* rel : {"driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800",
                          "driving/nuscenes-scene0061-kf0/bevfusion_demo_info/nuscenes_infos_test"}) {
    const fs::path stem = testing::RepoData(rel);
    ExpectMatchesTwin(stem.string() + ".pkl", stem.string() + ".json");
  }
}

TEST(PickleRealFiles, SharedPklsReadToTheirJsonTwins) {
  SD_REQUIRE_SHARED(root, "driving");
  int twins = 0;
  for (const auto& e : fs::recursive_directory_iterator(root)) {
    if (e.path().extension() != ".pkl") continue;
    fs::path twin = e.path();
    twin.replace_extension(".json");
    if (!fs::exists(twin)) continue;
    ExpectMatchesTwin(e.path(), twin);
    ++twins;
  }
  EXPECT_GE(twins, 10);
}

TEST(PickleRealFiles, EveryPklReadsAsPythonReadsIt) {
  SD_REQUIRE_PANDAS_PYTHON();
  std::vector<fs::path> files = {testing::RepoData("driving/kitti-mmdet3d-pkl-000008/v0x_format/kitti_000008_infos.pkl"),
                                 testing::RepoData("driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.pkl"),
                                 testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.pkl")};
  if (const fs::path shared = testing::SharedData("driving"); !shared.empty()) {
    for (const auto& e : fs::recursive_directory_iterator(shared))
      if (e.path().extension() == ".pkl") files.push_back(e.path());
  }
  testing::TempDir tmp;
  for (const fs::path& pkl : files) {
    SCOPED_TRACE(pkl.string());
    std::string output;
    ASSERT_EQ(RunOracle({"tag", pkl.string(), (tmp / "tag.json").string()}, &output), 0) << output;
    std::string why;
    EXPECT_TRUE(SameJson(Tagged(LoadFile(pkl)), ReadJsonFile(tmp / "tag.json"), "", &why)) << why;
    // Protocol 2 like the original, and 4: both read back equal.
    const Value v = LoadFile(pkl);
    EXPECT_TRUE(Load(Dump(v, 2), "2.pkl") == v);
    EXPECT_TRUE(Load(Dump(v, 4), "4.pkl") == v);
  }
}

// --- hostile input

TEST(PickleHostile, EveryTruncationIsALocatedError) {
  const fs::path file = testing::RepoData("driving/kitti-mmdet3d-pkl-000008/v0x_format/kitti_000008_infos.pkl");
  const std::string bytes = ReadFileToString(file);
  ASSERT_GT(bytes.size(), 4000u);
  for (size_t n = 0; n < bytes.size(); ++n) {
    const std::string error = ErrorOf(std::string_view(bytes).substr(0, n));
    ASSERT_EQ(error.rfind("x.pkl: byte ", 0), 0u) << "cut at " << n << ": '" << error << "'";
  }
  EXPECT_EQ(ErrorOf(bytes), "");
}

TEST(PickleHostile, RandomCorruptionNeverCrashes) {
  // A small deterministic fuzz: 1-4 random bytes replaced in real pickles. Each variant loads or is refused
  // with a located InputError; anything else (another exception, a crash, a hang) fails.
  std::vector<std::string> seeds = {
      ReadFileToString(testing::RepoData("driving/kitti-mmdet3d-pkl-000008/v0x_format/kitti_000008_infos.pkl")),
      ReadFileToString(testing::RepoData("driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.pkl"))};
  seeds.push_back(Dump(Load(seeds[0], "s"), 4));
  seeds.push_back(Dump(CppValue(), 2));
  std::mt19937 rng(12345);
  int refused = 0, total = 0;
  for (const std::string& seed : seeds) {
    for (int round = 0; round < 1500; ++round) {
      std::string bytes = seed;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int k = 0; k < edits; ++k) bytes[rng() % bytes.size()] = static_cast<char>(rng() & 0xff);
      const std::string error = ErrorOf(bytes);
      if (!error.empty()) {
        ++refused;
        ASSERT_EQ(error.rfind("x.pkl: byte ", 0), 0u) << error;
      }
      ++total;
    }
  }
  EXPECT_GT(refused, total / 4);
}

std::string Repeat(const std::string& s, int n) {
  std::string out;
  for (int i = 0; i < n; ++i) out += s;
  return out;
}

TEST(PickleHostile, RefusesWithALocatedError) {
  const auto expect = [](const std::string& bytes, const std::string& what, const LoadOptions& options = {}) {
    const std::string error = ErrorOf(bytes, options);
    EXPECT_EQ(error.rfind("x.pkl: byte ", 0), 0u) << error;
    EXPECT_NE(error.find(what), std::string::npos) << "'" << error << "' lacks '" << what << "'";
  };
  // A declared length far beyond the file: refused before anything is allocated.
  expect(std::string("\x80\x04X\x00\x00\x00\x80", 7) + std::string(13, 'a'), "byte 2: truncated: BINUNICODE needs 2147483648 bytes");
  expect(std::string("\x80\x04\x8e\xff\xff\xff\xff\xff\xff\xff\x7f", 11), "truncated");
  expect(std::string("\x80\x04\x95\x00\x00\x00\x00\x01\x00\x00\x00.", 12), "FRAME");
  expect(std::string("\x80\x02T\xff\xff\xff\xff.", 8), "negative length");
  // Deep nesting: 100,000 lists by EMPTY_LIST + APPEND, by MARK + LIST, tuples, dicts.
  expect("\x80\x02" + Repeat("]", 100000) + Repeat("a", 99999) + ".", "nesting deeper than 200 levels");
  expect("\x80\x02" + Repeat("(", 100000) + Repeat("l", 100000) + ".", "nesting deeper than 200 levels");
  expect(std::string("\x80\x02)") + Repeat("\x85", 100000) + ".", "nesting deeper than 200 levels");
  expect("\x80\x02" + Repeat("}K\x01", 100000) + "}" + Repeat("s", 100000) + ".", "nesting deeper than 200 levels");
  LoadOptions shallow;
  shallow.max_depth = 3;
  expect("\x80\x02]]]]aaa.", "nesting deeper than 3 levels", shallow);
  EXPECT_EQ(ErrorOf("\x80\x02]]]aa.", shallow), "");
  // Memo.
  expect("\x80\x02h\x05.", "byte 2: memo key 5 is not defined");
  expect(std::string("\x80\x02j\x00\x00\x00\x10.", 8), "memo key 268435456 is not defined");
  LoadOptions small_memo;
  small_memo.max_memo = 10;
  expect("\x80\x04]" + Repeat("\x94", 11) + ".", "more than 10 memo entries", small_memo);
  // Opcodes and the stack.
  expect("\x80\x02\xff.", "byte 2: unknown opcode 0xff");
  expect("\x80\x06N.", "unsupported pickle protocol 6");
  expect("\x80\x02" "a.", "stack underflow");
  expect("\x80\x02N(a.", "stack underflow");  // the list below the MARK is out of reach, as in CPython
  expect("\x80\x02]N(a.", "stack underflow");
  expect("\x80\x02]e.", "no MARK");
  expect("\x80\x02(N.", "STOP with an open MARK");
  expect("\x80\x02NN.", "STOP with 2 values on the stack");
  expect("\x80\x02.", "STOP with 0 values");
  expect("\x80\x02N.junk", "byte 4: 4 bytes after STOP");
  expect("\x80\x02N", "no STOP");
  expect("\x80\x02\x82\x01.", "EXT");
  expect("\x80\x02Pid\n.", "persistent IDs");
  expect("\x80\x05\x97.", "out-of-band");
  expect("\x80\x02NNNs.", "SETITEM on a None");
  expect("\x80\x02}]Ns.", "unhashable dict key (a list)");
  expect("\x80\x02}(]K\x01u.", "unhashable dict key");
  expect("\x80\x02N)R.", "REDUCE on a None");
  expect("\x80\x02]Nb.", "BUILD on a list");
  // Cycles: a list in itself, a dict in itself, a list in a list in itself.
  expect("\x80\x02]q\x00h\x00"s "a."s, "a value inside itself"s);
  expect("\x80\x02}q\x00K\x01h\x00s."s, "a value inside itself"s);
  expect("\x80\x02]q\x00]h\x00"s "aa."s, "already inside another value"s);
  expect("\x80\x04\x8f\x94(h\x00\x90."s, "inside itself"s);
  // Ints: LONG4 within int64 is fine (CPython only writes it for > 255 bytes), beyond is refused.
  EXPECT_EQ(Load(std::string("\x80\x02\x8b\x02\x00\x00\x00\x01\x02.", 10), "x").AsInt(), 0x0201);
  EXPECT_EQ(Load(std::string("\x80\x02\x8a\x09\xff\xff\xff\xff\xff\xff\xff\xff\xff.", 14), "x").AsInt(), -1);
  expect(std::string("\x80\x02\x8a\x09\x00\x00\x00\x00\x00\x00\x00\x00\x01.", 14), "outside int64");
  EXPECT_EQ(Load(std::string("\x80\x02\x8a\x08\x00\x00\x00\x00\x00\x00\x00\x80.", 13), "x").AsInt(), INT64_MIN);
  expect("I99999999999999999999\n.", "outside int64");
  expect("L-99999999999999999999L\n.", "outside int64");
  expect("Fnot-a-float\n.", "not a number");
  // Strings: invalid UTF-8 and lone surrogates.
  expect(std::string("\x80\x04\x8c\x02\xc3\x28.", 7), "invalid UTF-8");
  expect(std::string("\x80\x04\x8c\x03\xed\xa0\x80.", 8), "invalid UTF-8");
  expect("V\\ud800\n.", "surrogate");
  // numpy: data that does not fill the shape.
  std::string array = Dump(Value::FromArray(Array::Of<double>({1, 2, 3})), 4);
  const size_t at = array.find("K\x03\x85");
  ASSERT_NE(at, std::string::npos);
  array[at + 1] = 4;
  expect(array, "numpy data has 24 bytes, 4 float64 elements of 8 bytes need 32");
  array[at + 1] = 3;
  EXPECT_EQ(ErrorOf(array), "");
}

// --- Value, Array and ToJson without Python

TEST(PickleValue, CopiesOnWriteAndCannotContainItself) {
  Value a = Value::List({Value::Int(1)});
  Value b = a;
  b.Append(Value::Int(2));
  EXPECT_EQ(a.size(), 1u);
  EXPECT_EQ(b.size(), 2u);
  b.Append(b);  // appends the old b: no cycle
  ASSERT_EQ(b.size(), 3u);
  EXPECT_EQ(b[2].size(), 2u);
  EXPECT_NE(b[2].identity(), b.identity());
  b.SetItem(0, Value::Str("x"));
  EXPECT_EQ(b[0].AsString(), "x");
  EXPECT_EQ(b[2][0].AsInt(), 1);

  Value d = Value::Dict({{Value::Int(1), Value::Str("one")}, {Value::Float(1.0), Value::Str("replaced")}});
  ASSERT_EQ(d.size(), 1u);  // 1 == 1.0, as in Python; the first key stays
  EXPECT_EQ(d.items()[0].first.kind(), Kind::kInt);
  EXPECT_EQ(d.Find(Value::Bool(true))->AsString(), "replaced");
  for (int i = 0; i < 100; ++i) d.Set(std::string("k").append(std::to_string(i)), Value::Int(i));  // past the hash index threshold
  d.Set("k42", Value::Int(-42));
  EXPECT_EQ(d.size(), 101u);
  EXPECT_EQ(d.Find("k42")->AsInt(), -42);
  EXPECT_EQ(d.items()[43].first.AsString(), "k42");
  EXPECT_EQ(d.Find("nope"), nullptr);
  EXPECT_EQ(d.Find(Value::Tuple({Value::Int(1)})), nullptr);
  const Value e = d;
  d.Set("k0", Value::None());
  EXPECT_EQ(e.Find("k0")->AsInt(), 0);

  EXPECT_THROW(Value::Int(1).AsString(), InputError);
  EXPECT_THROW(Value::Str("s").AsDouble(), InputError);
  EXPECT_DOUBLE_EQ(Value::FromArray(Array::Scalar(1.5f)).AsDouble(), 1.5);
  EXPECT_EQ(Value::FromArray(Array::Scalar<int16_t>(-3)).AsInt(), -3);
  EXPECT_TRUE(Value::FromArray(Array::Scalar(true)).AsBool());
  EXPECT_EQ(Value::FromArray(Array::Unicode({"h\xc3\xa9"})).kind(), Kind::kArray);
  EXPECT_TRUE(Value::Float(NAN) == Value::Float(NAN));
  EXPECT_FALSE(Value::Float(0.0) == Value::Float(-0.0));
}

TEST(PickleValue, ArraysIndexInCOrderWhateverTheLayout) {
  // [[0, 1, 2], [3, 4, 5]] stored column-major: 0 3 1 4 2 5.
  Array f = Array::Of<int32_t>({0, 3, 1, 4, 2, 5}, {2, 3});
  f.fortran_order = true;
  for (int i = 0; i < 6; ++i) EXPECT_EQ(f.AsInt(i), i);
  EXPECT_EQ(f.ToDoubles(), (std::vector<double>{0, 1, 2, 3, 4, 5}));
  const Array c = f.ToCOrder();
  EXPECT_FALSE(c.fortran_order);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(c.At<int32_t>(i), i);
  EXPECT_TRUE(Value::FromArray(f) == Value::FromArray(c));
  const Array u = Array::Unicode({"ab", "\xe6\x97\xa5", ""});
  EXPECT_EQ(u.itemsize, 8);
  EXPECT_EQ(u.StringAt(0), "ab");
  EXPECT_EQ(u.StringAt(1), "\xe6\x97\xa5");
  EXPECT_EQ(u.StringAt(2), "");
  Array half = Array::Zeros(DType::kFloat16, {3});
  half.data = std::string("\x00\x3c\x01\x00\x00\x7e", 6);  // 1, the smallest subnormal, NaN
  EXPECT_EQ(half.AsDouble(0), 1.0);
  EXPECT_EQ(half.AsDouble(1), std::ldexp(1.0, -24));
  EXPECT_TRUE(std::isnan(half.AsDouble(2)));
  EXPECT_THROW(Array::Of<uint64_t>({~uint64_t(0)}).AsInt(0), InputError);
}

TEST(PickleToJson, ConvertsAsPythonsJsonDoes) {
  Array f = Array::Of<double>({0, 3, 1, 4, 2, NAN}, {2, 3});
  f.fortran_order = true;
  const Value v = Value::Dict({
      {Value::Str("t"), Value::Tuple({Value::Int(1), Value::Float(2.5), Value::Bool(true), Value::None()})},
      {Value::Int(12), Value::Float(INFINITY)},
      {Value::Float(1.5), Value::Str("s")},
      {Value::Float(1e16), Value::Int(0)},
      {Value::Bool(false), Value::Int(0)},
      {Value::None(), Value::Int(0)},
      {Value::Str("f"), Value::FromArray(f)},
      {Value::Str("d0"), Value::FromArray(Array::Scalar(2.5f))},
      {Value::Str("u"), Value::FromArray(Array::Unicode({"a", "bc"}))},
      {Value::Str("o"), Value::FromArray(Array::Objects({Value::Str("x"), Value::None()}))},
      {Value::Str("u64"), Value::FromArray(Array::Of<uint64_t>({~uint64_t(0)}))},
  });
  const json want = json::parse(R"({"t": [1, 2.5, true, null], "12": null, "1.5": "s", "1e+16": 0, "false": 0,
      "null": 0, "f": [[0.0, 1.0, 2.0], [3.0, 4.0, null]], "d0": 2.5, "u": ["a", "bc"], "o": ["x", null],
      "u64": [18446744073709551615]})");
  std::string why;
  EXPECT_TRUE(SameJson(ToJson(v), want, "", &why)) << why << "\n" << ToJson(v).dump();
  try {
    ToJson(Value::Dict({{Value::Str("a"), Value::List({Value::Bytes("x")})}}));
    ADD_FAILURE() << "bytes converted";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/a/0: bytes have no JSON form");
  }
  EXPECT_THROW(ToJson(Value::Dict({{Value::Tuple({}), Value::None()}})), InputError);
}

}  // namespace
}  // namespace sd::pickle
