#include "datasets/writers.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/internal.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using sd::testing::RepoData;
using sd::testing::TempDir;

// A warning tripod placed at T_ego_box, seen by `channel` with a plausible 2D box. Each format stores only
// yaw about its box frame's up axis (mmdet3d: LiDAR z; KITTI: rectified cam0 -y), so tests place the object
// with a rotation the format can represent; the writers drop the rest (see writers.h).
AddedObject Tripod(const std::string& channel, const Rigid3d& T_ego_box) {
  AddedObject obj;
  obj.category = "warning_tripod";
  obj.asset_id = "tripod-001";
  const Eigen::Vector3d size = FindCategory("warning_tripod")->default_size;
  obj.annotation.box.size = size;
  obj.annotation.box.T_frame_box = T_ego_box;
  obj.annotation.num_lidar_pts = 42;
  CameraBox cb;
  cb.channel = channel;
  cb.box = {500, 300, 560, 350};
  cb.visible_fraction = 0.9;
  cb.truncation = 0.0;
  obj.camera_boxes.push_back(cb);
  return obj;
}

void ExpectSameBox(const Box3& a, const Box3& b, double tol = 1e-4) {
  const auto ca = a.Corners(), cb = b.Corners();
  for (int k = 0; k < 8; ++k) EXPECT_LT((ca[k] - cb[k]).norm(), tol) << "corner " << k;
  EXPECT_LT((a.size - b.size).cwiseAbs().maxCoeff(), tol);
}

void ExpectSameAnnotations(const std::vector<Annotation>& got, const std::vector<Annotation>& want) {
  ASSERT_GE(got.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(got[i].category, want[i].category);
    EXPECT_EQ(got[i].num_lidar_pts, want[i].num_lidar_pts);
    ExpectSameBox(got[i].box, want[i].box, 1e-9);
  }
}

