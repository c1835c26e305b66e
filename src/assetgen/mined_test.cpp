#include "assetgen/mined.h"

#include <gtest/gtest.h>

#include "assetgen/views.h"
#include "core/error.h"
#include "mining/index.h"
#include "mining/query.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;

Box3 BoxAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& heading_cam) {
  // A box whose +x points along `heading_cam` (horizontal in the camera: y = 0), z along camera -y (up).
  const Eigen::Vector3d x = heading_cam.normalized(), z(0, -1, 0);
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = z.cross(x);
  R.col(2) = z;
  Box3 b;
  b.T_frame_box = Rigid3d(R, centre);
  b.size = {4.5, 1.9, 1.6};
  return b;
}

TEST(RigFront, FollowsTheBoxHeadingRelativeToTheRay) {
  // Facing the camera: the front points at the photo's camera, which the rig puts on +x.
  EXPECT_TRUE(RigFrontFromCameraBox(BoxAt({0, 0, 10}, {0, 0, -1})).isApprox(Eigen::Vector3d::UnitX(), 1e-12));
  // Facing away: -x. Driving to the photo's right: the rig's +y.
  EXPECT_TRUE(RigFrontFromCameraBox(BoxAt({0, 0, 10}, {0, 0, 1})).isApprox(-Eigen::Vector3d::UnitX(), 1e-12));
  EXPECT_TRUE(RigFrontFromCameraBox(BoxAt({0, 0, 10}, {1, 0, 0})).isApprox(Eigen::Vector3d::UnitY(), 1e-12));
  // Off-axis object, heading along its own ray (driving away from the camera): still -x — the facing is
  // relative to the ray through the object, as the crop sees it, not to the camera's optical axis.
  EXPECT_TRUE(RigFrontFromCameraBox(BoxAt({10, 0.5, 10}, {1, 0, 1})).isApprox(-Eigen::Vector3d::UnitX(), 1e-12));
}

TEST(RigFront, MatchesTheRigCameraAtAzimuthZero) {
  // The convention above is the rig's: the camera at azimuth 0 has its right along +y and looks along -x.
  const ViewCamera cam = OrbitCamera("az0", 0, 0, kRigDistance, 30, 64, 64);
  const Eigen::Matrix3d R = cam.T_world_cam.Rotation();
  EXPECT_TRUE((R * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE((R * Eigen::Vector3d::UnitZ()).isApprox(-Eigen::Vector3d::UnitX(), 1e-12));
}

// Mined from the repo's KITTI frames: each car hit loads with its crop, a box inside it, its LiDAR mask as the
// prior, the 3D box's size and a horizontal facing.
TEST(MinedObject, LoadsLogHitsWithPriorSizeAndFacing) {
  testing::TempDir tmp;
  mining::IndexBuildOptions o;
  o.sources = {{mining::SourceKind::kLog, testing::RepoData("driving/kitti-object")}};
  o.progress = false;
  mining::BuildIndex(tmp / "index", o);
  const mining::MiningIndex index = mining::MiningIndex::Open(tmp / "index");
  mining::QueryOptions q;
  q.prompts = {"car"};
  q.min_size_px = 0;
  q.max_truncation = 1;
  q.max_occlusion = 1;
  const auto results = mining::RunQuery(index, q);
  ASSERT_FALSE(results[0].hits.empty());
  mining::WriteMiningRun(tmp / "run", index, results, q, false);
  const auto entries = mining::ReadManifest(tmp / "run" / "manifest.jsonl");
  ASSERT_EQ(entries.size(), results[0].hits.size());
  for (const auto& e : entries) {
    const MinedObject m = LoadMinedObject(e);
    EXPECT_EQ(m.category, "car");
    ASSERT_TRUE(m.size_lwh.has_value());
    EXPECT_EQ(*m.size_lwh, e.item.box_ego->size);
    ASSERT_TRUE(m.front_in_rig.has_value());
    EXPECT_NEAR(m.front_in_rig->norm(), 1.0, 1e-9);
    EXPECT_NEAR(m.front_in_rig->z(), 0.0, 1e-12);
    EXPECT_GE(m.box.x1, 0);
    EXPECT_LE(m.box.x2, m.image.width());
    EXPECT_GT(m.box.Area(), 0.3 * m.image.width() * m.image.height());  // the crop is the box plus context
    ASSERT_TRUE(m.prior.has_value());
    EXPECT_EQ(m.prior->source, e.item.mask_source);
    // The mask lies inside the object's box (the projected 3D box bounds it), to a pixel of rounding.
    for (int y = 0; y < m.image.height(); ++y)
      for (int x = 0; x < m.image.width(); ++x)
        if (m.prior->mask.at(x, y) > 127) {
          ASSERT_GE(x + 1.5, m.box.x1);
          ASSERT_LE(x - 1.5, m.box.x2);
          ASSERT_GE(y + 1.5, m.box.y1);
          ASSERT_LE(y - 1.5, m.box.y2);
        }
  }
  // A hit whose crop file is gone is refused naming the file.
  mining::ManifestEntry broken = entries[0];
  broken.item.crop_file = (tmp / "run" / "crops" / "missing.jpg").string();
  EXPECT_THROW(LoadMinedObject(broken), InputError);
}

}  // namespace
}  // namespace sd
