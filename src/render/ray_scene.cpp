#include "render/ray_scene.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <embree3/rtcore.h>

#include "core/error.h"
#include "core/image.h"
#include "core/parallel.h"

namespace sd {
namespace {

void EmbreeError(void* /*user*/, RTCError code, const char* str) {
  SD_CHECK(false, << "Embree error " << static_cast<int>(code) << ": " << (str ? str : ""));
}

// One Embree device for the whole process: creating a device spins up Embree's thread pool, which is too
// costly per scene (synth builds one scene per frame). Devices are thread-safe; it is never released.
RTCDevice SharedDevice() {
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice(nullptr);
    SD_CHECK(d != nullptr, << "rtcNewDevice failed (error " << static_cast<int>(rtcGetDeviceError(nullptr)) << ")");
    rtcSetDeviceErrorFunction(d, EmbreeError, nullptr);
    return d;
  }();
  return device;
}

// Occluded(skip_mesh): the context carries the geometry id to ignore and a context filter function rejects
// its candidate hits. Unlike geometry masks (32 bits, so ids collide modulo 32) this is exact for any number
// of meshes. The filter only runs when a context sets it (skip_mesh >= 0), so plain queries pay nothing.
struct SkipContext {
  RTCIntersectContext context;  // must be first: Embree hands back a pointer to it
  unsigned skip_geom;
};

void SkipFilter(const RTCFilterFunctionNArguments* args) {
  const auto* ctx = reinterpret_cast<const SkipContext*>(args->context);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] != -1) continue;
    if (RTCHitN_geomID(args->hit, args->N, i) == ctx->skip_geom) args->valid[i] = 0;
  }
}

// In place: Embree keeps the context's address for the query.
void InitSkipContext(SkipContext* ctx, int skip_mesh) {
  rtcInitIntersectContext(&ctx->context);
  ctx->skip_geom = RTC_INVALID_GEOMETRY_ID;
  if (skip_mesh >= 0) {
    ctx->context.filter = SkipFilter;
    ctx->skip_geom = static_cast<unsigned>(skip_mesh);
  }
}

// Embree's contract (rtcIntersect1): a finite origin and direction, 0 <= tnear <= tfar. Outside it the traversal
// is undefined (an fx = 0 camera once reached it with infinite directions and aborted in bvh_intersector1.cpp).
// Such a ray is answered as a miss here instead: the readers refuse the inputs that made them, so what remains
// is a degenerate ray of the geometry (a normalised zero vector), which hits nothing.
bool RayWithinEmbreeContract(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near, float t_far) {
  return origin.allFinite() && dir.allFinite() && dir.squaredNorm() > 0 && std::isfinite(t_near) && t_near >= 0 &&
         !(t_far < t_near) && !std::isnan(t_far);
}

// Larger than any world coordinate the readers accept (1e7 m) and small enough for float traversal.
constexpr float kMaxSceneCoordinate = 1e8f;

RTCRayHit MakeRayHit(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near, float t_far) {
  RTCRayHit rh;
  rh.ray.org_x = origin.x();
  rh.ray.org_y = origin.y();
  rh.ray.org_z = origin.z();
  rh.ray.dir_x = dir.x();
  rh.ray.dir_y = dir.y();
  rh.ray.dir_z = dir.z();
  rh.ray.tnear = t_near;
  rh.ray.tfar = t_far;
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  return rh;
}

// Linear value of each 8-bit sRGB code.
const std::array<float, 256>& SrgbLut() {
  static const std::array<float, 256> lut = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = SrgbToLinear(static_cast<float>(i) / 255.0f);
    return t;
  }();
  return lut;
}

// Linear RGBA of one texel; 1-channel textures are grey, 2-channel grey + alpha.
Eigen::Vector4f Texel(const ImageU8& img, int x, int y) {
  const auto& lut = SrgbLut();
  const uint8_t* p = img.pixel(x, y);
  switch (img.channels()) {
    case 1: return {lut[p[0]], lut[p[0]], lut[p[0]], 1.0f};
    case 2: return {lut[p[0]], lut[p[0]], lut[p[0]], p[1] / 255.0f};
    case 3: return {lut[p[0]], lut[p[1]], lut[p[2]], 1.0f};
    default: return {lut[p[0]], lut[p[1]], lut[p[2]], p[3] / 255.0f};
  }
}

