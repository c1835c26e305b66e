#include "datasets/categories.h"

#include <gtest/gtest.h>

namespace sd {
namespace {

TEST(Categories, FourteenCanonicalWithSizes) {
  ASSERT_EQ(Categories().size(), 14u);
  for (const CategoryInfo& c : Categories()) {
    EXPECT_GT(c.default_size.minCoeff(), 0.0) << c.name;
    EXPECT_GT(c.lidar_reflectivity, 0.0) << c.name;
  }
  const auto cone = FindCategory("traffic_cone");
  ASSERT_TRUE(cone);
  EXPECT_NEAR(cone->default_size.x(), 0.41, 1e-9);
  EXPECT_NEAR(cone->default_size.z(), 1.07, 1e-9);
  const auto barrier = FindCategory("barrier");
  ASSERT_TRUE(barrier);
  EXPECT_NEAR(barrier->default_size.x(), 2.53, 1e-9);  // length first
  EXPECT_NEAR(barrier->default_size.y(), 0.50, 1e-9);
}

TEST(Categories, FindsEveryDatasetNameCaseInsensitively) {
  EXPECT_EQ(FindCategory("movable_object.trafficcone")->name, "traffic_cone");
  EXPECT_EQ(FindCategory("MOVABLE_OBJECT.BARRIER")->name, "barrier");
  EXPECT_EQ(FindCategory("vehicle.car")->name, "car");
  EXPECT_EQ(FindCategory("human.pedestrian.adult")->name, "pedestrian");
  EXPECT_EQ(FindCategory("Car")->name, "car");
  EXPECT_EQ(FindCategory("cyclist")->name, "bicycle");
  EXPECT_EQ(FindCategory("TrafficCone")->name, "traffic_cone");
  EXPECT_EQ(FindCategory("Warning_Tripod")->name, "warning_tripod");
  EXPECT_EQ(FindCategory("Van")->name, "car");
  EXPECT_FALSE(FindCategory("unicorn"));
  for (const CategoryInfo& c : Categories()) {
    EXPECT_EQ(FindCategory(c.nuscenes_name)->name, c.name);
    EXPECT_EQ(FindCategory(c.kitti_name)->name, c.name);
  }
}

TEST(Categories, Argoverse2Names) {
  EXPECT_EQ(FindCategory("REGULAR_VEHICLE")->name, "car");
  EXPECT_EQ(FindCategory("BOX_TRUCK")->name, "truck");
  EXPECT_EQ(FindCategory("TRUCK_CAB")->name, "truck");
  EXPECT_EQ(FindCategory("VEHICULAR_TRAILER")->name, "trailer");
  EXPECT_EQ(FindCategory("PEDESTRIAN")->name, "pedestrian");
  EXPECT_EQ(FindCategory("BICYCLE")->name, "bicycle");
  EXPECT_EQ(FindCategory("MOTORCYCLE")->name, "motorcycle");
  EXPECT_EQ(FindCategory("CONSTRUCTION_CONE")->name, "traffic_cone");
  EXPECT_EQ(FindCategory("ARTICULATED_BUS")->name, "bus");
  EXPECT_FALSE(FindCategory("STROLLER"));  // no canonical counterpart of that shape
  EXPECT_FALSE(FindCategory("BOLLARD"));
  EXPECT_FALSE(FindCategory("SIGN"));
}

TEST(Categories, DatasetNames) {
  const CategoryInfo ped = *FindCategory("pedestrian");
  EXPECT_EQ(DatasetCategoryName(ped, LogFormat::kKitti), "Pedestrian");
  EXPECT_EQ(DatasetCategoryName(ped, LogFormat::kNuScenesTables), "human.pedestrian.adult");
  EXPECT_EQ(DatasetCategoryName(ped, LogFormat::kMmdet3dV1), "pedestrian");
  EXPECT_EQ(DatasetCategoryName(*FindCategory("bicycle"), LogFormat::kKitti), "Cyclist");
  EXPECT_EQ(DatasetCategoryName(*FindCategory("a_frame_sign"), LogFormat::kKitti), "AFrameSign");
}

}  // namespace
}  // namespace sd
