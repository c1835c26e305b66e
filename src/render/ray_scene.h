#pragma once
// Ray casting against triangle meshes. Embree is an implementation detail (pimpl): no rtc* type leaves
// this module. A scene holds meshes already placed in one common frame (the caller transforms them).
#include <array>
#include <cstdint>
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

  // Adds a mesh (positions in the scene frame, finite and within 1e8 of the origin: SD_CHECK). The scene keeps a shared reference for shading lookups
  // (do not modify the mesh afterwards); Embree gets its own copy of positions and indices. Ids are
  // 0, 1, 2, ... in call order; a mesh without faces keeps its id and is never hit.
  int AddMesh(std::shared_ptr<const TriangleMesh> mesh);
  // Before Commit: many rays will skip `mesh` (skip_mesh below), as most rays of synthesis skip the ground
  // receiver the objects stand on. Commit then also builds a BVH without it, and those rays traverse that one
  // instead of having the mesh's hits filtered out: the same answers without its triangles, which lie under or
  // round every object, in their way. One mesh per scene; -1 none.
  void SetOftenSkipped(int mesh);
  // Before Commit: OccludedFan and OccludedPacket will trace rays whose answers are counted, not looked at one by
  // one (a surface's sky and sun rays, millions a frame). Commit then also builds a BVH for them without Embree's
  // robust mode (without the often-skipped mesh, if one is set: the rays that skip it traverse it; the others
  // keep the robust BVHs); a ray that meets a shared edge or vertex within rounding may pass through there, one
  // ray of an estimate of many, and the keyframe's sky and sun rays trace 5-16 % faster (bench/RESULTS.md).
  // Intersect, IntersectFan and Occluded stay watertight: a pixel's primary ray or a LiDAR beam through a crack
  // would be seen.
  void SetFastOcclusion(bool on = true);
  // Must be called after the last AddMesh and before any query. Builds a high-quality BVH with Embree's
  // robust (watertight) traversal: rays through shared edges and vertices of a closed mesh do not leak (and the
  // BVHs SetOftenSkipped and SetFastOcclusion ask for).
  void Commit();
  int NumMeshes() const;
  const TriangleMesh& Mesh(int id) const;

  // Nearest hit with t in [t_near, t_far]; `dir` must be unit length (a ray with a non-finite or zero origin or
  // direction, or t_near < 0 or > t_far, is a miss: it never reaches Embree); `skip_mesh` >= 0 ignores that mesh (as
  // for Occluded). Thread-safe after Commit().
  RayHit Intersect(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near = 0.0f,
                   float t_far = std::numeric_limits<float>::infinity(), int skip_mesh = -1) const;
  // Any hit in [t_near, t_far] (shadow rays). `skip_mesh` >= 0 ignores that mesh (e.g. the ground receiver);
  // exact for any number of meshes (a filter on the geometry id, not 32-bit ray masks).
  bool Occluded(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near, float t_far,
                int skip_mesh = -1) const;
  // Occluded for up to kMaxFanRays rays leaving one point (a surface point's sky or sun rays), traced as one
  // packet: the same answers as `count` calls of Occluded (but within rounding of an edge, with SetFastOcclusion),
  // at a fraction of the cost on SIMD hardware. Bit i of the result is set when ray i is occluded; a ray outside
  // Occluded's contract is not (as there).
  static constexpr int kMaxFanRays = 16;
  uint32_t OccludedFan(const Eigen::Vector3f& origin, const Eigen::Vector3f* dirs, int count, float t_near, float t_far,
                       int skip_mesh = -1) const;
  // Intersect for up to kMaxFanRays rays leaving one point (a pixel's sub-samples), traced as one packet: hits[i]
  // answers as Intersect(origin, dirs[i], t_near, t_far, skip_mesh) does.
  void IntersectFan(const Eigen::Vector3f& origin, const Eigen::Vector3f* dirs, int count, float t_near, float t_far,
                    int skip_mesh, RayHit* hits) const;
  // The same for up to kMaxFanRays rays that each leave their own point (the sun and sky rays of a pixel's
  // sub-samples, traced together).
  uint32_t OccludedPacket(const Eigen::Vector3f* origins, const Eigen::Vector3f* dirs, int count, float t_near,
                          float t_far, int skip_mesh = -1) const;
  // Batch form of Intersect for many rays (LiDAR); parallel. origins/dirs same size.
  std::vector<RayHit> IntersectMany(const std::vector<Eigen::Vector3f>& origins,
                                    const std::vector<Eigen::Vector3f>& dirs, float t_near = 0.0f) const;

  // Hit point, interpolated attributes; `hit` must be a hit. Normals are unit length and NOT flipped
  // towards the ray: callers that shade both sides flip them (see camera_render.h).
  Eigen::Vector3f HitPoint(const RayHit& hit) const;  // barycentric interpolation of the face's vertices
  Eigen::Vector3f ShadingNormal(const RayHit& hit) const;  // interpolated vertex normal, or face normal
  Eigen::Vector3f GeometricNormal(const RayHit& hit) const;  // face normal (CCW side); zero if degenerate
  // Base colour (linear RGBA) at the hit: material factor x texture x vertex colour. The texture is read
  // bilinearly at the interpolated UV with repeat (wrap-around) addressing, texels converted sRGB->linear
  // before filtering (alpha stays linear). No material: white; no UVs or no texture: factor only; no
  // vertex colours: 1.
  Eigen::Vector4f BaseColor(const RayHit& hit) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Rays leaving one point (its sky or sun rays), gathered and traced in packets with OccludedFan as each packet
// fills: Add a ray with a weight; OpenWeight traces what is left and returns the summed weights of the rays nothing
// (but `skip_mesh`) occludes, added in the order the rays were.
class OcclusionFan {
 public:
  OcclusionFan(const RayScene& scene, const Eigen::Vector3f& origin, int skip_mesh = -1)
      : scene_(scene), origin_(origin), skip_mesh_(skip_mesh) {}
  void Add(const Eigen::Vector3f& dir, double weight = 1.0);
  double OpenWeight();

 private:
  void Trace();
  const RayScene& scene_;
  Eigen::Vector3f origin_;
  int skip_mesh_;
  std::array<Eigen::Vector3f, RayScene::kMaxFanRays> dirs_;
  std::array<double, RayScene::kMaxFanRays> weights_;
  int count_ = 0;
  double open_ = 0;
};

}  // namespace sd
