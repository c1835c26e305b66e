#include "datasets/coco.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;
using sd::testing::RepoData;
using sd::testing::TempDir;

// An added object seen by every listed camera, with a distinct box per camera.
AddedObject Added(const std::string& category, const std::vector<std::string>& channels, double x0) {
  AddedObject obj;
  obj.category = category;
  obj.asset_id = category + "-asset";
  obj.annotation.box.size = FindCategory(category)->default_size;
  for (size_t k = 0; k < channels.size(); ++k) {
    CameraBox cb;
    cb.channel = channels[k];
    cb.box = {x0 + 10.0 * static_cast<double>(k), 200.5, x0 + 10.0 * static_cast<double>(k) + 37.25, 260};
    cb.visible_fraction = 0.75;
    cb.truncation = 0.125;
    obj.camera_boxes.push_back(cb);
  }
  return obj;
}

int64_t CategoryIdOf(const std::string& name) {
  const auto& all = Categories();
  for (size_t k = 0; k < all.size(); ++k)
    if (all[k].name == FindCategory(name)->name) return static_cast<int64_t>(k + 1);
  return 0;
}

// Writes `edits`, reads the file back and checks every image, real box, added box and category. Returns the
// number of real (non-synthetic) boxes.
size_t ExpectRoundTrip(const Log& log, const std::vector<FrameEdit>& edits) {
  TempDir out;
  const fs::path file = out / "coco.json";
  WriteCoco2D(log, edits, file);
  const Coco2D coco = ReadCoco2D(file);

  EXPECT_EQ(coco.categories.size(), Categories().size());
  for (size_t k = 0; k < Categories().size(); ++k) {
    EXPECT_EQ(coco.categories[k].id, static_cast<int64_t>(k + 1));
    EXPECT_EQ(coco.categories[k].name, Categories()[k].name);
  }
  size_t max_cameras = 1;
  for (const Frame& f : log.frames) max_cameras = std::max(max_cameras, f.cameras.size());

  std::vector<const FrameEdit*> sorted;
  for (const FrameEdit& e : edits) sorted.push_back(&e);
  std::sort(sorted.begin(), sorted.end(), [](auto* a, auto* b) { return a->frame_index < b->frame_index; });
  size_t next_image = 0, next_ann = 0, n_real = 0, n_synthetic = 0;
  for (const FrameEdit* e : sorted) {
    const Frame& frame = log.frames[e->frame_index];
    for (size_t c = 0; c < frame.cameras.size(); ++c) {
      const CameraSensor& cam = frame.cameras[c];
      if (next_image >= coco.images.size()) {
        ADD_FAILURE() << "too few images";
        return 0;
      }
      const CocoImage& im = coco.images[next_image++];
      EXPECT_EQ(im.id, static_cast<int64_t>(e->frame_index * max_cameras + c + 1));
      EXPECT_EQ(log.data_root / im.file_name, cam.image_path);  // resolves like the derivative's own layout
      EXPECT_EQ(im.width, cam.intrinsics.width);
      EXPECT_EQ(im.height, cam.intrinsics.height);
      EXPECT_EQ(im.frame_token, frame.token);
      EXPECT_EQ(im.channel, cam.channel);
      // The log's own boxes of this camera, in annotation order, then the added ones.
      for (const Annotation& a : frame.annotations) {
        auto it = a.box2d_by_camera.find(cam.channel);
        if (it == a.box2d_by_camera.end() || !FindCategory(a.category) || it->second.Empty()) continue;
        if (next_ann >= coco.annotations.size()) {
          ADD_FAILURE() << "too few annotations";
          return 0;
        }
        const CocoAnnotation& got = coco.annotations[next_ann++];
        EXPECT_EQ(got.image_id, im.id);
        EXPECT_FALSE(got.synthetic);
        EXPECT_EQ(got.category, FindCategory(a.category)->name);
        EXPECT_EQ(got.box.x1, it->second.x1);
        EXPECT_EQ(got.box.y1, it->second.y1);
        EXPECT_NEAR(got.box.x2, it->second.x2, 1e-9);
        EXPECT_NEAR(got.box.y2, it->second.y2, 1e-9);
        ++n_real;
      }
      for (const AddedObject& obj : e->added)
        for (const CameraBox& cb : obj.camera_boxes) {
          if (cb.channel != cam.channel) continue;
          if (next_ann >= coco.annotations.size()) {
          ADD_FAILURE() << "too few annotations";
          return 0;
        }
          const CocoAnnotation& got = coco.annotations[next_ann++];
          EXPECT_EQ(got.image_id, im.id);
          EXPECT_TRUE(got.synthetic);
          EXPECT_EQ(got.category, obj.category);
          EXPECT_EQ(got.category_id, CategoryIdOf(obj.category));
          EXPECT_EQ(got.box.x1, cb.box.x1);
          EXPECT_EQ(got.box.y1, cb.box.y1);
          EXPECT_EQ(got.box.x2, cb.box.x2);  // exact: pixel-edge values survive x + (x2 - x1)
          EXPECT_EQ(got.box.y2, cb.box.y2);
          EXPECT_EQ(got.area, cb.box.Area());
          EXPECT_EQ(got.visible_fraction, cb.visible_fraction);
          EXPECT_EQ(got.truncation, cb.truncation);
          EXPECT_EQ(got.asset_id, obj.asset_id);
          ++n_synthetic;
        }
    }
  }
  EXPECT_EQ(next_image, coco.images.size());
  EXPECT_EQ(next_ann, coco.annotations.size());
  for (size_t k = 0; k < coco.annotations.size(); ++k) EXPECT_EQ(coco.annotations[k].id, static_cast<int64_t>(k + 1));
  EXPECT_GT(n_synthetic, 0u);
  return n_real;
}