int Wrap(int i, int n) {
  const int r = i % n;
  return r < 0 ? r + n : r;
}

// Bilinear lookup with repeat addressing (glTF's default sampler); texels are linearised before filtering
// so that filtering happens in linear light.
Eigen::Vector4f SampleRepeat(const ImageU8& img, const Eigen::Vector2f& uv) {
  const int w = img.width(), h = img.height();
  const double x = static_cast<double>(uv.x()) * w - 0.5;
  const double y = static_cast<double>(uv.y()) * h - 0.5;
  if (!std::isfinite(x) || !std::isfinite(y)) return Texel(img, 0, 0);
  const double fx0 = std::floor(x), fy0 = std::floor(y);
  const float fx = static_cast<float>(x - fx0), fy = static_cast<float>(y - fy0);
  // Reduce before converting to int so huge UVs cannot overflow.
  const int x0 = Wrap(static_cast<int>(std::fmod(fx0, static_cast<double>(w))), w);
  const int y0 = Wrap(static_cast<int>(std::fmod(fy0, static_cast<double>(h))), h);
  const int x1 = (x0 + 1) % w, y1 = (y0 + 1) % h;
  const Eigen::Vector4f a = Texel(img, x0, y0) * (1 - fx) + Texel(img, x1, y0) * fx;
  const Eigen::Vector4f b = Texel(img, x0, y1) * (1 - fx) + Texel(img, x1, y1) * fx;
  return a * (1 - fy) + b * fy;
}

// A scene with the flags and build quality every query here relies on.
// ROBUST: watertight traversal (no leaks through shared edges/vertices); without it, the scenes of
// SetFastOcclusion. CONTEXT_FILTER_FUNCTION: lets the queries pass the skip filter through the context.
RTCScene NewScene(bool robust = true) {
  RTCScene scene = rtcNewScene(SharedDevice());
  rtcSetSceneFlags(scene, static_cast<RTCSceneFlags>((robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE) |
                                                     RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION));
  // Without the robust mode, a high-quality build adds spatial splits: four times the robust build's time on a
  // keyframe's 20 objects (40 against 9 ms), for traversal within the noise of the medium build's
  // (bench_road_shade, bench_sky_filter).
  rtcSetSceneBuildQuality(scene, robust ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM);
  return scene;
}

}  // namespace

struct RayScene::Impl {
  RTCScene scene = nullptr;
  // SetOftenSkipped: the scene without that mesh (null until Commit, or when none was set).
  RTCScene without = nullptr;
  int often_skipped = -1;
  // SetFastOcclusion: for OccludedFan and OccludedPacket, a scene without the robust mode (null until Commit, or
  // when it was not asked for): the one without the often skipped mesh where there is one (the rays that ask for
  // it), else the whole scene.
  bool fast_occlusion = false;
  RTCScene fast = nullptr;
  std::vector<std::shared_ptr<const TriangleMesh>> meshes;
  std::vector<RTCGeometry> geometries;  // by mesh id, held until Commit (null: an empty mesh)
  bool committed = false;

  Impl() : scene(NewScene()) {}
  ~Impl() {
    ReleaseGeometries();
    for (RTCScene s : {fast, without, scene})
      if (s) rtcReleaseScene(s);
  }
  void ReleaseGeometries() {
    for (RTCGeometry g : geometries)
      if (g) rtcReleaseGeometry(g);
    geometries.clear();
  }

  // The scene a query skipping `*skip_mesh` traverses; where that is the scene without the mesh, nothing is left
  // to skip (-1).
  RTCScene SceneFor(int* skip_mesh) const {
    if (without && *skip_mesh == often_skipped) {
      *skip_mesh = -1;
      return without;
    }
    return scene;
  }
  // The same for the occlusion rays of OccludedFan and OccludedPacket.
  RTCScene OcclusionSceneFor(int* skip_mesh) const {
    if (!fast) return SceneFor(skip_mesh);
    if (often_skipped < 0) return fast;
    if (*skip_mesh != often_skipped) return SceneFor(skip_mesh);
    *skip_mesh = -1;
    return fast;
  }

