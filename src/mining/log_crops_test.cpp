#include "mining/log_crops.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <numbers>

#include "core/error.h"
#include "datasets/readers.h"
#include "geometry/box_projection.h"
#include "io/image_io.h"
#include "testing/testing.h"

namespace sd::mining {
namespace {

namespace fs = std::filesystem;
using sd::testing::RepoData;
using sd::testing::TempDir;
using Vec2 = Eigen::Vector2d;

const char* kKf0Info = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

// --- Independent geometry for the checks: the 8 corners' projections, their hull, a point-in-polygon test. ---

// Projected corners of a box all of whose corners lie in front of the camera (else empty).
std::vector<Vec2> CornerProjections(const Box3& box, const CameraSensor& cam) {
  std::vector<Vec2> uv;
  for (const Eigen::Vector3d& c : box.Corners()) {
    const Eigen::Vector3d p = cam.T_ego_cam.Inverse() * c;
    if (p.z() <= 0.5) return {};
    uv.emplace_back(cam.intrinsics.fx * p.x() / p.z() + cam.intrinsics.cx, cam.intrinsics.fy * p.y() / p.z() + cam.intrinsics.cy);
  }
  return uv;
}

// Gift wrapping; orientation-free inside test below, so the hull's direction does not matter.
std::vector<Vec2> Hull(const std::vector<Vec2>& pts) {
  std::vector<Vec2> hull;
  size_t start = 0;
  for (size_t i = 1; i < pts.size(); ++i)
    if (pts[i].x() < pts[start].x()) start = i;
  size_t p = start;
  do {
    hull.push_back(pts[p]);
    size_t q = (p + 1) % pts.size();
    for (size_t r = 0; r < pts.size(); ++r) {
      const Vec2 a = pts[q] - pts[p], b = pts[r] - pts[p];
      const double cr = a.x() * b.y() - a.y() * b.x();
      if (cr < 0 || (cr == 0 && b.norm() > a.norm())) q = r;
    }
    p = q;
  } while (p != start && hull.size() <= pts.size());
  return hull;
}

// Signed distance of (u, v) outside a convex polygon's edges (<= 0 inside), any orientation.
double OutsideDistance(const std::vector<Vec2>& poly, double u, double v) {
  double area2 = 0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vec2& a = poly[i];
    const Vec2& b = poly[(i + 1) % poly.size()];
    area2 += a.x() * b.y() - b.x() * a.y();
  }
  const double sign = area2 > 0 ? 1 : -1;
  double worst = -1e18;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vec2& a = poly[i];
    const Vec2& b = poly[(i + 1) % poly.size()];
    const Vec2 e = b - a;
    const double cr = sign * (e.x() * (v - a.y()) - e.y() * (u - a.x()));
    worst = std::max(worst, -cr / e.norm());
  }
  return worst;
}

