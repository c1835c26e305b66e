#pragma once
// Ray casting against triangle meshes. Embree is an implementation detail (pimpl): no rtc* type leaves
// this module. A scene holds meshes already placed in one common frame (the caller transforms them).
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "core/mesh.h"

namespace sd {

struct RayHit {
  float t = std::numeric_limits<float>::infinity();  // distance along the (unit) ray direction; +inf = miss
  int mesh = -1;                                     // index returned by AddMesh
  int face = -1;                                     // triangle index in that mesh
  float u = 0, v = 0;                                // barycentrics: p = (1-u-v)*v0 + u*v1 + v*v2
  bool Hit() const { return mesh >= 0; }
};

class RayScene {
 public:
  RayScene();
  ~RayScene();
  RayScene(RayScene&&) noexcept;
  RayScene& operator=(RayScene&&) noexcept;

  // Adds a mesh (positions in the scene frame). The scene keeps a shared reference for shading lookups.
  int AddMesh(std::shared_ptr<const TriangleMesh> mesh);
  // Must be called after the last AddMesh and before any query.
  void Commit();
  int NumMeshes() const;
  const TriangleMesh& Mesh(int id) const;

  // Nearest hit with t in [t_near, t_far]; `dir` must be unit length. Thread-safe after Commit().
  RayHit Intersect(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near = 0.0f,
                   float t_far = std::numeric_limits<float>::infinity()) const;
  // Any hit in [t_near, t_far] (shadow rays). `skip_mesh` >= 0 ignores that mesh (e.g. the ground receiver).
  bool Occluded(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near, float t_far,
                int skip_mesh = -1) const;
  // Batch form of Intersect for many rays (LiDAR); parallel. origins/dirs same size.
  std::vector<RayHit> IntersectMany(const std::vector<Eigen::Vector3f>& origins,
                                    const std::vector<Eigen::Vector3f>& dirs, float t_near = 0.0f) const;

  // Hit point, interpolated attributes.
  Eigen::Vector3f HitPoint(const RayHit& hit) const;
  Eigen::Vector3f ShadingNormal(const RayHit& hit) const;  // interpolated vertex normal, or face normal
  Eigen::Vector3f GeometricNormal(const RayHit& hit) const;
  // Base colour (linear RGBA) at the hit: material factor x texture (bilinear, sRGB->linear) x vertex colour.
  Eigen::Vector4f BaseColor(const RayHit& hit) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sd