  const TriangleMesh& MeshOf(const RayHit& hit) const {
    SD_CHECK(hit.mesh >= 0 && hit.mesh < static_cast<int>(meshes.size()), << "mesh " << hit.mesh);
    const TriangleMesh& m = *meshes[hit.mesh];
    SD_CHECK(hit.face >= 0 && hit.face < static_cast<int>(m.NumFaces()), << "face " << hit.face);
    return m;
  }
};

RayScene::RayScene() : impl_(std::make_unique<Impl>()) {}
RayScene::~RayScene() = default;
RayScene::RayScene(RayScene&&) noexcept = default;
RayScene& RayScene::operator=(RayScene&&) noexcept = default;

int RayScene::AddMesh(std::shared_ptr<const TriangleMesh> mesh) {
  SD_CHECK(mesh != nullptr, << "null mesh");
  SD_CHECK(!impl_->committed, << "AddMesh after Commit");
  const int id = static_cast<int>(impl_->meshes.size());
  const TriangleMesh& m = *mesh;
  if (m.NumFaces() > 0 && m.NumVertices() > 0) {
    // Copied into Embree-owned buffers: Embree reads vertex buffers with 16-byte loads past the last
    // element, which a std::vector<Vector3f> does not guarantee to allow.
    RTCGeometry geom = rtcNewGeometry(SharedDevice(), RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                           3 * sizeof(float), m.NumVertices()));
    for (size_t i = 0; i < m.NumVertices(); ++i) {
      // Meshes are checked finite where they are read and placed by bounded poses: a vertex outside this is a
      // bug upstream, and Embree's BVH build is undefined on it.
      SD_CHECK(m.positions[i].allFinite() && m.positions[i].cwiseAbs().maxCoeff() < kMaxSceneCoordinate,
               << "vertex " << i << " at " << m.positions[i].transpose() << " cannot be ray traced");
      vb[3 * i + 0] = m.positions[i].x();
      vb[3 * i + 1] = m.positions[i].y();
      vb[3 * i + 2] = m.positions[i].z();
    }
    auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                              3 * sizeof(unsigned), m.NumFaces()));
    const int nv = static_cast<int>(m.NumVertices());
    for (size_t f = 0; f < m.NumFaces(); ++f) {
      for (int k = 0; k < 3; ++k) {
        const int vi = m.faces[f][k];
        SD_CHECK(vi >= 0 && vi < nv, << "face " << f << " index " << vi << " out of range " << nv);
        ib[3 * f + k] = static_cast<unsigned>(vi);
      }
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(impl_->scene, geom, static_cast<unsigned>(id));
    impl_->geometries.push_back(geom);  // our reference, released at Commit
  } else {
    impl_->geometries.push_back(nullptr);  // empty meshes keep their id but have no geometry: rays never hit them
  }
  impl_->meshes.push_back(std::move(mesh));
  return id;
}

void RayScene::SetOftenSkipped(int mesh) {
  SD_CHECK(!impl_->committed, << "SetOftenSkipped after Commit");
  SD_CHECK(mesh >= -1 && mesh < NumMeshes(), << "mesh " << mesh << " of " << NumMeshes());
  impl_->often_skipped = mesh;
}

void RayScene::SetFastOcclusion(bool on) {
  SD_CHECK(!impl_->committed, << "SetFastOcclusion after Commit");
  impl_->fast_occlusion = on;
}

void RayScene::Commit() {
  // Embree lets one geometry be attached to several scenes, under the same id.
  const auto scene_of = [&](bool robust, int leave_out) {
    RTCScene s = NewScene(robust);
    for (size_t id = 0; id < impl_->geometries.size(); ++id)
      if (impl_->geometries[id] && static_cast<int>(id) != leave_out)
        rtcAttachGeometryByID(s, impl_->geometries[id], static_cast<unsigned>(id));
    rtcCommitScene(s);
    return s;
  };
  rtcCommitScene(impl_->scene);
  if (impl_->often_skipped >= 0) impl_->without = scene_of(true, impl_->often_skipped);
  if (impl_->fast_occlusion) impl_->fast = scene_of(false, impl_->often_skipped);
  impl_->ReleaseGeometries();
  impl_->committed = true;
}

int RayScene::NumMeshes() const { return static_cast<int>(impl_->meshes.size()); }