double PolyArea(const std::vector<Vec2>& poly) {
  double a = 0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vec2& p = poly[i];
    const Vec2& q = poly[(i + 1) % poly.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return std::abs(a) / 2;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? std::nan("") : v[v.size() / 2];
}

struct FrameStats {
  int crops = 0, lidar_masks = 0, mask_pixels_checked = 0, polygons_checked = 0;
};

// Per-crop invariants: size limit and scale, mask inside the projected box (from the corners, rasterised
// here), item fields.
void CheckCrops(const Frame& frame, const std::vector<ObjectCrop>& crops, const LogCropOptions& opt, FrameStats* stats) {
  for (const ObjectCrop& c : crops) {
    const MinedItem& it = c.item;
    ++stats->crops;
    stats->lidar_masks += it.mask_source == "lidar";
    EXPECT_TRUE(it.mask_source == "lidar" || it.mask_source == "box") << it.mask_source;
    EXPECT_EQ(it.kind, SourceKind::kLog);
    EXPECT_EQ(it.frame_token, frame.token);
    const CameraSensor* cam = frame.FindCamera(it.camera);
    ASSERT_NE(cam, nullptr) << it.camera;
    EXPECT_EQ(it.origin, cam->image_path.string());
    ASSERT_TRUE(it.box_ego && it.camera_intrinsics);
    EXPECT_EQ(it.camera_intrinsics->fx, cam->intrinsics.fx);
    EXPECT_LE(std::max(it.crop_width, it.crop_height), opt.max_crop_px);
    EXPECT_EQ(c.image.width(), it.crop_width);
    EXPECT_EQ(c.image.height(), it.crop_height);
    EXPECT_EQ(c.image.channels(), 3);
    EXPECT_EQ(c.mask.width(), it.crop_width);
    EXPECT_EQ(c.mask.channels(), 1);
    const double rw = it.crop_rect.x2 - it.crop_rect.x1, rh = it.crop_rect.y2 - it.crop_rect.y1;
    EXPECT_NEAR(it.crop_width, rw * it.crop_scale, 1.0);
    EXPECT_NEAR(it.crop_height, rh * it.crop_scale, 1.0);
    if (std::max(rw, rh) <= opt.max_crop_px) {
      EXPECT_EQ(it.crop_scale, 1.0);
    }
    EXPECT_GE(it.box2d.x1, it.crop_rect.x1);
    EXPECT_LE(it.box2d.x2, it.crop_rect.x2);
    EXPECT_GE(it.truncation, 0);
    EXPECT_LE(it.truncation, opt.max_truncation);
    EXPECT_GE(std::min(it.box2d.x2 - it.box2d.x1, it.box2d.y2 - it.box2d.y1), opt.min_box_px);

    const std::vector<Vec2> corners = CornerProjections(*it.box_ego, *cam);
    if (corners.empty() || !cam->intrinsics.distortion.IsZero()) continue;
    const std::vector<Vec2> poly = Hull(corners);
    ++stats->polygons_checked;
    // Mask pixel centres, back in source pixels, inside the polygon (within one crop pixel when downscaled).
    const double tol = it.crop_scale < 1 ? 1.0 / it.crop_scale : 1e-6;
    int outside = 0, on = 0;
    for (int y = 0; y < c.mask.height(); ++y)
      for (int x = 0; x < c.mask.width(); ++x) {
        if (!c.mask.at(x, y)) continue;
        ++on;
        const double u = it.crop_rect.x1 + (x + 0.5) / it.crop_scale, v = it.crop_rect.y1 + (y + 0.5) / it.crop_scale;
        outside += OutsideDistance(poly, u, v) > tol;
      }
    stats->mask_pixels_checked += on;
    EXPECT_EQ(outside, 0) << it.camera << " " << it.dataset_category;
    EXPECT_GT(on, 0);
  }
}

// --- Synthetic camera looking along ego +x (camera z = ego x, camera x = -ego y, camera y = -ego z). ---

CameraSensor SyntheticCamera(const fs::path& image_path) {
  CameraSensor cam;
  cam.channel = "CAM_SYN";
  cam.image_path = image_path;
  cam.intrinsics.width = 640;
  cam.intrinsics.height = 480;
  cam.intrinsics.fx = cam.intrinsics.fy = 500;
  cam.intrinsics.cx = 320;
  cam.intrinsics.cy = 240;
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d(0, -1, 0);
  R.col(1) = Eigen::Vector3d(0, 0, -1);
  R.col(2) = Eigen::Vector3d(1, 0, 0);
  cam.T_ego_cam = Rigid3d(R, Eigen::Vector3d::Zero());
  return cam;
}

Box3 AxisBox(const Eigen::Vector3d& centre, const Eigen::Vector3d& size) {
  Box3 b;
  b.T_frame_box = Rigid3d(Eigen::Matrix3d::Identity(), centre);
  b.size = size;
  return b;
}

Frame SyntheticFrame(const TempDir& tmp) {
  const fs::path img = tmp / "syn.png";
  ImageU8 image(640, 480, 3, 90);
  WriteImage(img, image);
  Frame f;
  f.token = "syn";
  f.cameras.push_back(SyntheticCamera(img));
  return f;
}

TEST(LogCrops, HalfOutsideTheImageHasTruncationOneHalf) {
  TempDir tmp;
  Frame f = SyntheticFrame(tmp);
  // A thin board 10 m ahead, 2 m wide: 100 px wide, centred on the right image edge (x/z = 0.64 -> u = 640).
  Annotation a;
  a.category = "car";
  a.box = AxisBox({10, -6.4, 0}, {0, 2, 1});  // zero depth: the outline is exactly a rectangle
  f.annotations.push_back(a);
  const std::vector<ObjectCrop> crops = CropFrameObjects(f, {}, {});
  ASSERT_EQ(crops.size(), 1u);
  const MinedItem& it = crops[0].item;
  EXPECT_NEAR(it.truncation, 0.5, 1e-3);
  EXPECT_NEAR(it.box2d.x1, 590, 1e-6);
  EXPECT_NEAR(it.box2d.x2, 640, 1e-9);
  EXPECT_NEAR(it.box2d.y1, 215, 0.1);
  EXPECT_NEAR(it.box2d.y2, 265, 0.1);
  EXPECT_EQ(it.mask_source, "box");  // no sweep
  EXPECT_EQ(it.lidar_points, -1);
  EXPECT_EQ(it.occlusion, -1);
  EXPECT_EQ(it.category, "car");
  // Context 0.1: 5 px each side, clipped at the right edge.
  EXPECT_NEAR(it.crop_rect.x1, 585, 1);
  EXPECT_EQ(it.crop_rect.x2, 640);
  EXPECT_NEAR(it.crop_rect.y1, 210, 1);
  EXPECT_NEAR(it.crop_rect.y2, 270, 1);
  EXPECT_EQ(crops[0].image.at(3, 3, 1), 90);
  // The "box" mask is the polygon: 45 x 50 px of the 55 x 60 window (pixel centres inside).
  int on = 0;
  for (uint8_t v : crops[0].mask.vector()) on += v == 255;
  EXPECT_NEAR(on, 50 * 50, 110);
}

TEST(LogCrops, BoxStraddlingTheCameraPlaneIsClippedAtTheNearPlane) {
  TempDir tmp;
  Frame f = SyntheticFrame(tmp);
  // 6 m long, from 2.5 m behind the camera to 3.5 m ahead, 1.5 m to the left.
  Annotation a;
  a.category = "truck";
  a.box = AxisBox({0.5, 1.5, 0}, {6, 1, 2});
  f.annotations.push_back(a);
  const std::vector<Vec2> poly = geometry::ProjectBoxOutline(f.cameras[0].intrinsics, f.cameras[0].T_ego_cam.Inverse(), a.box, 0.5);
  ASSERT_GE(poly.size(), 3u);
  for (const Vec2& p : poly) EXPECT_TRUE(std::isfinite(p.x()) && std::isfinite(p.y()));
  // Without clipping its rear corners would project mirrored; with it the outline reaches the left side only:
  // the near-plane section (z = 0.5 m, y from 1 to 2 m) projects to u = 320 - 500 * [1, 2] / 0.5.
  double umin = 1e18, umax = -1e18;
  for (const Vec2& p : poly) umin = std::min(umin, p.x()), umax = std::max(umax, p.x());
  EXPECT_NEAR(umin, 320 - 500 * 2 / 0.5, 1e-6);
  EXPECT_NEAR(umax, 320 - 500 * 1 / 3.5, 1e-6);
  LogCropOptions opt;
  opt.max_truncation = 1;
  const std::vector<ObjectCrop> crops = CropFrameObjects(f, {}, opt);
  ASSERT_EQ(crops.size(), 1u);
  const MinedItem& it = crops[0].item;
  EXPECT_TRUE(std::isfinite(it.box2d.x1) && std::isfinite(it.box2d.x2) && std::isfinite(it.box2d.y1) && std::isfinite(it.box2d.y2));
  EXPECT_EQ(it.box2d.x1, 0);
  EXPECT_NEAR(it.box2d.x2, 320 - 500 * 1 / 3.5, 1e-6);
  EXPECT_GT(it.truncation, 0.5);
  EXPECT_LT(it.truncation, 1);
  // Entirely behind the near plane: no outline, no crop.
  EXPECT_TRUE(geometry::ProjectBoxOutline(f.cameras[0].intrinsics, f.cameras[0].T_ego_cam.Inverse(), AxisBox({-3, 0, 0}, {1, 1, 1}), 0.5).empty());
}

// A 2 x 2 m board 10 m ahead, its left half (ego y > 0) behind a wall 5 m ahead. The sweep holds, for every
// LiDAR ray (HDL-32E-like 1.33 x 0.33 deg grid from the camera centre), the wall's return where the ray meets
// the wall and the board's return where it meets the board, both: as if a second sensor saw the board behind the
// wall. The camera cannot: those board returns share their pixel with a wall return 5 m nearer.
TEST(LogCrops, ReturnsHiddenBehindNearerOnesStayOutOfTheMask) {
  TempDir tmp;
  Frame f = SyntheticFrame(tmp);
  Annotation a;
  a.category = "barrier";
  a.box = AxisBox({10, 0, 0}, {0.2, 2, 2});
  f.annotations.push_back(a);
  std::vector<Eigen::Vector3d> sweep;
  const double deg = std::numbers::pi / 180;
  int board = 0, wall_in_outline = 0;
  for (double el = -10; el <= 10; el += 1.33)
    for (double az = -15; az <= 15; az += 0.33) {
      const Eigen::Vector3d ray(1, std::tan(az * deg), std::tan(el * deg) / std::cos(az * deg));
      const Eigen::Vector3d on_board = ray * 10, on_wall = ray * 5;
      if (std::abs(on_board.y()) <= 1 && std::abs(on_board.z()) <= 1) {
        sweep.push_back(on_board);
        ++board;
      }
      if (on_wall.y() >= 0 && on_wall.y() <= 2 && std::abs(on_wall.z()) <= 1) {
        sweep.push_back(on_wall);
        wall_in_outline += on_board.y() >= 0 && on_board.y() <= 1 && std::abs(on_board.z()) <= 1;
      }
    }
  const std::vector<ObjectCrop> crops = CropFrameObjects(f, sweep, {});
  ASSERT_EQ(crops.size(), 1u);
  const MinedItem& it = crops[0].item;
  EXPECT_EQ(it.mask_source, "lidar");
  EXPECT_EQ(it.lidar_points, board);
  // Returns in the outline: all board ones, and the wall's in front of its left half.
  EXPECT_NEAR(it.occlusion, static_cast<double>(wall_in_outline) / (board + wall_in_outline), 0.02);
  std::cout << "board returns " << board << ", wall returns over it " << wall_in_outline << ", occlusion " << it.occlusion << "\n";
  // The board spans u = 320 -+ 50, v = 240 -+ 50 (at 10 m; its 0.2 m depth widens the outline slightly). Left
  // of centre (hidden) nothing, right of centre all of the face but a few pixels at its edges.
  int left = 0, right = 0, right_total = 0;
  const ImageU8& m = crops[0].mask;
  for (int y = 0; y < m.height(); ++y)
    for (int x = 0; x < m.width(); ++x) {
      const double u = it.crop_rect.x1 + x + 0.5, v = it.crop_rect.y1 + y + 0.5;
      if (std::abs(v - 240) > 44) continue;  // rows inside the face, away from its top and bottom edges
      if (u < 315) left += m.at(x, y) != 0;
      if (u > 325 && u < 365) right += m.at(x, y) != 0, ++right_total;
    }
  std::cout << "mask pixels left of centre " << left << ", right " << right << "/" << right_total << "\n";
  EXPECT_LT(left, 0.05 * right_total);
  EXPECT_GT(right, 0.95 * right_total);
}

TEST(LogCrops, LargeCropsAreDownscaledByTheAreaFilter) {
  TempDir tmp;
  Frame f = SyntheticFrame(tmp);
  // Left half black, right half white: the area filter keeps the mean.
  ImageU8 image(640, 480, 3, 0);
  for (int y = 0; y < 480; ++y)
    for (int x = 320; x < 640; ++x)
      for (int c = 0; c < 3; ++c) image.at(x, y, c) = 255;
  WriteImage(f.cameras[0].image_path, image);
  Annotation a;
  a.category = "car";
  a.box = AxisBox({5, 0, 0}, {0, 4, 3});  // 400 x 300 px, centred
  f.annotations.push_back(a);
  LogCropOptions opt;
  opt.context = 0;
  opt.max_crop_px = 100;
  const std::vector<ObjectCrop> crops = CropFrameObjects(f, {}, opt);
  ASSERT_EQ(crops.size(), 1u);
  const MinedItem& it = crops[0].item;
  EXPECT_EQ(it.crop_rect.x1, 120);
  EXPECT_EQ(it.crop_rect.x2, 520);
  EXPECT_DOUBLE_EQ(it.crop_scale, 0.25);
  EXPECT_EQ(it.crop_width, 100);
  EXPECT_EQ(it.crop_height, 75);
  double mean = 0;
  for (uint8_t v : crops[0].image.vector()) mean += v;
  mean /= static_cast<double>(crops[0].image.size());
  EXPECT_NEAR(mean, 127.5, 0.6);
  EXPECT_EQ(crops[0].image.at(49, 10, 0), 0);
  EXPECT_EQ(crops[0].image.at(50, 10, 0), 255);
}

TEST(LogCrops, MissingCameraImageNamesTheFile) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  Frame f = log.frames[1];
  f.cameras[0].image_path = f.cameras[0].image_path.parent_path() / "no_such_image.png";
  try {
    CropFrameObjects(f, {}, {});
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_image.png"), std::string::npos) << e.what();
  }
}