TEST(Coco2D, KittiRoundTripWithRealBoxes) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  std::vector<FrameEdit> edits(2);
  edits[0].frame_index = 2;
  edits[0].added = {Added("traffic_cone", {"image_2"}, 400), Added("warning_tripod", {"image_2"}, 600)};
  edits[1].frame_index = 1;
  edits[1].added = {Added("car", {"image_2"}, 100)};
  EXPECT_GT(ExpectRoundTrip(log, edits), 0u);

  // The real boxes are KITTI's label bboxes: frame 1's labels give as many non-synthetic boxes as it has
  // labels of canonical classes.
  TempDir out;
  WriteCoco2D(log, {edits[1]}, out / "c.json");
  const Coco2D coco = ReadCoco2D(out / "c.json");
  size_t want_real = 0;
  for (const Annotation& a : log.frames[1].annotations) want_real += a.box2d_by_camera.count("image_2") && FindCategory(a.category);
  size_t real = 0;
  for (const CocoAnnotation& a : coco.annotations) real += !a.synthetic;
  EXPECT_GT(want_real, 0u);
  EXPECT_EQ(real, want_real);
  EXPECT_EQ(coco.images.size(), 1u);
  EXPECT_EQ(coco.images[0].file_name, "image_2/000001.png");
  EXPECT_EQ(coco.images[0].id, 2);  // frame 1, the only camera

  Coco2DOptions only_added;
  only_added.real_boxes = false;
  WriteCoco2D(log, {edits[1]}, out / "d.json", only_added);
  EXPECT_EQ(ReadCoco2D(out / "d.json").annotations.size(), 1u);
}

