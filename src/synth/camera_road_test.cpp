#include "synth/camera_road.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <vector>

#include <gtest/gtest.h>

#include "core/error.h"
#include "core/stats.h"
#include "datasets/readers.h"
#include "io/image_io.h"
#include "testing/testing.h"

namespace sd {
namespace {

// The synthetic road: 12 cm below the prior plane (z = 0) with a 1 % cross slope, so a flat prior is wrong
// everywhere and the recovered heights must follow the tilt.
double RoadZ(double /*x*/, double y) { return -0.12 + 0.01 * y; }

// Deterministic value noise: a hash of the integer cell, bilinear between cells (no texture storage).
double CellValue(int64_t i, int64_t j, uint32_t salt) {
  uint64_t h = static_cast<uint64_t>(i) * 0x9E3779B97F4A7C15ull ^ static_cast<uint64_t>(j) * 0xC2B2AE3D27D4EB4Full ^ salt;
  h ^= h >> 31;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 29;
  return static_cast<double>(h & 0xFFFF) / 65535.0 - 0.5;
}
double Noise(double x, double y, double cell, uint32_t salt) {
  const double gx = x / cell, gy = y / cell;
  const int64_t i = static_cast<int64_t>(std::floor(gx)), j = static_cast<int64_t>(std::floor(gy));
  const double ax = gx - i, ay = gy - j;
  return (1 - ay) * ((1 - ax) * CellValue(i, j, salt) + ax * CellValue(i + 1, j, salt)) +
         ay * ((1 - ax) * CellValue(i, j + 1, salt) + ax * CellValue(i + 1, j + 1, salt));
}
// Asphalt-like grain (5 cm) over larger blotches (30 cm), in grey levels.
double RoadTexture(double x, double y) { return 120 + 90 * Noise(x, y, 0.05, 1) + 50 * Noise(x, y, 0.3, 2); }

// R_ego_cam of a camera looking along ego yaw `yaw`, pitched down by `pitch` (radians).
Eigen::Matrix3d LookRotation(double yaw, double pitch) {
  Eigen::Matrix3d forward_cam;  // columns: the camera's x (right), y (down), z (forward) in a +x-looking ego frame
  forward_cam << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()))
             .toRotationMatrix() *
         forward_cam;
}

// Renders the road (sky = one flat grey above the horizon) with 3x3 supersampling; `uniform` paints the road
// one flat grey as well (texture-less asphalt).
ImageU8 RenderRoad(const PinholeCamera& K, const Rigid3d& T_world_cam, bool uniform) {
  ImageU8 img(K.width, K.height, 3);
  for (int y = 0; y < K.height; ++y)
    for (int x = 0; x < K.width; ++x) {
      double sum = 0;
      for (int sy = 0; sy < 3; ++sy)
        for (int sx = 0; sx < 3; ++sx) {
          const Eigen::Vector2d uv(x + (sx + 0.5) / 3, y + (sy + 0.5) / 3);
          const Eigen::Vector3d d = T_world_cam.rotation * K.RayDirection(uv);
          const Eigen::Vector3d o = T_world_cam.translation;
          double value = 200;  // sky
          if (d.z() < -1e-6) {
            // Ray against the tilted plane z = -0.12 + 0.01 y: (o + t d).z = RoadZ(o + t d).
            const double t = (RoadZ(0, o.y()) - o.z()) / (d.z() - 0.01 * d.y());
            if (t > 0) {
              const Eigen::Vector3d p = o + t * d;
              value = uniform ? 110 : RoadTexture(p.x(), p.y());
            }
          }
          sum += value;
        }
      const auto g = static_cast<uint8_t>(std::clamp(std::lround(sum / 9), 0L, 255L));
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = g;
    }
  return img;
}

struct SceneOptions {
  int frames = 2;
  bool uniform = false;
  bool distorted = false;
  double motion = 1.0;  // metres the ego moves forward per frame (10 m/s at 10 Hz)
};

