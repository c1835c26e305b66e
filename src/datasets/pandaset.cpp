// PandaSet sequence folders (Hesai & Scale AI, CC BY 4.0): the reader and the writer. Conventions, and how the
// rig constants below were measured: docs/datasets.md ("PandaSet").
//
// Layout: <seq>/camera/<name>_camera/{NN.jpg, intrinsics.json, poses.json, timestamps.json},
// <seq>/lidar/{NN.pkl.gz, poses.json, timestamps.json}, <seq>/annotations/{cuboids,semseg}/NN.pkl.gz,
// <seq>/meta/{gps.json, timestamps.json}. The json files hold every frame of the full sequence, indexed by NN.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/log.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/json.h"
#include "io/pandas_frame.h"
#include "io/pickle.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

using namespace datasets_internal;

namespace {

constexpr double kPi = std::numbers::pi;

// --- The rig. PandaSet has no ego frame: its lidar/poses.json poses ("pose" below) are a vehicle reference
// 0.30 m above the road, x to the right, y forward, z up. Our ego frame is that pose turned to x forward, y left
// (a rotation of +90 degrees about z), origin unchanged, so T_world_ego = T_world_pose * T_pose_ego exactly.
Rigid3d PoseFromEgo() { return Rigid3d::FromYaw(kPi / 2, Eigen::Vector3d::Zero()); }

// The Pandar64 in the pose frame. Not the pose itself: every camera, placed by its own world pose and the
// devkit's static_extrinsic_calibration.yaml (camera <- Pandar64), puts the Pandar64 here, 1.85 m above the
// pose origin, to within 1 cm and 0.07 degrees over 6 cameras x 12 frames of sequence 002 (the test
// PandaSet.RigConstantsAgreeWithTheCamerasAndTheDevkitCalibration recomputes it). All PandaSet logs come from
// one vehicle.
Rigid3d PoseFromPandar64() {
  return Rigid3d::FromWxyz(-0.015901, -0.000206, -0.007849, 0.999843, Eigen::Vector3d(0.0001, 0.8075, 1.8515));
}
// The forward-facing PandarGT in the Pandar64's frame: the inverse of the devkit calibration's front_gt entry
// (front_gt <- Pandar64, the same convention the cameras' entries have).
Rigid3d Pandar64FromPandarGT() {
  return Rigid3d::FromWxyz(0.021475754959146356, -0.002060907279494794, 0.01134678181520767, 0.9997028534282365,
                           Eigen::Vector3d(-0.000451117754, -0.605646431446, -0.301525235176))
      .Inverse();
}

// The points ReadLidar returns: the file's columns, in the Pandar64 frame, time relative to the sweep's stamp.
PointLayout SweepLayout() { return PointLayout{6, {"x", "y", "z", "intensity", "time", "sensor"}}; }

struct StampedPoses {
  std::vector<Rigid3d> poses;  // sensor -> world, indexed by frame number
  std::vector<double> times;   // s
  fs::path file;
};

Rigid3d PoseOf(const JsonReader& r) {
  const JsonReader p = r["position"], h = r["heading"];
  return Rigid3d::FromWxyz(h["w"].Number(), h["x"].Number(), h["y"].Number(), h["z"].Number(),
                           Eigen::Vector3d(p["x"].Number(), p["y"].Number(), p["z"].Number()));
}

StampedPoses ReadStampedPoses(const fs::path& dir) {
  StampedPoses s;
  s.file = dir / "poses.json";
  const json poses = ReadJsonFile(s.file);
  const JsonReader pr(poses, s.file);
  for (size_t i = 0; i < pr.Size(); ++i) s.poses.push_back(PoseOf(pr[i]));
  const fs::path tfile = dir / "timestamps.json";
  const json times = ReadJsonFile(tfile);
  const JsonReader tr(times, tfile);
  for (size_t i = 0; i < tr.Size(); ++i) s.times.push_back(tr[i].Number());
  if (s.times.size() != s.poses.size())
    throw InputError(tfile, Msg() << tr.Size() << " timestamps for " << pr.Size() << " poses in " << s.file.filename().string());
  for (size_t i = 1; i < s.times.size(); ++i)
    if (!(s.times[i] > s.times[i - 1])) throw InputError(tfile, Msg() << "[" << i << "]: timestamps do not increase");
  return s;
}

// The pose at time t: translation linear, rotation slerp between the bracketing entries (the nearest outside).
Rigid3d PoseAt(const StampedPoses& s, double t) {
  auto it = std::lower_bound(s.times.begin(), s.times.end(), t);
  if (it == s.times.begin()) return s.poses.front();
  if (it == s.times.end()) return s.poses.back();
  const size_t b = static_cast<size_t>(it - s.times.begin()), a = b - 1;
  const double u = (t - s.times[a]) / (s.times[b] - s.times[a]);
  return Interpolate(s.poses[a], s.poses[b], u);
}

// Frame numbers with a LiDAR file (lidar/NN.pkl.gz), sorted.
std::vector<int> FrameNumbers(const fs::path& lidar_dir) {
  std::vector<int> out;
  for (const auto& e : fs::directory_iterator(lidar_dir)) {
    const std::string name = e.path().filename().string();
    const size_t dot = name.find('.');
    if (dot == 0 || dot == std::string::npos) continue;
    const std::string stem = name.substr(0, dot), ext = name.substr(dot);
    if ((ext != ".pkl.gz" && ext != ".pkl") || stem.size() > 6 || stem.find_first_not_of("0123456789") != std::string::npos)
      continue;
    out.push_back(std::stoi(stem));
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::string FrameName(int n) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%02d", n);
  return buf;
}

fs::path FrameFile(const fs::path& dir, int n) {
  const fs::path gz = dir / (FrameName(n) + ".pkl.gz");
  return fs::exists(gz) || !fs::exists(dir / (FrameName(n) + ".pkl")) ? gz : dir / (FrameName(n) + ".pkl");
}

const pandas::Column& RequireColumn(const pandas::DataFrame& df, const char* name, const fs::path& file) {
  const pandas::Column* c = df.Find(name);
  if (!c) throw InputError(file, Msg() << "no column '" << name << "'");
  return *c;
}

bool IsPandaSetSequence(const fs::path& p) {
  return fs::is_directory(p) && fs::is_regular_file(p / "lidar" / "poses.json") && fs::is_directory(p / "camera");
}

std::string ObjectString(const pandas::Column& c, int64_t i) {
  const pickle::Value& v = c.values.ObjectAt(i);
  return v.kind() == pickle::Kind::kStr ? v.AsString() : std::string();
}

// One cuboid row, world frame.
struct Cuboid {
  std::string uuid, label;
  Rigid3d T_world_box;
  Eigen::Vector3d size;  // length, width, height
  int sensor_id = -1;
  std::string sibling;
};

std::vector<Cuboid> ReadCuboids(const fs::path& file) {
  const pandas::DataFrame df = pandas::LoadDataFrameFile(file);
  const pandas::Column &uuid = RequireColumn(df, "uuid", file), &label = RequireColumn(df, "label", file),
                       &yaw = RequireColumn(df, "yaw", file), &px = RequireColumn(df, "position.x", file),
                       &py = RequireColumn(df, "position.y", file), &pz = RequireColumn(df, "position.z", file),
                       &dx = RequireColumn(df, "dimensions.x", file), &dy = RequireColumn(df, "dimensions.y", file),
                       &dz = RequireColumn(df, "dimensions.z", file);
  const pandas::Column* sensor = df.Find("cuboids.sensor_id");
  const pandas::Column* sibling = df.Find("cuboids.sibling_id");
  std::vector<Cuboid> out;
  for (int64_t i = 0; i < df.rows; ++i) {
    Cuboid c;
    c.uuid = ObjectString(uuid, i);
    c.label = ObjectString(label, i);
    if (c.uuid.empty()) throw InputError(file, Msg() << "row " << i << ": uuid is not a string");
    const Eigen::Vector3d centre(px.values.AsDouble(i), py.values.AsDouble(i), pz.values.AsDouble(i));
    // dimensions.x is the width (local x), .y the length (local y, the object's forward): heading = yaw + pi/2,
    // so our box x axis (length) points where the object faces.
    const Eigen::Vector3d dims(dx.values.AsDouble(i), dy.values.AsDouble(i), dz.values.AsDouble(i));
    const double heading = yaw.values.AsDouble(i) + kPi / 2;
    if (!centre.allFinite() || !dims.allFinite() || !std::isfinite(heading))
      throw InputError(file, Msg() << "row " << i << " (" << c.uuid << "): position, dimensions or yaw not finite");
    c.T_world_box = Rigid3d::FromYaw(heading, centre);
    c.size = Eigen::Vector3d(dims.y(), dims.x(), dims.z());
    if (sensor) {
      // -1 outside the LiDARs' overlap, else which LiDAR annotated this row (the cast needs the range check).
      const double id = sensor->values.AsDouble(i);
      if (!(id == -1 || id == 0 || id == 1))
        throw InputError(file, Msg() << "row " << i << " (" << c.uuid << "): cuboids.sensor_id " << id
                                     << " is not -1, 0 or 1");
      c.sensor_id = static_cast<int>(id);
    }
    if (sibling) c.sibling = ObjectString(*sibling, i);
    out.push_back(std::move(c));
  }
  return out;
}

// In the two LiDARs' overlap PandaSet annotates each object twice (cuboids.sensor_id 0 and 1, each naming the
// other in cuboids.sibling_id): the PandarGT's duplicate of a Pandar64 box is dropped.
std::vector<Cuboid> FoldSiblings(std::vector<Cuboid> rows) {
  std::set<std::string> pandar64;
  for (const Cuboid& c : rows)
    if (c.sensor_id == 0) pandar64.insert(c.uuid);
  std::vector<Cuboid> out;
  for (Cuboid& c : rows)
    if (!(c.sensor_id == 1 && pandar64.count(c.sibling))) out.push_back(std::move(c));
  return out;
}

}  // namespace

Log ReadPandaSet(const fs::path& dir, const OpenLogOptions& options) {
  if (!IsPandaSetSequence(dir))
    throw InputError(dir, "not a PandaSet sequence folder (expected lidar/poses.json and camera/)");
  Log log;
  log.format = LogFormat::kPandaSet;
  log.source = dir;
  log.data_root = options.data_root.empty() ? dir : options.data_root;
  log.annotation_path = dir / "annotations";
  log.name = fs::absolute(dir).lexically_normal().filename().string();
  log.version = "pandaset";
  log.ego_origin_on_ground = false;  // the pose origin is 0.30 m above the road
  log.nominal_road_z = -0.30;
  const StampedPoses lidar = ReadStampedPoses(dir / "lidar");
  const std::vector<int> numbers = FrameNumbers(dir / "lidar");
  if (numbers.empty()) throw InputError(dir / "lidar", "no LiDAR frames (NN.pkl.gz)");

  struct CameraFiles {
    std::string channel;
    fs::path dir;
    StampedPoses poses;
    PinholeCamera intrinsics;
  };
  std::vector<CameraFiles> cameras;
  for (const auto& e : fs::directory_iterator(dir / "camera")) {
    if (!e.is_directory() || !fs::is_regular_file(e.path() / "poses.json")) continue;
    CameraFiles c;
    c.channel = e.path().filename().string();
    c.dir = e.path();
    c.poses = ReadStampedPoses(e.path());
    const fs::path kfile = e.path() / "intrinsics.json";
    const json k = ReadJsonFile(kfile);
    const JsonReader kr(k, kfile);
    c.intrinsics.fx = kr["fx"].Number();
    c.intrinsics.fy = kr["fy"].Number();
    c.intrinsics.cx = kr["cx"].Number();
    c.intrinsics.cy = kr["cy"].Number();
    if (!(c.intrinsics.fx > 0 && c.intrinsics.fy > 0) || !std::isfinite(c.intrinsics.cx) || !std::isfinite(c.intrinsics.cy))
      throw InputError(kfile, "focal lengths must be positive and the principal point finite");
    cameras.push_back(std::move(c));
  }
  std::sort(cameras.begin(), cameras.end(), [](const CameraFiles& a, const CameraFiles& b) { return a.channel < b.channel; });

  const fs::path gps_file = dir / "meta" / "gps.json";
  if (fs::is_regular_file(gps_file)) {
    const json gps = ReadJsonFile(gps_file);
    const JsonReader g(gps, gps_file);
    const size_t first = static_cast<size_t>(numbers.front());
    if (first < g.Size()) log.location = GeoLocation{g[first]["lat"].Number(), g[first]["long"].Number(), ""};
  }

  const Rigid3d T_pose_ego = PoseFromEgo(), T_ego_pose = T_pose_ego.Inverse();
  const Rigid3d T_ego_lidar = T_ego_pose * PoseFromPandar64();
  std::map<std::string, std::vector<std::pair<size_t, Eigen::Vector3d>>> track_centres;  // uuid -> (frame, world centre)
  for (int n : numbers) {
    if (static_cast<size_t>(n) >= lidar.poses.size())
      throw InputError(lidar.file, Msg() << "has " << lidar.poses.size() << " poses; frame " << n << " has none");
    Frame f;
    f.token = FrameName(n);
    f.timestamp = lidar.times[static_cast<size_t>(n)];
    f.T_world_ego = lidar.poses[static_cast<size_t>(n)] * T_pose_ego;
    for (const CameraFiles& c : cameras) {
      const fs::path image = c.dir / (FrameName(n) + ".jpg");
      if (!fs::exists(image)) continue;
      if (static_cast<size_t>(n) >= c.poses.poses.size())
        throw InputError(c.poses.file, Msg() << "has " << c.poses.poses.size() << " poses; frame " << n << " has none");
      CameraSensor cam;
      cam.channel = c.channel;
      cam.image_path = image;
      cam.image_relpath = RelativePath(image, log.data_root);
      cam.timestamp = c.poses.times[static_cast<size_t>(n)];
      cam.intrinsics = c.intrinsics;
      const auto wh = ImageSizeFromHeader(image);
      cam.intrinsics.width = wh[0];
      cam.intrinsics.height = wh[1];
      const Rigid3d T_world_cam = c.poses.poses[static_cast<size_t>(n)];
      cam.T_world_egocam = PoseAt(lidar, cam.timestamp) * T_pose_ego;
      cam.T_egocam_cam = cam.T_world_egocam.Inverse() * T_world_cam;
      cam.T_ego_cam = f.T_world_ego.Inverse() * T_world_cam;
      f.cameras.push_back(std::move(cam));
    }
    LidarSensor l;
    l.channel = "lidar";
    l.path = FrameFile(dir / "lidar", n);
    l.relpath = RelativePath(l.path, log.data_root);
    l.layout = SweepLayout();
    l.timestamp = f.timestamp;
    l.T_ego_lidar = T_ego_lidar;
    l.file = SweepFile::kPandaSetPickle;
    l.T_lidar_world = (f.T_world_ego * T_ego_lidar).Inverse();
    l.sensor_feature = "sensor";
    l.T_lidar_sensors = {Rigid3d(), Pandar64FromPandarGT()};
    // The points are in the world frame: every return already placed by the pose at its own time.
    l.motion_compensated = true;
    l.one_beam_pattern = false;  // two LiDARs, no ring index
    f.lidar = l;

    const fs::path cuboid_file = FrameFile(dir / "annotations" / "cuboids", n);
    if (fs::exists(cuboid_file)) {
      f.has_annotations = true;
      const Rigid3d T_ego_world = f.T_world_ego.Inverse();
      for (Cuboid& c : FoldSiblings(ReadCuboids(cuboid_file))) {
        Annotation a;
        a.category = c.label;
        a.box.T_frame_box = T_ego_world * c.T_world_box;
        a.box.size = c.size;
        a.instance_token = c.uuid;
        a.token = HexToken(c.uuid + "@" + f.token);
        track_centres[c.uuid].push_back({log.frames.size(), c.T_world_box.translation});
        f.annotations.push_back(std::move(a));
      }
    }
    log.frames.push_back(std::move(f));
  }

  // Velocities from each track's centre in the neighbouring frames (central difference, one-sided at the ends),
  // in the ego frame; NaN for a track seen in one frame. PandaSet stores none.
  for (const auto& [uuid, seen] : track_centres) {
    if (seen.size() < 2) continue;
    for (size_t k = 0; k < seen.size(); ++k) {
      const auto& a = seen[k == 0 ? 0 : k - 1];
      const auto& b = seen[k + 1 == seen.size() ? k : k + 1];
      const double dt = log.frames[b.first].timestamp - log.frames[a.first].timestamp;
      if (!(dt > 0) || dt > 0.5) continue;  // not consecutive frames of the sequence
      const Eigen::Vector3d v_world = (b.second - a.second) / dt;
      Frame& f = log.frames[seen[k].first];
      for (Annotation& an : f.annotations)
        if (an.instance_token == uuid) an.velocity = (f.T_world_ego.rotation.inverse() * v_world).head<2>();
    }
  }
  return log;
}

PointCloud ReadPandaSetSweep(const LidarSensor& lidar) {
  if (!fs::exists(lidar.path)) throw InputError(lidar.path, "missing LiDAR sweep file (recorded as " + lidar.relpath + ")");
  const pandas::DataFrame df = pandas::LoadDataFrameFile(lidar.path);
  const pandas::Column &x = RequireColumn(df, "x", lidar.path), &y = RequireColumn(df, "y", lidar.path),
                       &z = RequireColumn(df, "z", lidar.path), &i = RequireColumn(df, "i", lidar.path),
                       &t = RequireColumn(df, "t", lidar.path), &d = RequireColumn(df, "d", lidar.path);
  PointCloud pc;
  const PointLayout layout = SweepLayout();
  pc.num_features = layout.num_features;
  pc.feature_names = layout.feature_names;
  pc.data.resize(static_cast<size_t>(df.rows) * 6);
  const Eigen::Matrix3d R = lidar.T_lidar_world.Rotation();
  const Eigen::Vector3d T = lidar.T_lidar_world.translation;
  for (int64_t k = 0; k < df.rows; ++k) {
    const Eigen::Vector3d p_world(x.values.AsDouble(k), y.values.AsDouble(k), z.values.AsDouble(k));
    const double time = t.values.AsDouble(k) - lidar.timestamp, sensor = d.values.AsDouble(k);
    if (!p_world.allFinite() || !std::isfinite(time) || (sensor != 0 && sensor != 1))
      throw InputError(lidar.path, Msg() << "row " << k << ": coordinates or time not finite, or d not 0/1");
    const Eigen::Vector3d p = R * p_world + T;
    float* r = &pc.data[static_cast<size_t>(k) * 6];
    r[0] = static_cast<float>(p.x());
    r[1] = static_cast<float>(p.y());
    r[2] = static_cast<float>(p.z());
    r[3] = static_cast<float>(i.values.AsDouble(k));
    r[4] = static_cast<float>(time);
    r[5] = static_cast<float>(sensor);
  }
  return pc;
}

namespace {

// ---------------------------------------------------------------------------------------------------------
// Writer

// An RFC 4122-shaped id from a 32-hex token, so added rows look like PandaSet's own uuids.
std::string UuidOf(const std::string& hex32) {
  return hex32.substr(0, 8) + "-" + hex32.substr(8, 4) + "-" + hex32.substr(12, 4) + "-" + hex32.substr(16, 4) + "-" +
         hex32.substr(20, 12);
}

pickle::Value NaNValue() { return pickle::Value::Float(std::numeric_limits<double>::quiet_NaN()); }

// Appends `extra` values to a 1-D column, keeping its dtype (object columns take Values; numeric ones doubles).
void AppendToColumn(pandas::Column* c, const std::vector<pickle::Value>& extra) {
  pickle::Array& a = c->values;
  SD_CHECK(a.ndim() == 1, << "column " << c->name << " is not 1-D");
  const int64_t n = a.size(), m = static_cast<int64_t>(extra.size());
  pickle::Array out = pickle::Array::Zeros(a.dtype, {n + m}, a.dtype == pickle::DType::kUnicode ? a.itemsize / 4 : 0);
  const pickle::Array src = a.ToCOrder();
  if (a.dtype == pickle::DType::kObject) {
    for (int64_t i = 0; i < n; ++i) out.objects[static_cast<size_t>(i)] = src.objects[static_cast<size_t>(i)];
    for (int64_t k = 0; k < m; ++k) out.objects[static_cast<size_t>(n + k)] = extra[static_cast<size_t>(k)];
  } else {
    std::memcpy(out.data.data(), src.data.data(), src.data.size());
    for (int64_t k = 0; k < m; ++k) {
      const pickle::Value& v = extra[static_cast<size_t>(k)];
      char* at = out.data.data() + (n + k) * out.itemsize;
      switch (a.dtype) {
        case pickle::DType::kBool: *at = v.AsBool() ? 1 : 0; break;
        case pickle::DType::kInt64: { const int64_t x = v.AsInt(); std::memcpy(at, &x, 8); break; }
        case pickle::DType::kInt32: { const int32_t x = static_cast<int32_t>(v.AsInt()); std::memcpy(at, &x, 4); break; }
        case pickle::DType::kFloat64: { const double x = v.AsDouble(); std::memcpy(at, &x, 8); break; }
        case pickle::DType::kFloat32: { const float x = static_cast<float>(v.AsDouble()); std::memcpy(at, &x, 4); break; }
        default: SD_CHECK(false, << "cannot append to a " << pickle::DTypeName(a.dtype) << " column " << c->name);
      }
    }
  }
  a = std::move(out);
}

// The cuboid rows of the added objects, appended to the frame's cuboids table column by column.
void AppendCuboids(pandas::DataFrame* df, const Frame& frame, const std::vector<AddedObject>& added, const fs::path& file) {
  std::map<std::string, std::vector<pickle::Value>> rows;
  for (size_t k = 0; k < added.size(); ++k) {
    const AddedObject& obj = added[k];
    const std::string track = obj.annotation.instance_token.empty() ? Msg() << "synthdrive/" << frame.token << "/" << k
                                                                      : obj.annotation.instance_token;
    const Box3 b = obj.annotation.box.Transformed(frame.T_world_ego);
    double yaw = b.Yaw() - kPi / 2;  // PandaSet's yaw turns its local y (length) axis to the heading
    yaw = std::atan2(std::sin(yaw), std::cos(yaw));
    const std::optional<CategoryInfo> cat = FindCategory(obj.category);
    const bool vehicle = cat && (cat->name == "car" || cat->name == "truck" || cat->name == "bus" ||
                                 cat->name == "trailer" || cat->name == "construction_vehicle");
    const std::map<std::string, pickle::Value> row = {
        {"uuid", pickle::Value::Str(UuidOf(HexToken("pandaset:" + track)))},
        {"label", pickle::Value::Str(ClassName(obj, LogFormat::kPandaSet))},
        {"yaw", pickle::Value::Float(yaw)},
        {"stationary", pickle::Value::Bool(true)},
        {"camera_used", pickle::Value::Int(-1)},
        {"position.x", pickle::Value::Float(b.center().x())},
        {"position.y", pickle::Value::Float(b.center().y())},
        {"position.z", pickle::Value::Float(b.center().z())},
        {"dimensions.x", pickle::Value::Float(b.size.y())},  // width
        {"dimensions.y", pickle::Value::Float(b.size.x())},  // length
        {"dimensions.z", pickle::Value::Float(b.size.z())},
        {"attributes.object_motion", vehicle ? pickle::Value::Str("Parked") : NaNValue()},
        {"cuboids.sibling_id", pickle::Value::Str("-")},
        {"cuboids.sensor_id", pickle::Value::Int(-1)},
    };
    for (const pandas::Column& c : df->columns) {
      auto it = row.find(c.name);
      rows[c.name].push_back(it != row.end() ? it->second : NaNValue());
    }
  }
  for (pandas::Column& c : df->columns) {
    try {
      AppendToColumn(&c, rows[c.name]);
    } catch (const InputError& e) {
      throw InputError(file, Msg() << "column " << c.name << ": " << e.what());
    }
  }
  df->rows += static_cast<int64_t>(added.size());
  if (df->index.is_range && df->index.step == 1 && df->index.stop == df->index.start + df->rows - static_cast<int64_t>(added.size()))
    df->index.stop += static_cast<int64_t>(added.size());
  else
    throw InputError(file, "the cuboids table's row index is not a plain RangeIndex; cannot append rows");
}

// PandaSet's semantic class id for a canonical category: its label's id in classes.json, else "Other Static
// Object" (42).
int SemsegClass(const std::string& category, const std::map<std::string, int>& class_ids) {
  const std::optional<CategoryInfo> c = FindCategory(category);
  if (c) {
    auto it = class_ids.find(c->pandaset_name);
    if (it != class_ids.end()) return it->second;
  }
  auto other = class_ids.find("Other Static Object");
  return other != class_ids.end() ? other->second : 42;
}

// The edited sweep back into the frame's DataFrame: rows the edit left bit-identical keep the file's float64
// values exactly; changed rows (returns moved onto an inserted object) get their new position in the world
// frame and intensity, and keep their time and sensor. Rows align one to one: PandaSet sweeps have no ring index,
// so synthesis only moves real returns, never adds or drops one.
void WriteSweep(const Log& log, const Frame& frame, const FrameEdit& edit, const fs::path& out_dir) {
  const LidarSensor& l = *frame.lidar;
  const PointCloud before = ReadPandaSetSweep(l);
  const PointCloud& after = *edit.points;
  if (after.size() != before.size() || after.num_features != before.num_features)
    throw InputError(l.path, Msg() << "the edited sweep has " << after.size() << " points, the file " << before.size()
                                   << ": PandaSet sweeps are written row for row");
  pandas::DataFrame df = pandas::LoadDataFrameFile(l.path);
  const Rigid3d T_world_lidar = l.T_lidar_world.Inverse();
  auto column = [&](const char* name) -> pickle::Array& {
    for (pandas::Column& c : df.columns)
      if (c.name == name) {
        c.values = c.values.ToCOrder();
        if (c.values.dtype != pickle::DType::kFloat64)
          throw InputError(l.path, Msg() << "column " << name << " is " << pickle::DTypeName(c.values.dtype) << ", expected float64");
        return c.values;
      }
    throw InputError(l.path, Msg() << "no column '" << name << "'");
  };
  pickle::Array &x = column("x"), &y = column("y"), &z = column("z"), &in = column("i");
  std::vector<int> changed;
  for (size_t k = 0; k < after.size(); ++k) {
    if (std::memcmp(&after.data[k * 6], &before.data[k * 6], 6 * sizeof(float)) == 0) continue;
    const Eigen::Vector3d p = T_world_lidar * after.xyz(k).cast<double>();
    const double v[4] = {p.x(), p.y(), p.z(), static_cast<double>(after.feature(k, 3))};
    pickle::Array* cols[4] = {&x, &y, &z, &in};
    for (int c = 0; c < 4; ++c) std::memcpy(cols[c]->data.data() + k * 8, &v[c], 8);
    changed.push_back(static_cast<int>(k));
  }
  const fs::path dst = out_dir / RelativePath(l.path, log.data_root);
  pickle::DumpFile(dst, pandas::DataFrameToPickle(df, pandas::Layout::kLegacy), 4, true);

  // The semantic class of every return now on an inserted object; the rest of the file as it was.
  const fs::path semseg = FrameFile(log.data_root / "annotations" / "semseg", std::stoi(frame.token));
  if (!fs::exists(semseg)) return;
  pandas::DataFrame classes = pandas::LoadDataFrameFile(semseg);
  if (classes.rows != df.rows) throw InputError(semseg, Msg() << classes.rows << " rows for a sweep of " << df.rows);
  std::map<std::string, int> class_ids;
  const fs::path classes_json = semseg.parent_path() / "classes.json";
  if (fs::exists(classes_json)) {
    const json table = ReadJsonFile(classes_json);
    if (table.is_object())
      for (auto it = table.begin(); it != table.end(); ++it)
        if (it->is_string()) class_ids[it->get<std::string>()] = std::atoi(it.key().c_str());
  }
  pandas::Column* cls = nullptr;
  for (pandas::Column& c : classes.columns)
    if (c.name == "class") cls = &c;
  if (!cls) throw InputError(semseg, "no column 'class'");
  cls->values = cls->values.ToCOrder();
  if (!pickle::IsInteger(cls->values.dtype)) throw InputError(semseg, "column 'class' is not an integer column");
  for (const auto& [point, object] : edit.point_objects) {
    if (point < 0 || static_cast<size_t>(point) >= after.size() || object < 0 || static_cast<size_t>(object) >= edit.added.size())
      continue;
    const int64_t id = SemsegClass(edit.added[static_cast<size_t>(object)].category, class_ids);
    char* at = cls->values.data.data() + static_cast<int64_t>(point) * cls->values.itemsize;
    if (cls->values.itemsize == 8) std::memcpy(at, &id, 8);
    else {
      const int32_t id32 = static_cast<int32_t>(id);
      std::memcpy(at, &id32, 4);
    }
  }
  pickle::DumpFile(out_dir / RelativePath(semseg, log.data_root), pandas::DataFrameToPickle(classes, pandas::Layout::kLegacy), 4, true);
}

std::vector<fs::path> WritePandaSet(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                    const WriteOptions& options) {
  SensorFileWriter files(log, out_dir, options);
  std::vector<fs::path> written;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    for (const CameraSensor& cam : frame.cameras) {
      auto it = e.images.find(cam.channel);
      files.Image(cam, it == e.images.end() ? nullptr : &it->second);
    }
    for (const auto& [channel, img] : e.images)
      if (!frame.FindCamera(channel)) throw InputError(log.source, "edit replaces an image of unknown camera " + channel);
    if (frame.lidar) {
      if (e.points) WriteSweep(log, frame, e, out_dir);
      else files.Unchanged(frame.lidar->path, out_dir / RelativePath(frame.lidar->path, log.data_root));
      const fs::path semseg = FrameFile(log.data_root / "annotations" / "semseg", std::stoi(frame.token));
      if (!e.points && fs::exists(semseg)) files.Unchanged(semseg, out_dir / RelativePath(semseg, log.data_root));
    }
    const fs::path cuboids = FrameFile(log.data_root / "annotations" / "cuboids", std::stoi(frame.token));
    if (fs::exists(cuboids)) {
      const fs::path dst = out_dir / RelativePath(cuboids, log.data_root);
      if (e.added.empty()) {
        files.Unchanged(cuboids, dst);
      } else {
        pandas::DataFrame df = pandas::LoadDataFrameFile(cuboids);
        AppendCuboids(&df, frame, e.added, cuboids);
        pickle::DumpFile(dst, pandas::DataFrameToPickle(df, pandas::Layout::kLegacy), 4, true);
      }
      written.push_back(dst);
    }
  }
  // The sequence's own tables (poses, timestamps, intrinsics, GPS, classes) hold every frame: copied whole, byte
  // for byte. Frame files of unedited frames are not written, as for every format.
  for (const auto& entry : fs::recursive_directory_iterator(log.data_root)) {
    if (!entry.is_regular_file() || entry.path().extension() != ".json") continue;
    const fs::path dst = out_dir / RelativePath(entry.path(), log.data_root);
    if (!fs::exists(dst)) WriteFileAtomic(dst, ReadFileToString(entry.path()));
  }
  return written;
}

}  // namespace

namespace datasets_internal {

LogFormatInfo PandaSetFormat() {
  return {LogFormat::kPandaSet, "pandaset", "pandaset", &IsPandaSetSequence, &ReadPandaSet, &WritePandaSet, nullptr,
          [](const CategoryInfo& c) { return c.pandaset_name; }};
}

}  // namespace datasets_internal
}  // namespace sd