const TriangleMesh& RayScene::Mesh(int id) const {
  SD_CHECK(id >= 0 && id < NumMeshes(), << "mesh " << id);
  return *impl_->meshes[id];
}

RayHit RayScene::Intersect(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near, float t_far,
                           int skip_mesh) const {
  SD_CHECK(impl_->committed, << "query before Commit");
  if (!RayWithinEmbreeContract(origin, dir, t_near, t_far)) return RayHit{};
  RTCScene scene = impl_->SceneFor(&skip_mesh);
  SkipContext ctx;
  InitSkipContext(&ctx, skip_mesh);
  RTCRayHit rh = MakeRayHit(origin, dir, t_near, t_far);
  rtcIntersect1(scene, &ctx.context, &rh);
  RayHit hit;
  if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
    hit.t = rh.ray.tfar;
    hit.mesh = static_cast<int>(rh.hit.geomID);
    hit.face = static_cast<int>(rh.hit.primID);
    hit.u = rh.hit.u;
    hit.v = rh.hit.v;
  }
  return hit;
}

bool RayScene::Occluded(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near, float t_far,
                        int skip_mesh) const {
  SD_CHECK(impl_->committed, << "query before Commit");
  if (!RayWithinEmbreeContract(origin, dir, t_near, t_far)) return false;
  RTCScene scene = impl_->SceneFor(&skip_mesh);
  SkipContext ctx;
  InitSkipContext(&ctx, skip_mesh);
  RTCRay ray = MakeRayHit(origin, dir, t_near, t_far).ray;
  rtcOccluded1(scene, &ctx.context, &ray);
  // Embree sets tfar to -inf when the ray is occluded.
  return ray.tfar < 0.0f;
}

namespace {
// Lane i of an Embree ray packet (RTCRay4/8/16): the ray from `origin` along `dir`, or, both null, an unused lane
// (past the rays given, or outside the contract), which still gets finite values: Embree may read it.
template <typename RayPacket>
void SetLane(RayPacket* rays, int i, const Eigen::Vector3f* origin, const Eigen::Vector3f* dir, float t_near,
             float t_far) {
  const bool ok = origin && dir;
  rays->org_x[i] = ok ? origin->x() : 0.0f;
  rays->org_y[i] = ok ? origin->y() : 0.0f;
  rays->org_z[i] = ok ? origin->z() : 0.0f;
  rays->dir_x[i] = ok ? dir->x() : 0.0f;
  rays->dir_y[i] = ok ? dir->y() : 0.0f;
  rays->dir_z[i] = ok ? dir->z() : 1.0f;
  rays->tnear[i] = ok ? t_near : 0.0f;
  rays->tfar[i] = ok ? t_far : 0.0f;
  rays->time[i] = 0.0f;
  rays->mask[i] = 0xFFFFFFFFu;
  rays->id[i] = static_cast<unsigned>(i);
  rays->flags[i] = 0;
}

// One Embree packet of W (4, 8 or 16) occlusion rays; origin_of(i) gives ray i's origin.
template <int W, typename RTCRayW, typename OccludedW, typename OriginOf>
uint32_t OccludedPacketOf(RTCScene scene, const OccludedW& occluded_w, const OriginOf& origin_of, const Eigen::Vector3f* dirs,
                          int count, float t_near, float t_far, int skip_mesh) {
  SkipContext ctx;
  InitSkipContext(&ctx, skip_mesh);
  alignas(64) int valid[W];
  RTCRayW rays;
  bool any = false;
  for (int i = 0; i < W; ++i) {
    const bool ok = i < count && RayWithinEmbreeContract(origin_of(i), dirs[i], t_near, t_far);
    valid[i] = ok ? -1 : 0;
    any = any || ok;
    SetLane(&rays, i, ok ? &origin_of(i) : nullptr, ok ? &dirs[i] : nullptr, t_near, t_far);
  }
  if (!any) return 0;
  occluded_w(valid, scene, &ctx.context, &rays);
  uint32_t occluded = 0;
  for (int i = 0; i < count; ++i)
    if (valid[i] && rays.tfar[i] < 0.0f) occluded |= 1u << i;  // Embree sets tfar to -inf when occluded
  return occluded;
}

// Up to 16 occlusion rays in the narrowest packet that holds them: a wide packet's empty lanes still cost their
// share of every traversal step (the render's 4 sun rays and 16 sky rays per pixel leave a tail of 4).
template <typename OriginOf>
uint32_t TracePacket(RTCScene scene, const OriginOf& origin_of, const Eigen::Vector3f* dirs, int count, float t_near,
                     float t_far, int skip_mesh) {
  SD_CHECK(count >= 0 && count <= RayScene::kMaxFanRays,
           << count << " rays in one packet (at most " << RayScene::kMaxFanRays << ")");
  if (count <= 4) return OccludedPacketOf<4, RTCRay4>(scene, rtcOccluded4, origin_of, dirs, count, t_near, t_far, skip_mesh);
  if (count <= 8) return OccludedPacketOf<8, RTCRay8>(scene, rtcOccluded8, origin_of, dirs, count, t_near, t_far, skip_mesh);
  return OccludedPacketOf<16, RTCRay16>(scene, rtcOccluded16, origin_of, dirs, count, t_near, t_far, skip_mesh);
}
}  // namespace

