#include "io/pandas_frame.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "io/files.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd::pandas {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using pickle::Array;
using pickle::DType;
using pickle::Kind;
using pickle::Value;

// --- the Python oracle (tools/testing/pickle_oracle.py; see pickle_test.cpp)

// The oracle with these arguments; exit status, output in *output.
int RunOracle(const std::vector<std::string>& args, std::string* output) {
  return testing::RunPython("tools/testing/pickle_oracle.py", args, output);
}

// The oracle's tags of the values a frame holds: None, bool, int, float, str (object columns and labels).
json TagFloat(double d) {
  if (std::isnan(d)) return json::array({"float", "nan"});
  int64_t bits;
  std::memcpy(&bits, &d, 8);
  return json::array({"float", bits});
}

json TagScalar(const Value& v) {
  switch (v.kind()) {
    case Kind::kNone: return nullptr;
    case Kind::kBool: return v.AsBool();
    case Kind::kInt: return json::array({"int", v.AsInt()});
    case Kind::kFloat: return TagFloat(v.AsDouble());
    case Kind::kStr: return json::array({"str", v.AsString()});
    default: return json::array({"unexpected", pickle::KindName(v.kind())});
  }
}

json TagElement(const Array& a, int64_t i) {
  if (a.dtype == DType::kObject) return TagScalar(a.ObjectAt(i));
  if (a.dtype == DType::kUnicode) return json::array({"str", a.StringAt(i)});
  if (pickle::IsFloat(a.dtype)) return TagFloat(a.AsDouble(i));
  if (a.dtype == DType::kUInt64) return json::array({"int", a.At<uint64_t>(i)});
  if (a.dtype == DType::kBool) return a.At<bool>(i);
  return json::array({"int", a.AsInt(i)});
}

// Compares `df` with the oracle's `frame` dump in `dir` (frame.json + <i>.bin): every value, exactly.
void ExpectFrameEquals(const DataFrame& df, const fs::path& dir) {
  const json want = ReadJsonFile(dir / "frame.json");
  ASSERT_EQ(df.rows, want["rows"].get<int64_t>());
  ASSERT_EQ(df.columns.size(), want["columns"].size());
  for (size_t c = 0; c < df.columns.size(); ++c) {
    const Column& col = df.columns[c];
    const json& w = want["columns"][c];
    SCOPED_TRACE(col.name);
    EXPECT_EQ(col.name, w["name"].get<std::string>());
    EXPECT_EQ(pickle::DTypeName(col.values.dtype), w["dtype"].get<std::string>());
    ASSERT_EQ(col.values.shape, std::vector<int64_t>{df.rows});
    if (w.contains("objects")) {
      json got = json::array();
      for (int64_t i = 0; i < df.rows; ++i) got.push_back(TagElement(col.values, i));
      EXPECT_EQ(got, w["objects"]);
    } else {
      // Raw little-endian values as numpy holds them: equal bytes are equal values, NaN payloads included.
      EXPECT_TRUE(col.values.data == ReadFileToString(dir / w["file"].get<std::string>())) << "values differ";
    }
    ASSERT_NE(df.Find(col.name), nullptr);
    EXPECT_EQ(df.Find(col.name)->name, col.name);
  }
  const json& idx = want["index"];
  EXPECT_EQ(TagScalar(df.index.name), idx["name"]);
  EXPECT_EQ(TagScalar(df.columns_name), want["columns_name"]);
  if (idx["kind"] == "range") {
    ASSERT_TRUE(df.index.is_range);
    EXPECT_EQ(df.index.start, idx["start"].get<int64_t>());
    EXPECT_EQ(df.index.stop, idx["stop"].get<int64_t>());
    EXPECT_EQ(df.index.step, idx["step"].get<int64_t>());
  } else {
    ASSERT_FALSE(df.index.is_range);
    const json& labels = idx["values"];  // ["array", dtype, shape, fortran, elements]
    EXPECT_EQ(pickle::DTypeName(df.index.labels.dtype), labels[1].get<std::string>());
    json got = json::array();
    for (int64_t i = 0; i < df.index.labels.size(); ++i) got.push_back(TagElement(df.index.labels, i));
    EXPECT_EQ(got, labels[4]);
  }
}