TEST(LogCrops, LyftTablesWithoutImagesNameTheMissingImage) {
  const Log log = OpenLog(RepoData("driving/lyft-tables"));
  ASSERT_FALSE(log.frames.empty());
  bool threw = false;
  for (const Frame& f : log.frames) {
    if (f.annotations.empty()) continue;
    try {
      CropFrameObjects(f, {}, {});
    } catch (const InputError& e) {
      threw = true;
      bool names_one = false;
      for (const CameraSensor& c : f.cameras)
        names_one = names_one || std::string(e.what()).find(c.image_path.filename().string()) != std::string::npos;
      EXPECT_TRUE(names_one) << e.what();
      break;
    }
  }
  EXPECT_TRUE(threw);
}

// KITTI 2D boxes are tight boxes of the object's image, the 3D box's projection encloses it and is larger (the
// box's corners stick out beyond a car's rounded outline). Measured before choosing the threshold: for the
// untruncated, unoccluded objects the IoU is median 0.97, min 0.89 (repo and OpenPCDet frames), so 0.8.
void KittiIoU(const fs::path& root, std::vector<double>* ious, FrameStats* stats) {
  const Log log = OpenLog(root);
  LogCropOptions opt;
  for (const Frame& f : log.frames) {
    const std::vector<Eigen::Vector3d> sweep = SweepInEgo(f);
    const std::vector<ObjectCrop> crops = CropFrameObjects(f, sweep, opt);
    CheckCrops(f, crops, opt, stats);
    for (const ObjectCrop& c : crops) {
      ASSERT_TRUE(c.item.annotated_box2d);
      EXPECT_GE(c.item.lidar_points, 0);
      for (const Annotation& a : f.annotations) {
        if (a.box.center() != c.item.box_ego->center()) continue;
        if (a.truncation == 0 && a.visibility == 0) ious->push_back(IoU(c.item.box2d, *c.item.annotated_box2d));
      }
    }
  }
}