TEST(WriteDerivative, Mmdet3dV1RoundTrip) {
  const Log log = OpenLog(RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  const Frame& f = log.frames[0];
  TempDir out;
  FrameEdit edit;
  // LiDAR frame: x right, y forward; the ground is ~1.84 m below the sensor.
  edit.added.push_back(Tripod("CAM_FRONT", f.lidar->T_ego_lidar * Rigid3d::FromYaw(0.4, Eigen::Vector3d(1.5, 8.0, -1.6))));
  const ImageU8 grey(1600, 900, 3, 128);
  edit.images["CAM_FRONT"] = grey;
  PointCloud points = ReadLidar(*f.lidar);
  const size_t n_points = points.size();
  points.data.resize(points.data.size() - 5 * 10);  // drop 10 points, as a LiDAR simulation might occlude them
  edit.points = points;
  const auto written = WriteDerivative(log, {edit}, out.path());
  ASSERT_EQ(written.size(), 1u);
  EXPECT_EQ(written[0], out / "mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");

  const Log back = OpenLog(written[0]);
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  EXPECT_EQ(b.token, f.token);
  ASSERT_EQ(b.annotations.size(), f.annotations.size() + 1);
  ExpectSameAnnotations(b.annotations, f.annotations);
  EXPECT_EQ(b.annotations.back().category, "warning_tripod");
  EXPECT_EQ(back.categories.size(), 11u);
  EXPECT_EQ(b.annotations.back().num_lidar_pts, 42);
  ExpectSameBox(b.annotations.back().box, edit.added[0].annotation.box);
  // Sensor files at the same data_root-relative paths; replaced ones replaced.
  EXPECT_EQ(ReadLidar(*b.lidar).size(), n_points - 10);
  ASSERT_EQ(b.cameras.size(), 6u);
  for (const CameraSensor& c : b.cameras) {
    ASSERT_TRUE(fs::exists(c.image_path)) << c.image_path;
    EXPECT_EQ(c.intrinsics.width, 1600);
    EXPECT_LT((c.T_ego_cam.Matrix() - f.FindCamera(c.channel)->T_ego_cam.Matrix()).cwiseAbs().maxCoeff(), 1e-9);
  }
  const ImageU8 front = ReadImage(b.FindCamera("CAM_FRONT")->image_path);
  EXPECT_NEAR(front.at(800, 450, 1), 128, 3);

  // The added cam_instance follows the dataset's camera-box convention (pinned in readers_test).
  const json j = ReadJsonFile(written[0]);
  const json& ci = j["data_list"][0]["cam_instances"]["CAM_FRONT"].back();
  const CameraSensor& cam = *b.FindCamera("CAM_FRONT");
  const Box3 bc = edit.added[0].annotation.box.Transformed(cam.T_ego_cam.Inverse());
  const auto uv = cam.intrinsics.Project(bc.center());
  ASSERT_TRUE(uv);
  EXPECT_NEAR(ci["center_2d"][0].get<double>(), uv->x(), 1e-6);
  EXPECT_NEAR(ci["center_2d"][1].get<double>(), uv->y(), 1e-6);
  EXPECT_NEAR(ci["depth"].get<double>(), bc.center().z(), 1e-9);
  EXPECT_NEAR(ci["bbox_3d"][4].get<double>(), bc.size.z(), 1e-12);  // l h w order
  EXPECT_EQ(ci["bbox_label_3d"].get<int>(), 10);
  EXPECT_EQ(j["metainfo"]["categories"]["warning_tripod"].get<int>(), 10);
}

TEST(WriteDerivative, Mmdet3dV0RoundTrip) {
  SD_REQUIRE_SHARED(info, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  const Log log = OpenLog(info);
  TempDir out;
  FrameEdit edit;
  edit.frame_index = 5;
  const Rigid3d& T_ego_lidar = log.frames[5].lidar->T_ego_lidar;
  edit.added.push_back(Tripod("CAM_FRONT", T_ego_lidar * Rigid3d::FromYaw(-0.7, Eigen::Vector3d(-1.0, 9.0, -1.6))));
  WriteOptions options;
  EXPECT_THROW(WriteDerivative(log, {edit}, out.path(), options), InputError);  // sensor files absent
  options.require_sensor_files = false;
  const auto written = WriteDerivative(log, {edit}, out.path(), options);
  ASSERT_EQ(written.size(), 1u);
  const Log back = OpenLog(written[0], {.format = {}, .data_root = out.path()});
  EXPECT_EQ(back.format, LogFormat::kMmdet3dV0);
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  const Frame& f = log.frames[5];
  EXPECT_EQ(b.token, f.token);
  ASSERT_EQ(b.annotations.size(), f.annotations.size() + 1);
  ExpectSameAnnotations(b.annotations, f.annotations);
  EXPECT_EQ(b.annotations.back().category, "warning_tripod");
  ExpectSameBox(b.annotations.back().box, edit.added[0].annotation.box);
}

TEST(WriteDerivative, NuScenesTablesRoundTrip) {
  const Log log = OpenLog(RepoData("driving/nuscenes-scene0061-kf0"));
  TempDir out;
  FrameEdit edit;
  edit.added.push_back(Tripod("CAM_FRONT", Rigid3d::FromYaw(0.4, Eigen::Vector3d(8.0, 1.5, 0.2))));
  const auto written = WriteDerivative(log, {edit}, out.path(), {.unchanged = UnchangedFiles::kSymlink});
  EXPECT_EQ(written.size(), 3u);  // sample_annotation, instance, category (a new class)
  const Log back = OpenLog(out.path());
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  EXPECT_TRUE(b.has_annotations);
  ASSERT_EQ(b.annotations.size(), 1u);
  EXPECT_EQ(b.annotations[0].category, "movable_object.warning_tripod");
  EXPECT_EQ(b.annotations[0].visibility, 4);  // 90 % visible
  EXPECT_EQ(b.annotations[0].num_lidar_pts, 42);
  EXPECT_EQ(b.annotations[0].token.size(), 32u);
  ExpectSameBox(b.annotations[0].box, edit.added[0].annotation.box);
  EXPECT_TRUE(fs::is_symlink(b.lidar->path));
  EXPECT_EQ(ReadLidar(*b.lidar).size(), 34688u);
}

TEST(WriteDerivative, LyftTablesKeepOldAnnotations) {
  const Log log = OpenLog(RepoData("driving/lyft-tables/v1.01-train"));
  TempDir out;
  FrameEdit edit;
  AddedObject car = Tripod("CAM_FRONT", Rigid3d::FromYaw(2.0, Eigen::Vector3d(12.0, -3.0, 0.9)));
  car.category = "car";
  car.annotation.box.size = FindCategory("car")->default_size;
  edit.added.push_back(car);
  WriteOptions options;
  options.require_sensor_files = false;  // the fixture ships tables only
  const auto written = WriteDerivative(log, {edit}, out.path(), options);
  EXPECT_EQ(written.size(), 2u);  // Lyft's own "car" category record is reused, category.json unchanged
  const Log back = OpenLog(out.path());
  ASSERT_EQ(back.frames[0].annotations.size(), 5u);
  ExpectSameAnnotations(back.frames[0].annotations, log.frames[0].annotations);
  EXPECT_EQ(back.frames[0].annotations.back().category, "car");
  ExpectSameBox(back.frames[0].annotations.back().box, car.annotation.box);
}

TEST(WriteDerivative, KittiRoundTrip) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  TempDir out;
  FrameEdit edit;
  edit.frame_index = 1;
  // A rotation KITTI can hold: yaw about rectified cam0's y, i.e. an existing label's rotation.
  edit.added.push_back(Tripod("image_2", Rigid3d(log.frames[1].annotations[0].box.T_frame_box.rotation, Eigen::Vector3d(10.0, 1.5, -1.5))));
  const auto written = WriteDerivative(log, {edit}, out.path());
  ASSERT_EQ(written.size(), 1u);
  EXPECT_EQ(written[0], out / "label_2/000001.txt");
  const Log back = OpenLog(out.path());
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  EXPECT_EQ(b.token, "000001");
  const Frame& f = log.frames[1];
  ASSERT_EQ(b.annotations.size(), f.annotations.size() + 1);
  ExpectSameAnnotations(b.annotations, f.annotations);
  EXPECT_EQ(b.annotations.back().category, "WarningTripod");
  EXPECT_EQ(b.annotations.back().visibility, 0);  // 90 % visible -> fully visible
  ExpectSameBox(b.annotations.back().box, edit.added[0].annotation.box);
  EXPECT_EQ(ReadLidar(*b.lidar).size(), ReadLidar(*f.lidar).size());
  EXPECT_EQ(b.cameras[0].intrinsics.width, f.cameras[0].intrinsics.width);
}

// ---------------------------------------------------------------------------------------------------------
// Byte identity: every record the edit does not touch keeps the bytes it had in the input. The checks below
// find records in the raw text with their own small scanner (independent of the writer's) and compare bytes.

struct TextSpan {
  size_t begin = 0, end = 0;
};

size_t SkipSpace(const std::string& t, size_t i) {
  while (i < t.size() && std::isspace(static_cast<unsigned char>(t[i]))) ++i;
  return i;
}

// End of the JSON value starting at t[i] (strings, containers, bare literals such as NaN).
size_t ValueEnd(const std::string& t, size_t i) {
  if (t[i] == '"') {
    for (++i; t[i] != '"'; ++i)
      if (t[i] == '\\') ++i;
    return i + 1;
  }
  if (t[i] == '[' || t[i] == '{') {
    int depth = 0;
    for (;; ++i) {
      if (t[i] == '"') i = ValueEnd(t, i) - 1;
      else if (t[i] == '[' || t[i] == '{') ++depth;
      else if ((t[i] == ']' || t[i] == '}') && --depth == 0) return i + 1;
    }
  }
  while (i < t.size() && !std::strchr(",]} \t\r\n", t[i])) ++i;
  return i;
}

// Elements of an array, or members (key -> value span) of an object, as raw text spans.
std::vector<TextSpan> RawElements(const std::string& t, TextSpan arr) {
  std::vector<TextSpan> out;
  for (size_t i = SkipSpace(t, arr.begin + 1); t[i] != ']'; i = SkipSpace(t, i)) {
    if (t[i] == ',') i = SkipSpace(t, i + 1);
    out.push_back({i, ValueEnd(t, i)});
    i = out.back().end;
  }
  return out;
}
std::map<std::string, TextSpan> RawMembers(const std::string& t, TextSpan obj) {
  std::map<std::string, TextSpan> out;
  for (size_t i = SkipSpace(t, obj.begin + 1); t[i] != '}'; i = SkipSpace(t, i)) {
    if (t[i] == ',') i = SkipSpace(t, i + 1);
    const size_t key_end = ValueEnd(t, i);
    const std::string key = json::parse(t.substr(i, key_end - i)).get<std::string>();
    const size_t v = SkipSpace(t, SkipSpace(t, key_end) + 1);
    out[key] = {v, ValueEnd(t, v)};
    i = out[key].end;
  }
  return out;
}
std::string Raw(const std::string& t, TextSpan s) { return t.substr(s.begin, s.end - s.begin); }
TextSpan RootSpan(const std::string& t) {
  const size_t b = SkipSpace(t, 0);
  return {b, ValueEnd(t, b)};
}

// `out` is `in` with bytes inserted only: nothing of `in` removed, changed or reordered.
bool InsertionsOnly(const std::string& in, const std::string& out) {
  size_t k = 0;
  for (size_t i = 0; i < out.size() && k < in.size(); ++i)
    if (out[i] == in[k]) ++k;
  return k == in.size();
}

// `out` is `in` with one block inserted (records appended to a table).
bool OneInsertion(const std::string& in, const std::string& out) {
  if (out.size() < in.size()) return false;
  size_t p = 0;
  while (p < in.size() && in[p] == out[p]) ++p;
  return in.compare(p, std::string::npos, out, out.size() - (in.size() - p), std::string::npos) == 0;
}

size_t Count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t i = text.find(what); i != std::string::npos; i = text.find(what, i + 1)) ++n;
  return n;
}