// Writes `df` in both layouts (protocols 2 and 4, the latter gzipped) and appends "original ours" pairs to
// *pairs, for one `frame_equals` run of the oracle; our own reader must read each back to the same columns.
void WriteBothLayouts(const DataFrame& df, const fs::path& original, const fs::path& dir, const std::string& stem,
                      std::vector<std::string>* pairs) {
  for (const Layout layout : {Layout::kPandas15, Layout::kLegacy}) {
    const Value v = DataFrameToPickle(df, layout);
    for (const int protocol : {2, 4}) {
      const fs::path out = dir / (stem + (layout == Layout::kLegacy ? ".legacy" : ".p15") + ".w" +
                                  std::to_string(protocol) + (protocol == 4 ? ".pkl.gz" : ".pkl"));
      pickle::DumpFile(out, v, protocol, /*gzip=*/protocol == 4);
      pairs->push_back(original.string());
      pairs->push_back(out.string());
      const DataFrame again = LoadDataFrameFile(out);
      ASSERT_EQ(again.columns.size(), df.columns.size());
      for (size_t c = 0; c < df.columns.size(); ++c) {
        EXPECT_EQ(again.columns[c].name, df.columns[c].name);
        const DType d = df.columns[c].values.dtype == DType::kUnicode ? DType::kObject : df.columns[c].values.dtype;
        EXPECT_EQ(again.columns[c].values.dtype, d);
        if (d != DType::kObject) EXPECT_TRUE(Value::FromArray(again.columns[c].values) == Value::FromArray(df.columns[c].values));
        else EXPECT_TRUE(again.columns[c].values.objects == df.columns[c].values.objects);
      }
      EXPECT_EQ(again.rows, df.rows);
    }
  }
}

void ExpectPandasEquals(std::vector<std::string> pairs, int count) {
  std::string output;
  pairs.insert(pairs.begin(), "frame_equals");
  EXPECT_EQ(RunOracle(pairs, &output), 0) << output;
  EXPECT_NE(output.find("compared " + std::to_string(count) + " frames, 0 differ"), std::string::npos) << output;
}

class PandasOracle : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (testing::PandasPython().empty()) return;
    dir_ = new testing::TempDir();
    std::string output;
    status_ = RunOracle({"frames", dir_->path().string()}, &output);
    if (status_ != 0) std::cerr << output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    SD_REQUIRE_PANDAS_PYTHON();
    ASSERT_EQ(status_, 0) << "pickle_oracle.py frames failed";
  }
  static testing::TempDir* dir_;
  static int status_;
};
testing::TempDir* PandasOracle::dir_ = nullptr;
int PandasOracle::status_ = -1;

TEST_F(PandasOracle, ReadsSyntheticFramesAsPandasDoes) {
  int frames = 0;
  for (const auto& e : fs::directory_iterator(dir_->path())) {
    if (e.path().extension() != ".pkl") continue;
    SCOPED_TRACE(e.path().filename().string());
    fs::path dump = e.path();
    dump.replace_extension(".frame");
    DataFrame df;
    try {
      df = LoadDataFrameFile(e.path());
    } catch (const InputError& err) {
      ADD_FAILURE() << err.what();
      continue;
    }
    ExpectFrameEquals(df, dump);
    ++frames;
  }
  EXPECT_EQ(frames, 7 * 6);  // 7 frames x protocols 0-5
}

TEST_F(PandasOracle, PandasReadsTheFramesWeWrite) {
  std::vector<std::string> pairs;
  for (const char* name : {"mixed", "fortran_block", "explicit_index", "string_index", "stepped_range", "empty_rows",
                           "no_columns"}) {
    SCOPED_TRACE(name);
    const fs::path original = dir_->path() / (std::string(name) + ".p4.pkl");
    WriteBothLayouts(LoadDataFrameFile(original), original, dir_->path(), name, &pairs);
  }
  ExpectPandasEquals(pairs, 7 * 4);
}

TEST_F(PandasOracle, FramesBuiltHereLoadInPandas) {
  // Column types a caller builds: float32, int64 with a stride of placements (the int columns interleave with
  // floats), unicode (written as an object column of str), and an explicit float index.
  DataFrame df;
  df.rows = 3;
  df.columns = {{"a", Array::Of<double>({1.5, NAN, -0.0})},
                {"n", Array::Of<int64_t>({1, 2, 3})},
                {"b", Array::Of<float>({0.1f, 0.2f, 0.3f})},
                {"m", Array::Of<int64_t>({-1, -2, INT64_MIN})},
                {"label", Array::Unicode({"car", "", "p\xc3\xa9"})},
                {"flag", Array::Of<bool>({true, false, true})}};
  df.index.is_range = false;
  df.index.labels = Array::Of<double>({0.5, 1.5, 2.5});
  df.index.name = Value::Str("t");
  const Value v = DataFrameToPickle(df);
  const fs::path ours = dir_->path() / "built.pkl";
  pickle::DumpFile(ours, v, 4, false);
  std::string output;
  ASSERT_EQ(RunOracle({"frame", ours.string(), (dir_->path() / "built.frame").string()}, &output), 0)
      << output;
  DataFrame expected = df;
  expected.columns[4].values = Array::Objects({Value::Str("car"), Value::Str(""), Value::Str("p\xc3\xa9")});
  ExpectFrameEquals(expected, dir_->path() / "built.frame");
  ExpectFrameEquals(LoadDataFrameFile(ours), dir_->path() / "built.frame");
}

