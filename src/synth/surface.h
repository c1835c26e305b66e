#pragma once
// The road surface as placement, shading and LiDAR simulation query it, in the WORLD frame of a log (the
// dataset's global / map frame; identity for KITTI, whose frames have no world pose).
//
// Why an interface: the surface is reconstructed from a whole sequence (synth/road_surface.h: LiDAR sweeps
// aggregated with the ego poses), while sequence planning (synth/sequence_plan.h) and tests only need to ask
// "how high is the road here, which way does it face, may an object stand here". Tests use PlaneSurface.
#include <optional>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace sd {

struct SurfacePoint {
  double height = 0;                                  // world z of the road at (x, y), metres
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, z > 0
  bool observed = false;  // true where LiDAR measured the road here; false where a hole was filled
};

class SurfaceModel {
 public:
  virtual ~SurfaceModel() = default;
  // nullopt outside the surface's extent (nothing measured or filled there).
  virtual std::optional<SurfacePoint> At(const Eigen::Vector2d& xy_world) const = 0;
  // Drivable area: road an object may stand on (not a kerb top, wall, vegetation or unknown ground).
  virtual bool IsDrivable(const Eigen::Vector2d& xy_world) const = 0;
};

// An infinite plane n.p + d = 0, drivable everywhere or within an axis-aligned xy rectangle: for tests.
class PlaneSurface final : public SurfaceModel {
 public:
  explicit PlaneSurface(const Eigen::Vector3d& normal = Eigen::Vector3d::UnitZ(), double d = 0)
      : normal_(normal.normalized()), d_(d / normal.norm()) {}
  PlaneSurface& WithDrivableBox(const Eigen::AlignedBox2d& box) {
    drivable_ = box;
    return *this;
  }
  std::optional<SurfacePoint> At(const Eigen::Vector2d& xy) const override {
    return SurfacePoint{-(d_ + normal_.x() * xy.x() + normal_.y() * xy.y()) / normal_.z(), normal_, true};
  }
  bool IsDrivable(const Eigen::Vector2d& xy) const override { return !drivable_ || drivable_->contains(xy); }

 private:
  Eigen::Vector3d normal_;
  double d_;
  std::optional<Eigen::AlignedBox2d> drivable_;
};

}  // namespace sd