uint32_t RayScene::OccludedFan(const Eigen::Vector3f& origin, const Eigen::Vector3f* dirs, int count, float t_near,
                               float t_far, int skip_mesh) const {
  SD_CHECK(impl_->committed, << "query before Commit");
  RTCScene scene = impl_->OcclusionSceneFor(&skip_mesh);
  return TracePacket(scene, [&](int) -> const Eigen::Vector3f& { return origin; }, dirs, count, t_near, t_far, skip_mesh);
}

namespace {
// One Embree packet of W (4, 8 or 16) primary rays leaving `origin`.
template <int W, typename RTCRayHitW, typename IntersectW>
void IntersectPacketOf(RTCScene scene, const IntersectW& intersect, const Eigen::Vector3f& origin,
                       const Eigen::Vector3f* dirs, int count, float t_near, float t_far, int skip_mesh, RayHit* hits) {
  SkipContext ctx;
  InitSkipContext(&ctx, skip_mesh);
  alignas(64) int valid[W];
  RTCRayHitW rh;
  bool any = false;
  for (int i = 0; i < W; ++i) {
    const bool ok = i < count && RayWithinEmbreeContract(origin, dirs[i], t_near, t_far);
    valid[i] = ok ? -1 : 0;
    any = any || ok;
    SetLane(&rh.ray, i, ok ? &origin : nullptr, ok ? &dirs[i] : nullptr, t_near, t_far);
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  for (int i = 0; i < count; ++i) hits[i] = RayHit{};
  if (!any) return;
  intersect(valid, scene, &ctx.context, &rh);
  for (int i = 0; i < count; ++i) {
    if (!valid[i] || rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) continue;
    hits[i].t = rh.ray.tfar[i];
    hits[i].mesh = static_cast<int>(rh.hit.geomID[i]);
    hits[i].face = static_cast<int>(rh.hit.primID[i]);
    hits[i].u = rh.hit.u[i];
    hits[i].v = rh.hit.v[i];
  }
}
}  // namespace

void RayScene::IntersectFan(const Eigen::Vector3f& origin, const Eigen::Vector3f* dirs, int count, float t_near,
                            float t_far, int skip_mesh, RayHit* hits) const {
  SD_CHECK(impl_->committed, << "query before Commit");
  SD_CHECK(count >= 0 && count <= kMaxFanRays, << count << " rays in one packet (at most " << kMaxFanRays << ")");
  RTCScene scene = impl_->SceneFor(&skip_mesh);
  // The narrowest packet that holds them: a wide packet's empty lanes still cost their share of every traversal step.
  if (count <= 4)
    IntersectPacketOf<4, RTCRayHit4>(scene, rtcIntersect4, origin, dirs, count, t_near, t_far, skip_mesh, hits);
  else if (count <= 8)
    IntersectPacketOf<8, RTCRayHit8>(scene, rtcIntersect8, origin, dirs, count, t_near, t_far, skip_mesh, hits);
  else
    IntersectPacketOf<16, RTCRayHit16>(scene, rtcIntersect16, origin, dirs, count, t_near, t_far, skip_mesh, hits);
}

uint32_t RayScene::OccludedPacket(const Eigen::Vector3f* origins, const Eigen::Vector3f* dirs, int count, float t_near,
                                  float t_far, int skip_mesh) const {
  SD_CHECK(impl_->committed, << "query before Commit");
  RTCScene scene = impl_->OcclusionSceneFor(&skip_mesh);
  return TracePacket(scene, [&](int i) -> const Eigen::Vector3f& { return origins[i]; }, dirs, count, t_near, t_far,
                     skip_mesh);
}

void OcclusionFan::Add(const Eigen::Vector3f& dir, double weight) {
  dirs_[static_cast<size_t>(count_)] = dir;
  weights_[static_cast<size_t>(count_++)] = weight;
  if (count_ == RayScene::kMaxFanRays) Trace();
}

double OcclusionFan::OpenWeight() {
  if (count_ > 0) Trace();
  return open_;
}

void OcclusionFan::Trace() {
  const uint32_t occluded =
      scene_.OccludedFan(origin_, dirs_.data(), count_, 0.0f, std::numeric_limits<float>::infinity(), skip_mesh_);
  for (int i = 0; i < count_; ++i)
    if (!(occluded >> i & 1u)) open_ += weights_[static_cast<size_t>(i)];
  count_ = 0;
}

std::vector<RayHit> RayScene::IntersectMany(const std::vector<Eigen::Vector3f>& origins,
                                            const std::vector<Eigen::Vector3f>& dirs, float t_near) const {
  SD_CHECK(origins.size() == dirs.size(), << origins.size() << " origins vs " << dirs.size() << " dirs");
  std::vector<RayHit> hits(origins.size());
  ParallelForRange(0, origins.size(), 1024, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) hits[i] = Intersect(origins[i], dirs[i], t_near);
  });
  return hits;
}

