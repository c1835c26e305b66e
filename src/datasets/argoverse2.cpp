// Argoverse 2 sensor logs, read from the JSON / float32 conversions of their Arrow tables (we link no Arrow
// library): city_SE3_egovehicle.json, annotations.json and sensors/lidar/<ts_ns>.xyzil.f32.bin.
#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "core/error.h"
#include "datasets/internal.h"
#include "datasets/readers.h"
#include "io/json.h"

namespace fs = std::filesystem;

namespace sd {

namespace {

constexpr const char* kSweepSuffix = ".xyzil.f32.bin";

struct StampedPose {
  int64_t timestamp_ns = 0;
  Rigid3d T_city_ego;
};

Rigid3d RowPose(const JsonReader& r) {
  return Rigid3d::FromWxyz(r["qw"].Number(), r["qx"].Number(), r["qy"].Number(), r["qz"].Number(),
                           Eigen::Vector3d(r["tx_m"].Number(), r["ty_m"].Number(), r["tz_m"].Number()));
}

// Poses come at ~170 Hz, so linear translation + slerp between the two bracketing poses is far below the
// annotation accuracy. Outside the recorded span the nearest pose is used (the tables cover every sweep).
Rigid3d InterpolatePose(const std::vector<StampedPose>& poses, int64_t t_ns) {
  auto it = std::lower_bound(poses.begin(), poses.end(), t_ns,
                             [](const StampedPose& p, int64_t t) { return p.timestamp_ns < t; });
  if (it == poses.begin()) return poses.front().T_city_ego;
  if (it == poses.end()) return poses.back().T_city_ego;
  if (it->timestamp_ns == t_ns) return it->T_city_ego;
  const StampedPose& b = *it;
  const StampedPose& a = *(it - 1);
  const double s = static_cast<double>(t_ns - a.timestamp_ns) / static_cast<double>(b.timestamp_ns - a.timestamp_ns);
  return Interpolate(a.T_city_ego, b.T_city_ego, s);
}

}  // namespace

Log ReadArgoverse2(const fs::path& log_dir, const OpenLogOptions& options) {
  const fs::path poses_file = log_dir / "city_SE3_egovehicle.json";
  const fs::path annotations_file = log_dir / "annotations.json";
  if (!fs::is_regular_file(poses_file))
    throw InputError(log_dir, "not an Argoverse 2 log directory (no city_SE3_egovehicle.json; the .feather "
                              "tables must be converted to JSON first)");

  Log log;
  log.format = LogFormat::kArgoverse2;
  log.source = log_dir;
  log.data_root = options.data_root.empty() ? log_dir : options.data_root;
  log.annotation_path = annotations_file;
  log.name = log_dir.filename().string();
  if (log.name.empty()) log.name = log_dir.parent_path().filename().string();
  log.version = "av2-sensor";

  // Poses, sorted by time.
  const nlohmann::json poses_json = ReadJsonFile(poses_file);
  const JsonReader poses_reader(poses_json, poses_file);
  std::vector<StampedPose> poses(poses_reader.Size());
  for (size_t i = 0; i < poses.size(); ++i) {
    const JsonReader row = poses_reader[i];
    poses[i] = {row["timestamp_ns"].Integer(), RowPose(row)};
  }
  if (poses.empty()) throw InputError(poses_file, "no ego poses");
  std::sort(poses.begin(), poses.end(),
            [](const StampedPose& a, const StampedPose& b) { return a.timestamp_ns < b.timestamp_ns; });

  // Frames: every sweep on disk and every annotated timestamp.
  std::map<int64_t, Frame> frames;
  auto frame_at = [&](int64_t t_ns) -> Frame& {
    Frame& f = frames[t_ns];
    if (f.token.empty()) {
      f.token = std::to_string(t_ns);
      f.timestamp = static_cast<double>(t_ns) * 1e-9;
      f.T_world_ego = InterpolatePose(poses, t_ns);
    }
    return f;
  };

  const fs::path lidar_dir = log_dir / "sensors" / "lidar";
  if (fs::is_directory(lidar_dir)) {
    for (const auto& e : fs::directory_iterator(lidar_dir)) {
      const std::string name = e.path().filename().string();
      const std::string suffix = kSweepSuffix;
      if (name.size() <= suffix.size() || name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0) continue;
      const std::string stem = name.substr(0, name.size() - suffix.size());
      if (stem.size() > 19 || stem.find_first_not_of("0123456789") != std::string::npos) continue;
      const int64_t t_ns = std::stoll(stem);
      Frame& f = frame_at(t_ns);
      LidarSensor l;
      l.channel = "LIDAR";
      l.token = stem;
      l.path = e.path();
      l.relpath = datasets_internal::RelativePath(e.path(), log.data_root);
      l.layout = PointLayout{5, {"x", "y", "z", "intensity", "laser_number"}};
      l.timestamp = f.timestamp;
      // The two stacked lidars' points are already merged in the ego frame: T_ego_lidar = identity, and no
      // one beam pattern describes the sweep.
      l.one_beam_pattern = false;
      f.lidar = l;
    }
  }

  if (fs::is_regular_file(annotations_file)) {
    const nlohmann::json rows_json = ReadJsonFile(annotations_file);
    const JsonReader rows(rows_json, annotations_file);
    std::vector<int64_t> annotated;
    for (size_t i = 0; i < rows.Size(); ++i) {
      const JsonReader r = rows[i];
      const int64_t t_ns = r["timestamp_ns"].Integer();
      Frame& f = frame_at(t_ns);
      f.has_annotations = true;
      Annotation a;
      a.category = r["category"].String();
      a.instance_token = r["track_uuid"].String();
      a.token = datasets_internal::HexToken(a.instance_token + "@" + f.token);
      a.box.T_frame_box = RowPose(r);  // ego <- object, centre
      a.box.size = Eigen::Vector3d(r["length_m"].Number(), r["width_m"].Number(), r["height_m"].Number());
      if (r.Has("num_interior_pts")) a.num_lidar_pts = static_cast<int>(r["num_interior_pts"].Integer());
      f.annotations.push_back(std::move(a));
    }
  }

  for (auto& [t_ns, f] : frames) log.frames.push_back(std::move(f));
  if (log.frames.empty())
    throw InputError(log_dir, "Argoverse 2 log has neither converted sweeps (sensors/lidar/*.xyzil.f32.bin) nor "
                              "annotations.json");
  return log;
}

namespace datasets_internal {

LogFormatInfo Argoverse2Format() {
  return {LogFormat::kArgoverse2, "argoverse2", "argoverse2",
          [](const fs::path& p) {
            return fs::is_regular_file(p / "city_SE3_egovehicle.json") && fs::is_regular_file(p / "annotations.json");
          },
          &ReadArgoverse2, nullptr, "writing Argoverse 2 logs is not supported (their tables are Apache Arrow files)",
          [](const CategoryInfo& c) { return c.name; }};
}

}  // namespace datasets_internal

}  // namespace sd