TEST(Coco2D, Mmdet3dV1RoundTripSixCameras) {
  const Log log = OpenLog(RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  ASSERT_EQ(log.frames[0].cameras.size(), 6u);
  FrameEdit e;
  e.added = {Added("traffic_cone", {"CAM_FRONT", "CAM_FRONT_LEFT"}, 700), Added("barrier", {"CAM_BACK"}, 50)};
  EXPECT_GT(ExpectRoundTrip(log, {e}), 0u);  // the info's cam_instances
  TempDir out;
  WriteCoco2D(log, {e}, out / "c.json");
  const Coco2D coco = ReadCoco2D(out / "c.json");
  ASSERT_EQ(coco.images.size(), 6u);
  // v1 bare image names resolve in samples/<CHANNEL>/, as the derivative writes them.
  for (const CocoImage& im : coco.images) EXPECT_EQ(im.file_name.rfind("samples/" + im.channel + "/", 0), 0u) << im.file_name;
  size_t real = 0;
  for (const CocoAnnotation& a : coco.annotations) real += !a.synthetic;
  EXPECT_GT(real, 0u);  // the info's cam_instances
}

TEST(Coco2D, XywhIsExact) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  FrameEdit e;
  AddedObject obj = Added("barrier", {"image_2"}, 0);
  obj.camera_boxes[0].box = {500.25, 300.5, 560.75, 350.0};
  e.added = {obj};
  TempDir out;
  WriteCoco2D(log, {e}, out / "c.json", {.real_boxes = false, .description = "test"});
  const nlohmann::json j = ReadJsonFile(out / "c.json");
  ASSERT_EQ(j["annotations"].size(), 1u);
  const nlohmann::json& a = j["annotations"][0];
  EXPECT_EQ(a["bbox"], nlohmann::json({500.25, 300.5, 60.5, 49.5}));
  EXPECT_EQ(a["area"].get<double>(), 60.5 * 49.5);
  EXPECT_EQ(a["iscrowd"].get<int>(), 0);
  EXPECT_EQ(a["category_id"].get<int>(), CategoryIdOf("barrier"));
  EXPECT_TRUE(a["synthetic"].get<bool>());
  EXPECT_EQ(j["info"]["description"], "test");
  const Coco2D coco = ReadCoco2D(out / "c.json");
  EXPECT_EQ(coco.annotations[0].box.x1, 500.25);
  EXPECT_EQ(coco.annotations[0].box.y1, 300.5);
  EXPECT_EQ(coco.annotations[0].box.x2, 560.75);
  EXPECT_EQ(coco.annotations[0].box.y2, 350.0);
}

TEST(Coco2D, DeterministicBytesAndStableIds) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  std::vector<FrameEdit> edits(3);
  for (size_t f = 0; f < 3; ++f) {
    edits[f].frame_index = f;
    edits[f].added = {Added("traffic_cone", {"image_2"}, 100.0 * static_cast<double>(f + 1))};
  }
  TempDir out;
  WriteCoco2D(log, edits, out / "a.json");
  WriteCoco2D(log, edits, out / "b.json");
  std::vector<FrameEdit> reversed(edits.rbegin(), edits.rend());
  WriteCoco2D(log, reversed, out / "c.json");
  const std::string a = ReadFileToString(out / "a.json");
  EXPECT_EQ(ReadFileToString(out / "b.json"), a);
  EXPECT_EQ(ReadFileToString(out / "c.json"), a);  // the order of edits does not matter
  // A frame's image keeps its id when written alone (shard outputs merge without clashes).
  WriteCoco2D(log, {edits[2]}, out / "d.json");
  const Coco2D all = ReadCoco2D(out / "a.json"), one = ReadCoco2D(out / "d.json");
  ASSERT_EQ(all.images.size(), 3u);
  ASSERT_EQ(one.images.size(), 1u);
  EXPECT_EQ(one.images[0].id, all.images[2].id);
  EXPECT_EQ(one.images[0].file_name, all.images[2].file_name);
}