Eigen::Vector3f RayScene::HitPoint(const RayHit& hit) const {
  const TriangleMesh& m = impl_->MeshOf(hit);
  const Eigen::Vector3i& f = m.faces[hit.face];
  return (1 - hit.u - hit.v) * m.positions[f[0]] + hit.u * m.positions[f[1]] + hit.v * m.positions[f[2]];
}

Eigen::Vector3f RayScene::GeometricNormal(const RayHit& hit) const {
  const TriangleMesh& m = impl_->MeshOf(hit);
  return m.FaceNormal(static_cast<size_t>(hit.face));
}

Eigen::Vector3f RayScene::ShadingNormal(const RayHit& hit) const {
  const TriangleMesh& m = impl_->MeshOf(hit);
  if (m.normals.size() == m.NumVertices()) {
    const Eigen::Vector3i& f = m.faces[hit.face];
    const Eigen::Vector3f n = (1 - hit.u - hit.v) * m.normals[f[0]] + hit.u * m.normals[f[1]] + hit.v * m.normals[f[2]];
    const float len = n.norm();
    if (len > 1e-12f) return n / len;
  }
  return m.FaceNormal(static_cast<size_t>(hit.face));
}

Eigen::Vector4f RayScene::BaseColor(const RayHit& hit) const {
  const TriangleMesh& m = impl_->MeshOf(hit);
  const Eigen::Vector3i& f = m.faces[hit.face];
  const float w0 = 1 - hit.u - hit.v, w1 = hit.u, w2 = hit.v;
  Eigen::Vector4f color = Eigen::Vector4f::Ones();
  const int mat = m.MaterialOf(static_cast<size_t>(hit.face));
  if (mat >= 0 && mat < static_cast<int>(m.materials.size())) {
    const Material& material = m.materials[mat];
    color = material.base_color_factor;
    const ImageU8* tex = material.base_color_texture.get();
    if (tex && !tex->empty() && m.uvs.size() == m.NumVertices()) {
      const Eigen::Vector2f uv = w0 * m.uvs[f[0]] + w1 * m.uvs[f[1]] + w2 * m.uvs[f[2]];
      color = color.cwiseProduct(SampleRepeat(*tex, uv));
    }
  }
  if (m.colors.size() == m.NumVertices()) {
    color = color.cwiseProduct(w0 * m.colors[f[0]] + w1 * m.colors[f[1]] + w2 * m.colors[f[2]]);
  }
  return color;
}

}  // namespace sd