// A two-camera rig (front, and left pitched further down) on an ego moving forward and drifting left a little;
// world = the first frame's ego frame.
Log MakeScene(const testing::TempDir& dir, const SceneOptions& s) {
  Log log;
  log.sequential = true;
  PinholeCamera K;
  K.width = 480;
  K.height = 300;
  K.fx = K.fy = 300;
  K.cx = 240;
  K.cy = 150;
  if (s.distorted) K.distortion.k1 = -0.08, K.distortion.k2 = 0.01;
  const struct {
    const char* channel;
    double yaw, pitch;
    Eigen::Vector3d position;
  } rig[] = {{"CAM_FRONT", 0.0, 0.15, {1.5, 0.0, 1.6}}, {"CAM_LEFT", 1.4, 0.35, {1.0, 0.8, 1.6}}};
  for (int f = 0; f < s.frames; ++f) {
    Frame frame;
    frame.token = std::to_string(f);
    frame.timestamp = 0.1 * f;
    frame.T_world_ego = Rigid3d(Eigen::Matrix3d(Eigen::AngleAxisd(0.02 * f, Eigen::Vector3d::UnitZ())),
                                Eigen::Vector3d(s.motion * f, 0.1 * s.motion * f, 0));
    for (const auto& r : rig) {
      CameraSensor cam;
      cam.channel = r.channel;
      cam.intrinsics = K;
      cam.T_ego_cam = Rigid3d(LookRotation(r.yaw, r.pitch), r.position);
      cam.T_egocam_cam = cam.T_ego_cam;
      cam.timestamp = frame.timestamp;
      cam.image_path = dir / (std::string(r.channel) + "_" + frame.token + ".png");
      WriteImage(cam.image_path, RenderRoad(K, frame.T_world_ego * cam.T_ego_cam, s.uniform));
      frame.cameras.push_back(cam);
    }
    log.frames.push_back(frame);
  }
  return log;
}

// |found height - true road height| at each point's (x, y), in the reference ego frame (= world for frame 0).
std::vector<double> HeightErrors(const CameraRoadResult& r) {
  std::vector<double> err;
  for (const Eigen::Vector3d& p : r.points_ego) err.push_back(std::abs(p.z() - RoadZ(p.x(), p.y())));
  std::sort(err.begin(), err.end());
  return err;
}

void ExpectRecovered(const CameraRoadResult& r) {
  ASSERT_GT(r.pixels_accepted, 300) << r.summary;
  EXPECT_EQ(r.points_ego.size(), r.camera_of.size());
  const std::vector<double> err = HeightErrors(r);
  const double median = err[err.size() / 2], p90 = err[err.size() * 9 / 10];
  EXPECT_LT(median, 0.02) << r.summary;
  EXPECT_LT(p90, 0.04) << r.summary;
  // Never wrong data: no point far off the road.
  EXPECT_LT(err.back(), 0.15) << r.summary;
  // Both cameras contribute, unbiased (the front one sees forward motion, the left one sideways parallax).
  for (int c = 0; c < 2; ++c) {
    std::vector<double> signed_err;
    for (size_t k = 0; k < r.points_ego.size(); ++k)
      if (r.camera_of[k] == c) signed_err.push_back(r.points_ego[k].z() - RoadZ(r.points_ego[k].x(), r.points_ego[k].y()));
    EXPECT_GT(signed_err.size(), 50u) << "camera " << c;
    EXPECT_LT(std::abs(Median(signed_err)), 0.01) << "camera " << c;
  }
  for (const Eigen::Vector3d& p : r.points_ego) EXPECT_LE(p.head<2>().norm(), 40.5);
}

TEST(CameraRoadTest, RecoversAnOffsetTiltedRoadFromTwoFrames) {
  testing::TempDir dir;
  const Log log = MakeScene(dir, {});
  const CameraRoadResult r = EstimateRoadFromCameras(log, 0, 0.0);
  EXPECT_EQ(r.source_views, 2);
  EXPECT_EQ(r.cameras_used, 2);
  EXPECT_NE(r.summary.find("stereo over 2 source views of 2 cameras"), std::string::npos) << r.summary;
  ExpectRecovered(r);
  // The second frame, matched backwards against the first: the same road in its own ego frame.
  const CameraRoadResult back = EstimateRoadFromCameras(log, 1, 0.0);
  ASSERT_GT(back.pixels_accepted, 300) << back.summary;
  std::vector<double> err;
  for (const Eigen::Vector3d& p : back.points_ego) {
    const Eigen::Vector3d w = log.frames[1].T_world_ego * p;
    err.push_back(std::abs(w.z() - RoadZ(w.x(), w.y())));
  }
  EXPECT_LT(Median(err), 0.02);
}

TEST(CameraRoadTest, HandlesDistortedCameras) {
  testing::TempDir dir;
  SceneOptions s;
  s.distorted = true;
  ExpectRecovered(EstimateRoadFromCameras(MakeScene(dir, s), 0, 0.0));
}

TEST(CameraRoadTest, AFrameWithoutNeighboursGivesNoPoints) {
  testing::TempDir dir;
  SceneOptions s;
  s.frames = 1;
  const CameraRoadResult r = EstimateRoadFromCameras(MakeScene(dir, s), 0, 0.0);
  EXPECT_TRUE(r.points_ego.empty());
  EXPECT_EQ(r.source_views, 0);
  EXPECT_NE(r.summary.find("no neighbouring frame"), std::string::npos) << r.summary;

  // Two frames too far apart in time, or frames that are not a sequence: the same.
  Log far = MakeScene(dir, {});
  far.frames[1].timestamp = 5.0;
  EXPECT_NE(EstimateRoadFromCameras(far, 0, 0.0).summary.find("no neighbouring frame"), std::string::npos);
  Log unordered = MakeScene(dir, {});
  unordered.sequential = false;
  const CameraRoadResult u = EstimateRoadFromCameras(unordered, 0, 0.0);
  EXPECT_TRUE(u.points_ego.empty());
  EXPECT_NE(u.summary.find("not a sequence"), std::string::npos) << u.summary;
}