std::vector<std::string> Files(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// nuScenes/Lyft tables: tables without additions byte-identical; extended tables = input + one appended block
// holding exactly the added records.
void CheckTablesKeepBytes(const fs::path& root, const std::vector<size_t>& frames) {
  const Log log = OpenLog(root);
  std::vector<FrameEdit> edits;
  size_t n_added = 0;
  for (size_t f : frames) {
    FrameEdit e;
    e.frame_index = f;
    e.added.push_back(Tripod("CAM_FRONT", Rigid3d::FromYaw(0.4, Eigen::Vector3d(8.0, 1.5, 0.2))));
    AddedObject car = Tripod("CAM_FRONT", Rigid3d::FromYaw(-1.0, Eigen::Vector3d(14.0, -2.0, 0.9)));
    car.category = "car";
    e.added.push_back(car);
    n_added += 2;
    edits.push_back(e);
  }
  TempDir out;
  WriteDerivative(log, edits, out.path(), {.unchanged = UnchangedFiles::kSymlink, .require_sensor_files = false});
  const fs::path in_v = log.annotation_path;
  const fs::path out_v = out / datasets_internal::RelativePath(fs::absolute(in_v), fs::absolute(log.data_root));
  for (const std::string& name : Files(in_v)) {
    if (fs::path(name).extension() != ".json") continue;
    SCOPED_TRACE(name);
    const std::string in = ReadFileToString(in_v / name), got = ReadFileToString(out_v / name);
    const json a = json::parse(in), b = json::parse(got);
    ASSERT_TRUE(a.is_array());
    if (name == "sample_annotation.json" || name == "instance.json") {
      EXPECT_TRUE(OneInsertion(in, got));
      ASSERT_EQ(b.size(), a.size() + n_added);
      for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(b[i], a[i]);
    } else if (name == "category.json") {
      EXPECT_TRUE(OneInsertion(in, got));
      EXPECT_LE(b.size(), a.size() + 1);  // a new record only for a class the dataset lacks (warning_tripod)
    } else {
      EXPECT_EQ(got, in);
    }
  }
  // Every added object read back, with the original annotations of the edited frames unchanged.
  const Log back = OpenLog(out.path());
  size_t found = 0;
  for (const Frame& f : back.frames)
    for (const Annotation& a : f.annotations) found += a.category == "movable_object.warning_tripod";
  EXPECT_EQ(found, frames.size());
  for (size_t f : frames) {
    const Frame* b = nullptr;
    for (const Frame& x : back.frames)
      if (x.token == log.frames[f].token) b = &x;
    ASSERT_TRUE(b);
    ASSERT_EQ(b->annotations.size(), log.frames[f].annotations.size() + 2);
  }
}

TEST(ByteIdentity, NuScenesTables) {
  CheckTablesKeepBytes(RepoData("driving/nuscenes-scene0061-kf0"), {0});
  CheckTablesKeepBytes(RepoData("driving/lyft-tables/v1.01-train"), {0});
}

TEST(ByteIdentity, LyftTablesShared) {
  SD_REQUIRE_SHARED(root, "driving/lyft-mmdet3d-tests/v1.01-train");
  CheckTablesKeepBytes(root, {0});
}

// mmdet3d infos: the output keeps the edited frames' records, each the input record with the added objects
// appended to its lists (instances / cam_instances, or v0's gt_* columns); every other field, every existing
// list element and the text around the record list keep their bytes. NaN literals survive.
void CheckInfoKeepsBytes(const fs::path& info, const std::vector<size_t>& frames, const fs::path& data_root = {},
                         const fs::path& keep_output = {}) {
  SCOPED_TRACE(info.string());
  const Log log = OpenLog(info, {.format = {}, .data_root = data_root});
  const bool v1 = log.format == LogFormat::kMmdet3dV1;
  const char* list_key = v1 ? "data_list" : "infos";
  std::vector<FrameEdit> edits;
  for (size_t f : frames) {
    FrameEdit e;
    e.frame_index = f;
    // Ahead of the ego vehicle (whatever the LiDAR's mounting), rotated about the LiDAR's z axis only.
    const Rigid3d T_ego_lidar = log.frames[f].lidar->T_ego_lidar;
    const auto placed = [&](double yaw, const Eigen::Vector3d& p_ego) {
      return T_ego_lidar * Rigid3d::FromYaw(yaw, T_ego_lidar.Inverse() * p_ego);
    };
    e.added.push_back(Tripod("CAM_FRONT", placed(0.4, Eigen::Vector3d(8.0, 1.5, 0.3))));
    AddedObject car = Tripod("CAM_FRONT", placed(-1.0, Eigen::Vector3d(15.0, -3.0, 0.9)));
    car.category = "car";
    e.added.push_back(car);
    edits.push_back(e);
  }
  TempDir out;
  const auto written = WriteDerivative(log, edits, out.path(), {.unchanged = UnchangedFiles::kSymlink, .require_sensor_files = false});
  ASSERT_EQ(written.size(), 1u);
  if (!keep_output.empty()) fs::copy_file(written[0], keep_output);
  const std::string in = ReadFileToString(info), got = ReadFileToString(written[0]);
  const TextSpan in_list = RawMembers(in, RootSpan(in)).at(list_key), got_list = RawMembers(got, RootSpan(got)).at(list_key);
  // Around the record list: unchanged, or (v1, a class the metainfo lacks) the class appended.
  EXPECT_TRUE(InsertionsOnly(in.substr(0, in_list.begin), got.substr(0, got_list.begin)));
  EXPECT_TRUE(InsertionsOnly(in.substr(in_list.end), got.substr(got_list.end)));
  const std::vector<TextSpan> in_recs = RawElements(in, in_list), got_recs = RawElements(got, got_list);
  ASSERT_EQ(got_recs.size(), frames.size());
  const std::set<std::string> lists = v1 ? std::set<std::string>{"instances"}
                                         : std::set<std::string>{"gt_boxes", "gt_names", "gt_velocity", "num_lidar_pts",
                                                                 "num_radar_pts", "valid_flag"};
  for (size_t k = 0; k < frames.size(); ++k) {
    SCOPED_TRACE("frame " + std::to_string(frames[k]));
    const std::string a = Raw(in, in_recs[frames[k]]), b = Raw(got, got_recs[k]);
    EXPECT_TRUE(InsertionsOnly(a, b));
    const auto am = RawMembers(a, {0, a.size()}), bm = RawMembers(b, {0, b.size()});
    for (const auto& [key, span] : am) {
      SCOPED_TRACE(key);
      ASSERT_TRUE(bm.count(key));
      const bool is_list = lists.count(key) && a[span.begin] == '[';
      if (!is_list && key != "cam_instances") {
        EXPECT_EQ(Raw(b, bm.at(key)), Raw(a, span));
        continue;
      }
      std::vector<std::pair<std::string, TextSpan>> a_lists, b_lists;
      if (key == "cam_instances") {
        const auto ac = RawMembers(a, span), bc = RawMembers(b, bm.at(key));
        for (const auto& [ch, s] : ac) a_lists.push_back({ch, s}), b_lists.push_back({ch, bc.at(ch)});
      } else {
        a_lists.push_back({key, span});
        b_lists.push_back({key, bm.at(key)});
      }
      for (size_t l = 0; l < a_lists.size(); ++l) {
        const auto ae = RawElements(a, a_lists[l].second), be = RawElements(b, b_lists[l].second);
        ASSERT_GE(be.size(), ae.size()) << a_lists[l].first;
        for (size_t i = 0; i < ae.size(); ++i) EXPECT_EQ(Raw(b, be[i]), Raw(a, ae[i])) << a_lists[l].first << "[" << i << "]";
      }
    }
    EXPECT_EQ(Count(b, "NaN"), Count(a, "NaN")) << "NaN literals kept";
  }
  // Read back: the edited frames, their own annotations, then the added objects.
  const Log back = OpenLog(written[0], {.format = {}, .data_root = log.data_root});
  ASSERT_EQ(back.frames.size(), frames.size());
  for (size_t k = 0; k < frames.size(); ++k) {
    const Frame& f = log.frames[frames[k]];
    const Frame& b = back.frames[k];
    EXPECT_EQ(b.token, f.token);
    ASSERT_EQ(b.annotations.size(), f.annotations.size() + 2);
    ExpectSameAnnotations(b.annotations, f.annotations);
    EXPECT_EQ(b.annotations[f.annotations.size()].category, "warning_tripod");
    EXPECT_EQ(b.annotations[f.annotations.size() + 1].category, "car");
    ExpectSameBox(b.annotations[f.annotations.size()].box, edits[k].added[0].annotation.box);
    ExpectSameBox(b.annotations[f.annotations.size() + 1].box, edits[k].added[1].annotation.box);
    if (v1) {  // the added cam_instances come back as the objects' 2D boxes
      const auto& got = b.annotations[f.annotations.size()].box2d_by_camera;
      ASSERT_TRUE(got.count("CAM_FRONT"));
      EXPECT_EQ(got.at("CAM_FRONT").x1, 500);
      EXPECT_EQ(got.at("CAM_FRONT").y2, 350);
    }
  }
}

TEST(ByteIdentity, Mmdet3dV1) {
  CheckInfoKeepsBytes(RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"), {0});
}

TEST(ByteIdentity, Mmdet3dV0) {
  CheckInfoKeepsBytes(RepoData("driving/nuscenes-scene0061-kf0/bevfusion_demo_info/nuscenes_infos_test.json"), {0});
}

// A one-line info (nlohmann's compact layout) whose metainfo lists `classes`, whose record has no
// instances / cam_instances, and which carries a NaN and a key the writer does not know.
TEST(ByteIdentity, Mmdet3dV1OneLineClassesNoLists) {
  const fs::path scene = RepoData("driving/nuscenes-scene0061-kf0");
  json j = ReadJsonFile(scene / "mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");
  json classes = json::array();
  for (const auto& [name, index] : j["metainfo"]["categories"].items()) classes.push_back(std::pair(index.get<int>(), name));
  std::sort(classes.begin(), classes.end());
  json names = json::array();
  for (const json& c : classes) names.push_back(c[1]);
  j["metainfo"].erase("categories");
  j["metainfo"]["classes"] = names;
  j["data_list"][0].erase("instances");
  j["data_list"][0].erase("cam_instances");
  j["zz_other_tool"] = {{"note", "kept"}};
  std::string text = j.dump();
  text.insert(text.rfind('}'), ", \"nan_field\": NaN");
  TempDir dir;
  WriteFileAtomic(dir / "info.json", text);
  CheckInfoKeepsBytes(dir / "info.json", {0}, scene, dir / "out.json");
  const std::string got = ReadFileToString(dir / "out.json");
  EXPECT_EQ(got.find('\n'), std::string::npos);  // still one line
  const json out = datasets_internal::ReadPythonJson(dir / "out.json");
  EXPECT_EQ(out["metainfo"]["classes"].size(), names.size() + 1);
  EXPECT_EQ(out["metainfo"]["classes"].back(), "warning_tripod");
  EXPECT_EQ(out["data_list"][0]["instances"].size(), 2u);
  EXPECT_EQ(out["data_list"][0]["cam_instances"]["CAM_FRONT"].size(), 2u);
  EXPECT_EQ(out["zz_other_tool"]["note"], "kept");
}

TEST(ByteIdentity, Mmdet3dSharedInfos) {
  SD_REQUIRE_SHARED(v0, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  CheckInfoKeepsBytes(v0, {33, 2, 39});  // 33 and 39 hold NaN velocities; out of order on purpose
  SD_REQUIRE_SHARED(lyft, "driving/lyft-mmdet3d-tests/lyft_infos.json");
  CheckInfoKeepsBytes(lyft, {0});
  SD_REQUIRE_SHARED(lyft_val, "driving/lyft-mmdet3d-tests/lyft_infos_val.json");
  CheckInfoKeepsBytes(lyft_val, {0});
}

// KITTI: the edited frames' label files are the input's lines followed by the added ones; calib files and
// every other sensor file byte-identical.
void CheckKittiKeepsBytes(const fs::path& root, const std::vector<size_t>& frames) {
  const Log log = OpenLog(root);
  std::vector<FrameEdit> edits;
  for (size_t f : frames) {
    FrameEdit e;
    e.frame_index = f;
    e.added.push_back(Tripod("image_2", Rigid3d::FromYaw(0.3, Eigen::Vector3d(10.0, 1.5, -1.5))));
    edits.push_back(e);
  }
  TempDir out;
  WriteDerivative(log, edits, out.path());
  const fs::path out_root =
      out / datasets_internal::RelativePath(fs::absolute(log.annotation_path.parent_path()), fs::absolute(log.data_root));
  for (size_t f : frames) {
    const std::string id = log.frames[f].token;
    SCOPED_TRACE(id);
    std::string in = ReadFileToString(log.annotation_path / (id + ".txt"));
    const std::string got = ReadFileToString(out_root / "label_2" / (id + ".txt"));
    if (!in.empty() && in.back() != '\n') in += '\n';  // the one byte a label file may gain
    ASSERT_GT(got.size(), in.size());
    EXPECT_EQ(got.substr(0, in.size()), in);
    EXPECT_EQ(std::count(got.begin() + static_cast<long>(in.size()), got.end(), '\n'), 1);
    EXPECT_EQ(ReadFileToString(out_root / "calib" / (id + ".txt")), ReadFileToString(log.data_root / "calib" / (id + ".txt")));
    EXPECT_EQ(ReadFileToString(out_root / "velodyne" / (id + ".bin")), ReadFileToString(log.frames[f].lidar->path));
  }
  EXPECT_EQ(Files(out_root / "label_2").size(), frames.size());  // only the edited frames are written
  const Log back = OpenLog(out.path());
  ASSERT_EQ(back.frames.size(), frames.size());
  for (size_t k = 0; k < frames.size(); ++k) {
    ASSERT_EQ(back.frames[k].annotations.size(), log.frames[frames[k]].annotations.size() + 1);
    ExpectSameAnnotations(back.frames[k].annotations, log.frames[frames[k]].annotations);
    EXPECT_EQ(back.frames[k].annotations.back().category, "WarningTripod");
    const Box2 box = back.frames[k].annotations.back().box2d_by_camera.at("image_2");
    EXPECT_EQ(box.x1, 500);
    EXPECT_EQ(box.y1, 300);
    EXPECT_EQ(box.x2, 560);
    EXPECT_EQ(box.y2, 350);
  }
}

TEST(ByteIdentity, Kitti) {
  CheckKittiKeepsBytes(RepoData("driving/kitti-object"), {0, 2});
}

TEST(ByteIdentity, KittiShared) {
  SD_REQUIRE_SHARED(root, "driving/kitti-object-openpcdet");
  CheckKittiKeepsBytes(root, {1, 3});
}

TEST(WriteDerivative, RejectsBadEdits) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  TempDir out;
  FrameEdit edit;
  edit.frame_index = 7;
  EXPECT_THROW(WriteDerivative(log, {edit}, out.path()), InputError);
  edit.frame_index = 0;
  edit.images["image_2"] = ImageU8(10, 10, 3);  // wrong size
  EXPECT_THROW(WriteDerivative(log, {edit}, out.path()), InputError);
  EXPECT_THROW(WriteDerivative(log, {}, out / "missing"), InputError);
}

}  // namespace
}  // namespace sd