TEST(Coco2D, RejectsBadEditsAndFiles) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  TempDir out;
  FrameEdit bad_frame;
  bad_frame.frame_index = 9;
  EXPECT_THROW(WriteCoco2D(log, {bad_frame}, out / "x.json"), InputError);
  FrameEdit bad_camera;
  bad_camera.added = {Added("car", {"CAM_FRONT"}, 10)};
  EXPECT_THROW(WriteCoco2D(log, {bad_camera}, out / "x.json"), InputError);
  FrameEdit bad_category;
  bad_category.added = {Added("car", {"image_2"}, 10)};
  bad_category.added[0].category = "spaceship";
  EXPECT_THROW(WriteCoco2D(log, {bad_category}, out / "x.json"), InputError);
  EXPECT_FALSE(fs::exists(out / "x.json"));  // nothing written on error

  auto expect_error = [&](const std::string& text, const std::string& fragment) {
    const fs::path p = out / "bad.json";
    WriteFileAtomic(p, text);
    try {
      ReadCoco2D(p);
      ADD_FAILURE() << "no error for " << text;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("bad.json"), std::string::npos) << msg;
      EXPECT_NE(msg.find(fragment), std::string::npos) << msg;
    }
  };
  const std::string cats = R"("categories": [{"id": 1, "name": "car"}])";
  const std::string image = R"("images": [{"id": 1, "file_name": "a.png", "width": 10, "height": 10}])";
  expect_error("{\"images\": [", "");
  expect_error("[]", "expected");
  expect_error("{" + image + ", \"annotations\": []}", "categories");
  expect_error("{" + image + ", " + cats + R"(, "annotations": [{"id": 1, "image_id": 2, "category_id": 1, "bbox": [0, 0, 1, 1]}]})",
               "no image with id 2");
  expect_error("{" + image + ", " + cats + R"(, "annotations": [{"id": 1, "image_id": 1, "category_id": 5, "bbox": [0, 0, 1, 1]}]})",
               "no category with id 5");
  expect_error("{" + image + ", " + cats + R"(, "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 1]}]})",
               "4 numbers");
  expect_error("{" + image + ", " + cats + R"(, "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, -1, 1]}]})",
               "negative");
  expect_error("{" + image + ", " + cats + R"(, "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, "a", 1]}]})",
               "bbox[2]");
  expect_error("{" + image + ", " + cats +
                   R"(, "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 1, 1]},
                                         {"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 1, 1]}]})",
               "duplicate annotation id");
  expect_error(R"({"images": [{"id": 1, "file_name": "a.png", "width": 0, "height": 10}], "annotations": [], )" + cats + "}",
               "image size");
  // A minimal file of another tool (no SynthDrive fields) reads.
  WriteFileAtomic(out / "plain.json", "{" + image + ", " + cats +
                                          R"(, "annotations": [{"id": 7, "image_id": 1, "category_id": 1, "bbox": [1, 2, 3, 4]}]})");
  const Coco2D plain = ReadCoco2D(out / "plain.json");
  ASSERT_EQ(plain.annotations.size(), 1u);
  EXPECT_EQ(plain.annotations[0].box.x2, 4.0);
  EXPECT_EQ(plain.annotations[0].box.y2, 6.0);
  EXPECT_EQ(plain.annotations[0].area, 12.0);
  EXPECT_FALSE(plain.annotations[0].synthetic);
  EXPECT_EQ(plain.annotations[0].category, "car");
}

TEST(Coco2D, SharedKitti) {
  SD_REQUIRE_SHARED(root, "driving/kitti-object-openpcdet");
  const Log log = OpenLog(root);
  ASSERT_GE(log.frames.size(), 2u);
  std::vector<FrameEdit> edits(2);
  edits[0].frame_index = log.frames.size() - 1;
  edits[0].added = {Added("debris", {"image_2"}, 300)};
  edits[1].frame_index = 0;
  edits[1].added = {Added("pedestrian", {"image_2"}, 800)};
  EXPECT_GT(ExpectRoundTrip(log, edits), 0u);  // the labels' image_2 boxes
}

TEST(Coco2D, SharedNuScenes) {
  SD_REQUIRE_SHARED(info, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  const Log log = OpenLog(info);
  std::vector<FrameEdit> edits(2);
  edits[0].frame_index = 10;
  edits[0].added = {Added("traffic_cone", {"CAM_FRONT", "CAM_FRONT_RIGHT"}, 900)};
  edits[1].frame_index = 3;
  edits[1].added = {Added("a_frame_sign", {"CAM_BACK"}, 200)};
  ExpectRoundTrip(log, edits);
  SD_REQUIRE_SHARED(tables, "driving/nuscenes-scene0061-kf0");
  FrameEdit e;
  e.added = {Added("portable_traffic_light", {"CAM_FRONT"}, 600)};
  ExpectRoundTrip(OpenLog(tables), {e});
}

}  // namespace
}  // namespace sd