TEST(LogCrops, KittiBoxesMatchTheLabels2dBoxes) {
  std::vector<double> ious;
  FrameStats stats;
  KittiIoU(RepoData("driving/kitti-object"), &ious, &stats);
  ASSERT_GE(ious.size(), 3u);
  std::cout << "KITTI repo: " << stats.crops << " crops in 3 frames, " << stats.lidar_masks << " lidar masks; IoU(box2d, label) over "
            << ious.size() << " unoccluded untruncated: median " << Median(ious) << " min " << *std::min_element(ious.begin(), ious.end())
            << "; " << stats.mask_pixels_checked << " mask pixels in " << stats.polygons_checked << " polygons checked\n";
  EXPECT_GT(Median(ious), 0.8);
  EXPECT_GT(stats.lidar_masks, 0);
}

TEST(LogCrops, KittiOpenPcdetBoxesMatchTheLabels2dBoxes) {
  SD_REQUIRE_SHARED(root, "driving/kitti-object-openpcdet");
  std::vector<double> ious;
  FrameStats stats;
  KittiIoU(root, &ious, &stats);
  ASSERT_GE(ious.size(), 3u);
  std::cout << "KITTI openpcdet: " << stats.crops << " crops, " << stats.lidar_masks << " lidar masks; IoU over " << ious.size()
            << ": median " << Median(ious) << " min " << *std::min_element(ious.begin(), ious.end()) << "\n";
  EXPECT_GT(Median(ious), 0.8);
}

