// Python pickles read as data (io/pickle.h: Load, gunzipped first like LoadFile when the bytes are gzip), then
// what the readers do with a loaded tree: its JSON twin (ToJson), a DataFrame (io/pandas_frame.h) when it is an
// object, and the writer's Dump of it (mmdet3d derivatives re-pickle what was read).
#include "fuzz/fuzz_support.h"
#include "io/gzip.h"
#include "io/pandas_frame.h"
#include "io/pickle.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    std::string_view bytes = sd::fuzz::AsText(data, size);
    std::string gunzipped;
    if (sd::IsGzip(bytes)) {
      // The fuzzer's memory limit is 2 GB; 64 MB still lets a small input claim a large output.
      gunzipped = sd::Gunzip(bytes, "fuzz.pkl.gz", size_t(64) << 20);
      bytes = gunzipped;
    }
    const sd::pickle::Value value = sd::pickle::Load(bytes, "fuzz.pkl");
    sd::pickle::Dump(value, 2);
    sd::pickle::Dump(value, 4);
    if (value.kind() == sd::pickle::Kind::kObject) sd::pandas::DataFrameFromPickle(value, "fuzz.pkl");
    sd::pickle::ToJson(value);
  });
}

namespace {

// A frame with the column kinds PandaSet's files hold: float64 and int64 numbers, object strings.
sd::pickle::Value SmallFrame(sd::pandas::Layout layout) {
  sd::pandas::DataFrame df;
  df.rows = 2;
  df.index.stop = 2;
  sd::pickle::Array x;
  x.dtype = sd::pickle::DType::kFloat64;
  x.itemsize = 8;
  x.shape = {2};
  const double xs[2] = {1.5, -2.25};
  x.data.assign(reinterpret_cast<const char*>(xs), sizeof xs);
  sd::pickle::Array d = x;
  d.dtype = sd::pickle::DType::kInt64;
  const int64_t ds[2] = {0, 1};
  d.data.assign(reinterpret_cast<const char*>(ds), sizeof ds);
  sd::pickle::Array label;
  label.dtype = sd::pickle::DType::kObject;
  label.shape = {2};
  label.objects = {sd::pickle::Value::Str("Car"), sd::pickle::Value::Str("Cones")};
  df.columns = {{"position.x", x}, {"d", d}, {"label", label}};
  return sd::pandas::DataFrameToPickle(df, layout);
}

}  // namespace

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  std::vector<Seed> seeds;
  for (const char* file : {"data/driving/nuscenes-scene0061-kf0/bevfusion_demo_info/nuscenes_infos_test.pkl",
                           "data/driving/kitti-mmdet3d-pkl-000008/v0x_format/kitti_000008_infos.pkl",
                           "data/driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.pkl"}) {
    const std::string bytes = ReadBytes(RepoPath(file));
    const std::string name = std::filesystem::path(file).filename().string();
    seeds.push_back({name, bytes});
    // Protocol 2 spells arrays and bytes differently (_codecs.encode) from the protocol 4 the files use.
    seeds.push_back({"protocol2-" + name, pickle::Dump(pickle::Load(bytes, file), 2)});
  }
  seeds.push_back({"frame-pandas15.pkl", pickle::Dump(SmallFrame(pandas::Layout::kPandas15), 4)});
  seeds.push_back({"frame-legacy.pkl", pickle::Dump(SmallFrame(pandas::Layout::kLegacy), 2)});
  const auto cuboids = SharedDataPath("driving/pandaset-002-f44-55/annotations/cuboids/44.pkl.gz");
  if (std::filesystem::exists(cuboids)) seeds.push_back({"pandaset-cuboids-44.pkl.gz", ReadBytes(cuboids)});
  return seeds;
}