// --- PandaSet

TEST(PandaSet, FramesReadAsPandasReadsThemAndRoundTrip) {
  SD_REQUIRE_SHARED(root, "driving/pandaset-002-f44-55");
  SD_REQUIRE_PANDAS_PYTHON();
  testing::TempDir tmp;
  std::vector<std::string> pairs;
  for (const char* rel : {"lidar/44.pkl.gz", "annotations/cuboids/44.pkl.gz", "annotations/semseg/44.pkl.gz"}) {
    SCOPED_TRACE(rel);
    const fs::path file = root / rel;
    const std::string stem = fs::path(rel).parent_path().filename().string();
    std::string output;
    ASSERT_EQ(RunOracle({"frame", file.string(), (tmp / stem).string()}, &output), 0) << output;
    const DataFrame df = LoadDataFrameFile(file);
    ExpectFrameEquals(df, tmp / stem);
    WriteBothLayouts(df, file, tmp.path(), stem, &pairs);
  }
  ExpectPandasEquals(pairs, 3 * 4);
  const DataFrame lidar = LoadDataFrameFile(root / "lidar/44.pkl.gz");
  ASSERT_EQ(lidar.columns.size(), 6u);
  EXPECT_EQ(lidar.rows, 164108);
  EXPECT_EQ(lidar.Find("d")->values.dtype, DType::kInt64);
  EXPECT_EQ(lidar.Find("x")->values.dtype, DType::kFloat64);
  EXPECT_EQ(lidar.index.name.AsString(), "index");
  EXPECT_EQ(lidar.Find("nope"), nullptr);
}

TEST(PandaSet, LidarFrameLoadsInWellUnderASecond) {
  SD_REQUIRE_SHARED(file, "driving/pandaset-002-f44-55/lidar/44.pkl.gz");
  const std::string bytes = ReadFileToString(file);
  double best_load = 1e9, best_total = 1e9;
  for (int round = 0; round < 3; ++round) {
    const auto t0 = std::chrono::steady_clock::now();
    const pickle::Value v = pickle::LoadFile(file);  // gunzip + parse
    const auto t1 = std::chrono::steady_clock::now();
    const DataFrame df = DataFrameFromPickle(v, file);
    const auto t2 = std::chrono::steady_clock::now();
    ASSERT_EQ(df.rows, 164108);
    best_load = std::min(best_load, std::chrono::duration<double>(t1 - t0).count());
    best_total = std::min(best_total, std::chrono::duration<double>(t2 - t0).count());
  }
  std::cout << "PandaSet lidar frame (" << bytes.size() << " bytes gzip): LoadFile " << best_load * 1e3
            << " ms, + DataFrameFromPickle " << best_total * 1e3 << " ms\n";
  EXPECT_LT(best_total, 1.0);
}

TEST(PandasFrame, RefusesWhatIsNotADataFrame) {
  const auto error_of = [](const Value& v) {
    try {
      DataFrameFromPickle(v, "f.pkl");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error_of(Value::List()), "f.pkl: pandas DataFrame: the pickle holds a list, not a DataFrame");
  DataFrame df;
  df.rows = 2;
  df.index.stop = 2;
  df.columns = {{"a", Array::Of<double>({1, 2})}};
  Value good = DataFrameToPickle(df);
  EXPECT_EQ(error_of(good), "");
  // A block that claims a column twice.
  Value bad = DataFrameToPickle(DataFrame{{{"a", Array::Of<double>({1, 2})}, {"b", Array::Of<double>({3, 4})}}, 2,
                                          RowIndex{true, 0, 2, 1, {}, {}}, {}});
  pickle::Object& frame = bad.mutable_object();
  Value mgr = *frame.state.Find("_mgr");
  pickle::Object& m = mgr.mutable_object();
  Value blocks = m.args[0];
  Value block = blocks[0];
  pickle::Object& b = block.mutable_object();
  b.args.SetItem(1, pickle::Value::FromArray(Array::Of<int64_t>({0, 0})));
  blocks.SetItem(0, block);
  m.args.SetItem(0, blocks);
  frame.state.Set("_mgr", mgr);
  EXPECT_NE(error_of(bad).find("f.pkl: pandas DataFrame: block placement of column 0"), std::string::npos) << error_of(bad);
  // Our own pickle of it refuses the same way after a round trip through bytes.
  EXPECT_NE(error_of(pickle::Load(pickle::Dump(bad, 4), "f.pkl")).find("block placement"), std::string::npos);
}

}  // namespace
}  // namespace sd::pandas