TEST(LogCrops, NuScenesKeyframeCropsMasksAndCamInstances) {
  const Log log = OpenLog(RepoData(kKf0Info));
  const Frame& f = log.frames[0];
  const std::vector<Eigen::Vector3d> sweep = SweepInEgo(f);
  ASSERT_EQ(sweep.size(), 34688u);
  LogCropOptions opt;
  const std::vector<ObjectCrop> crops = CropFrameObjects(f, sweep, opt);
  FrameStats stats;
  CheckCrops(f, crops, opt, &stats);
  std::vector<double> ious;
  int near_cars = 0;
  std::vector<double> ratios;
  for (const ObjectCrop& c : crops) {
    const MinedItem& it = c.item;
    // -1 only where no return lands in the outline (far objects).
    EXPECT_TRUE(it.occlusion == -1 || (it.occlusion >= 0 && it.occlusion <= 1)) << it.occlusion;
    if (it.lidar_points > 0) {
      EXPECT_GE(it.occlusion, 0);
    }
    // mmdet3d's cam_instances bbox is the projected 3D box clipped to the image, as ours, but made from the
    // annotation's full rotation; the info's instances keep only the yaw about the LiDAR's z, so near boxes on
    // tilted ground differ by up to ~20 px (the 15 m truck in CAM_FRONT: IoU 0.86).
    if (it.annotated_box2d) ious.push_back(IoU(it.box2d, *it.annotated_box2d));
    const CameraSensor* cam = f.FindCamera(it.camera);
    const double depth = (cam->T_ego_cam.Inverse() * it.box_ego->center()).z();
    // Near boxy objects with a LiDAR mask: the mask covers a fair part of the box outline and never more.
    // (Not pedestrians: a person fills little of a box sized for swinging limbs; measured 0.18 at 12.6 m.)
    const bool boxy = it.category == "car" || it.category == "truck" || it.category == "bus" || it.category == "barrier";
    if (boxy && depth < 25 && it.mask_source == "lidar" && it.truncation == 0) {
      near_cars += it.category == "car";
      const std::vector<Vec2> poly = Hull(CornerProjections(*it.box_ego, *cam));
      int on = 0;
      for (uint8_t v : c.mask.vector()) on += v == 255;
      const double ratio = on / (it.crop_scale * it.crop_scale) / PolyArea(poly);
      ratios.push_back(ratio);
      EXPECT_GT(ratio, 0.2) << it.camera << " " << it.category << " depth " << depth;
      EXPECT_LE(ratio, 1.02) << it.camera << " " << it.category << " depth " << depth;  // downscaling rounds
    }
  }
  std::cout << "nuScenes kf0: " << crops.size() << " crops over 6 cameras, " << stats.lidar_masks << " lidar masks; " << near_cars
            << " near cars; near boxy lidar-mask objects " << ratios.size() << ", mask/polygon median " << Median(ratios) << " min "
            << (ratios.empty() ? 0 : *std::min_element(ratios.begin(), ratios.end())) << "; IoU(box2d, cam_instances bbox) over " << ious.size()
            << ": median " << Median(ious) << " min " << (ious.empty() ? 0 : *std::min_element(ious.begin(), ious.end())) << "\n";
  EXPECT_GE(near_cars, 1);  // the keyframe has one car within 25 m (CAM_BACK, 18.5 m)
  EXPECT_GE(ratios.size(), 8u);
  ASSERT_GE(ious.size(), 20u);
  EXPECT_GT(Median(ious), 0.9);  // measured 0.951, min 0.858
}