TEST(CameraRoadTest, AParkedCarGivesNoParallaxAndNoPoints) {
  testing::TempDir dir;
  SceneOptions s;
  s.motion = 0.0;
  Log log = MakeScene(dir, s);
  const CameraRoadResult r = EstimateRoadFromCameras(log, 0, 0.0);
  EXPECT_TRUE(r.points_ego.empty());
  EXPECT_EQ(r.source_views, 0);
  EXPECT_NE(r.summary.find(": none"), std::string::npos) << r.summary;
}

TEST(CameraRoadTest, TexturelessRoadGivesNoPoints) {
  testing::TempDir dir;
  SceneOptions s;
  s.uniform = true;
  const CameraRoadResult r = EstimateRoadFromCameras(MakeScene(dir, s), 0, 0.0);
  EXPECT_GT(r.pixels_tried, 1000) << r.summary;
  EXPECT_EQ(r.pixels_accepted, 0) << r.summary;
  EXPECT_TRUE(r.points_ego.empty());
}

TEST(CameraRoadTest, MissingImagesAreLeftOutAndBrokenOnesNamed) {
  testing::TempDir dir;
  Log log = MakeScene(dir, {});
  // A source image missing: that camera has no source, the other still works.
  std::filesystem::remove(log.frames[1].cameras[1].image_path);
  const CameraRoadResult r = EstimateRoadFromCameras(log, 0, 0.0);
  EXPECT_EQ(r.cameras_used, 1);
  ASSERT_EQ(r.skipped.size(), 1u);
  EXPECT_NE(r.skipped[0].find("image missing"), std::string::npos) << r.skipped[0];
  EXPECT_GT(r.pixels_accepted, 100) << r.summary;
  for (int c : r.camera_of) EXPECT_EQ(c, 0);
  // The reference image missing.
  std::filesystem::remove(log.frames[0].cameras[0].image_path);
  const CameraRoadResult none = EstimateRoadFromCameras(log, 0, 0.0);
  EXPECT_TRUE(none.points_ego.empty());
  EXPECT_NE(none.summary.find("none"), std::string::npos) << none.summary;

  // An image that exists but is not one: InputError naming the file.
  Log broken = MakeScene(dir, {});
  std::ofstream(broken.frames[0].cameras[0].image_path, std::ios::binary) << "not an image";
  try {
    EstimateRoadFromCameras(broken, 0, 0.0);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(broken.frames[0].cameras[0].image_path.string()), std::string::npos) << e.what();
  }
}

// The repo's nuScenes keyframe is one frame: no neighbour, no points, said so.
TEST(CameraRoadTest, TheRepoKeyframeHasNoNeighbour) {
  const Log log = OpenLog(testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  ASSERT_EQ(log.frames.size(), 1u);
  const CameraRoadResult r = EstimateRoadFromCameras(log, 0, 0.0);
  EXPECT_TRUE(r.points_ego.empty());
  EXPECT_NE(r.summary.find("no neighbouring frame"), std::string::npos) << r.summary;
}

// Real data where present: PandaSet's road is recovered near the ego origin's known height above it.
TEST(CameraRoadTest, PandaSetFrontCameraFindsTheRoad) {
  SD_REQUIRE_SHARED(seq, "driving/pandaset-002-f44-55");
  Log log = OpenLog(seq);
  ASSERT_GE(log.frames.size(), 3u);
  for (Frame& f : log.frames) {  // one camera keeps the test short
    std::vector<CameraSensor> front;
    for (const CameraSensor& c : f.cameras)
      if (c.channel == "front_camera") front.push_back(c);
    f.cameras = front;
  }
  ASSERT_EQ(log.frames[1].cameras.size(), 1u);
  const CameraRoadResult r = EstimateRoadFromCameras(log, 1, -0.30);
  ASSERT_GT(r.pixels_accepted, 100) << r.summary;
  std::vector<double> near;
  for (const Eigen::Vector3d& p : r.points_ego)
    if (p.head<2>().norm() < 15) near.push_back(p.z());
  ASSERT_GT(near.size(), 20u) << r.summary;
  EXPECT_NEAR(Median(near), -0.30, 0.15) << r.summary;
}

}  // namespace
}  // namespace sd