TEST(LogCrops, CategoryAndCameraFilters) {
  const Log log = OpenLog(RepoData(kKf0Info));
  const Frame& f = log.frames[0];
  const std::vector<ObjectCrop> all = CropFrameObjects(f, {}, {});
  std::map<std::string, int> by_camera, by_category;
  for (const ObjectCrop& c : all) ++by_camera[c.item.camera], ++by_category[c.item.category];
  ASSERT_GT(by_camera["CAM_FRONT"], 0);
  ASSERT_GT(by_category["pedestrian"], 0);
  ASSERT_GT(by_category["car"], 0);

  LogCropOptions cams;
  cams.cameras = {"CAM_FRONT"};
  const std::vector<ObjectCrop> front = CropFrameObjects(f, {}, cams);
  EXPECT_EQ(static_cast<int>(front.size()), by_camera["CAM_FRONT"]);
  for (const ObjectCrop& c : front) EXPECT_EQ(c.item.camera, "CAM_FRONT");

  LogCropOptions cats;
  cats.categories = {"pedestrian", "Car"};  // a dataset name is canonicalised too
  const std::vector<ObjectCrop> some = CropFrameObjects(f, {}, cats);
  EXPECT_EQ(static_cast<int>(some.size()), by_category["pedestrian"] + by_category["car"]);
  for (const ObjectCrop& c : some) EXPECT_TRUE(c.item.category == "pedestrian" || c.item.category == "car") << c.item.category;
}

}  // namespace
}  // namespace sd::mining
