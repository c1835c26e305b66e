#include "render/ray_scene.h"

#include <cmath>

#include <gtest/gtest.h>

#include <limits>
#include <vector>

#include "core/image.h"
#include "render/test_meshes.h"

namespace sd {
namespace {

using testmesh::Box;
using testmesh::Quad;

// A big quad in the plane z = 3 facing -z (towards the origin).
RayScene PlaneScene() {
  RayScene scene;
  scene.AddMesh(Quad({0, 0, 3}, {0, 1, 0}, {1, 0, 0}, 10, 10));  // y x x = -z
  scene.Commit();
  return scene;
}

TEST(RayScene, PlaneHitDistanceIsExact) {
  const RayScene scene = PlaneScene();
  for (float angle : {0.0f, 0.3f, 0.7f, 1.1f}) {
    const Eigen::Vector3f dir(std::sin(angle), 0.0f, std::cos(angle));
    const RayHit hit = scene.Intersect(Eigen::Vector3f::Zero(), dir);
    ASSERT_TRUE(hit.Hit()) << angle;
    EXPECT_EQ(hit.mesh, 0);
    EXPECT_NEAR(hit.t, 3.0f / std::cos(angle), 1e-5f) << angle;
    // Barycentrics reconstruct the hit point.
    const Eigen::Vector3f p = scene.HitPoint(hit);
    EXPECT_NEAR((p - hit.t * dir).norm(), 0.0f, 1e-5f) << angle;
    EXPECT_NEAR(scene.GeometricNormal(hit).z(), -1.0f, 1e-6f);
    EXPECT_NEAR(scene.ShadingNormal(hit).z(), -1.0f, 1e-6f);  // no vertex normals: face normal
  }
  // t range is honoured; a ray pointing away misses.
  EXPECT_FALSE(scene.Intersect(Eigen::Vector3f::Zero(), {0, 0, 1}, 0.0f, 2.9f).Hit());
  EXPECT_FALSE(scene.Intersect(Eigen::Vector3f::Zero(), {0, 0, -1}).Hit());
  EXPECT_TRUE(scene.Occluded(Eigen::Vector3f::Zero(), {0, 0, 1}, 0.0f, 3.1f));
  EXPECT_FALSE(scene.Occluded(Eigen::Vector3f::Zero(), {0, 0, 1}, 0.0f, 2.9f));
}

TEST(RayScene, UnitCubeFacesAndNormals) {
  RayScene scene;
  scene.AddMesh(Box({-0.5f, -0.5f, -0.5f}, {0.5f, 0.5f, 0.5f}));
  scene.Commit();
  for (int axis = 0; axis < 3; ++axis) {
    for (float sign : {-1.0f, 1.0f}) {
      Eigen::Vector3f origin = Eigen::Vector3f::Zero();
      origin[axis] = 4.0f * sign;
      const Eigen::Vector3f dir = -origin.normalized();
      Eigen::Vector3f off(0.1f, 0.2f, 0.05f);
      off[axis] = 0;  // off-centre but still 4 m from the face's plane
      const RayHit hit = scene.Intersect(origin + off, dir);
      ASSERT_TRUE(hit.Hit());
      EXPECT_NEAR(hit.t, 3.5f, 1e-5f);
      // Faces are outward (CCW from outside).
      EXPECT_NEAR(scene.GeometricNormal(hit).dot(-dir), 1.0f, 1e-6f);
    }
  }
}

// Embree's verify suite habit: rays aimed exactly at shared edges and vertices of a closed mesh never leak.
TEST(RayScene, NoLeaksThroughSharedEdgesOfClosedCube) {
  RayScene scene;
  scene.AddMesh(Box({-1, -1, -1}, {1, 1, 1}));
  scene.Commit();
  // From the centre towards a dense grid on each face, including its border (cube edges), its corners and
  // its diagonal (the edge shared by the face's two triangles).
  int rays = 0, misses = 0;
  const int n = 40;
  for (int axis = 0; axis < 3; ++axis) {
    for (float sign : {-1.0f, 1.0f}) {
      for (int i = 0; i <= n; ++i) {
        for (int j = 0; j <= n; ++j) {
          Eigen::Vector3f target;
          target[axis] = sign;
          target[(axis + 1) % 3] = -1.0f + 2.0f * i / n;
          target[(axis + 2) % 3] = -1.0f + 2.0f * j / n;
          ++rays;
          if (!scene.Intersect(Eigen::Vector3f::Zero(), target.normalized()).Hit()) ++misses;
          if (!scene.Occluded(Eigen::Vector3f::Zero(), target.normalized(), 0.0f, 10.0f)) ++misses;
        }
      }
    }
  }
  EXPECT_EQ(misses, 0) << "of " << rays << " rays";
  // From outside along the face diagonals (the shared interior edges) of the top face.
  int outside_misses = 0;
  for (int i = 1; i < n; ++i) {
    const float s = -1.0f + 2.0f * i / n;
    for (const Eigen::Vector3f& xy : {Eigen::Vector3f(s, s, 5), Eigen::Vector3f(s, -s, 5)}) {
      const RayHit hit = scene.Intersect(xy, {0, 0, -1});
      if (!hit.Hit() || std::abs(hit.t - 4.0f) > 1e-5f) ++outside_misses;
    }
  }
  EXPECT_EQ(outside_misses, 0);
}

TEST(RayScene, OccludedSkipMesh) {
  RayScene scene;
  const int near_id = scene.AddMesh(Quad({0, 0, 1}, {1, 0, 0}, {0, 1, 0}, 1, 1));
  const int far_id = scene.AddMesh(Quad({0, 0, 2}, {1, 0, 0}, {0, 1, 0}, 1, 1));
  scene.AddMesh(std::make_shared<TriangleMesh>());  // empty meshes keep their id and are never hit
  scene.Commit();
  EXPECT_EQ(scene.NumMeshes(), 3);
  const Eigen::Vector3f o = Eigen::Vector3f::Zero(), d(0, 0, 1);
  EXPECT_TRUE(scene.Occluded(o, d, 0, 10));
  EXPECT_TRUE(scene.Occluded(o, d, 0, 10, near_id));    // the far quad still blocks
  EXPECT_FALSE(scene.Occluded(o, d, 0, 1.5f, near_id));  // only the skipped one is within range
  EXPECT_TRUE(scene.Occluded(o, d, 0, 1.5f, far_id));
  EXPECT_EQ(scene.Intersect(o, d).mesh, near_id);
  EXPECT_EQ(scene.Intersect(o, d, 1.5f).mesh, far_id);
}

// A fan traced as one packet answers exactly as its rays traced one by one: random fans round points inside,
// on and outside boxes, with and without a skipped mesh, of every size up to the packet's, with rays outside the
// contract mixed in (answered "not occluded", as Occluded answers them).
TEST(RayScene, OccludedFanAnswersAsOccludedDoes) {
  RayScene scene;
  const int ground = scene.AddMesh(Quad({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 20, 20));
  scene.AddMesh(Box({-1, -1, 0}, {1, 1, 2}));
  scene.AddMesh(Box({2, -0.5f, 0}, {3, 0.5f, 3}));
  scene.Commit();
  uint32_t state = 12345;
  const auto uniform = [&] {  // [-1, 1)
    state = state * 1664525u + 1013904223u;
    return static_cast<float>(state >> 8) / 8388608.0f - 1.0f;
  };
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  int occluded = 0, open = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const Eigen::Vector3f origin(3 * uniform(), 3 * uniform(), 1.5f + 1.5f * uniform());
    const int count = trial % (RayScene::kMaxFanRays + 1);
    std::vector<Eigen::Vector3f> dirs(static_cast<size_t>(count));
    for (auto& d : dirs) d = Eigen::Vector3f(uniform(), uniform(), uniform()).normalized();
    if (count > 3) dirs[1] = Eigen::Vector3f(nan, 0, 0), dirs[2] = Eigen::Vector3f::Zero();
    const int skip = trial % 3 == 0 ? ground : -1;
    const float t_far = trial % 4 == 0 ? 1.0f : inf;
    const uint32_t fan = scene.OccludedFan(origin, dirs.data(), count, 0.0f, t_far, skip);
    for (int i = 0; i < count; ++i) {
      const bool one = scene.Occluded(origin, dirs[static_cast<size_t>(i)], 0.0f, t_far, skip);
      ASSERT_EQ((fan >> i & 1u) != 0, one) << "trial " << trial << " ray " << i;
      (one ? occluded : open)++;
    }
    EXPECT_EQ(fan >> count, 0u);
  }
  EXPECT_GT(occluded, 500);  // both answers were exercised
  EXPECT_GT(open, 500);
}

// A fan of primary rays traced as one packet hits what each ray traced alone hits, at the same distance.
TEST(RayScene, IntersectFanAnswersAsIntersectDoes) {
  RayScene scene;
  const int ground = scene.AddMesh(Quad({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 20, 20));
  scene.AddMesh(Box({-1, -1, 0}, {1, 1, 2}));
  scene.AddMesh(Box({2, -0.5f, 0}, {3, 0.5f, 3}));
  scene.Commit();
  uint32_t state = 4242;
  const auto uniform = [&] {  // [-1, 1)
    state = state * 1664525u + 1013904223u;
    return static_cast<float>(state >> 8) / 8388608.0f - 1.0f;
  };
  const float inf = std::numeric_limits<float>::infinity();
  int hits = 0, misses = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Eigen::Vector3f origin(4 * uniform(), 4 * uniform(), 2.0f + 2.0f * uniform());
    const int count = trial % (RayScene::kMaxFanRays + 1);
    std::vector<Eigen::Vector3f> dirs(static_cast<size_t>(count));
    for (auto& d : dirs) d = Eigen::Vector3f(uniform(), uniform(), uniform()).normalized();
    if (count > 2) dirs[1] = Eigen::Vector3f::Zero();  // outside the contract: a miss
    const int skip = trial % 3 == 0 ? ground : -1;
    std::vector<RayHit> fan(static_cast<size_t>(count));
    scene.IntersectFan(origin, dirs.data(), count, 0.0f, inf, skip, fan.data());
    for (int i = 0; i < count; ++i) {
      const RayHit one = scene.Intersect(origin, dirs[static_cast<size_t>(i)], 0.0f, inf, skip);
      const RayHit& f = fan[static_cast<size_t>(i)];
      ASSERT_EQ(f.mesh, one.mesh) << "trial " << trial << " ray " << i;
      ASSERT_EQ(f.face, one.face) << "trial " << trial << " ray " << i;
      if (one.Hit()) {
        EXPECT_NEAR(f.t, one.t, 1e-5f * (1 + one.t));
        ++hits;
      } else {
        ++misses;
      }
    }
  }
  EXPECT_GT(hits, 300);
  EXPECT_GT(misses, 300);
}

// A packet whose rays leave different points answers as its rays traced one by one.
TEST(RayScene, OccludedPacketAnswersAsOccludedDoes) {
  RayScene scene;
  const int ground = scene.AddMesh(Quad({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 20, 20));
  scene.AddMesh(Box({-1, -1, 0}, {1, 1, 2}));
  scene.AddMesh(Box({2, -0.5f, 0}, {3, 0.5f, 3}));
  scene.Commit();
  uint32_t state = 777;
  const auto uniform = [&] {  // [-1, 1)
    state = state * 1664525u + 1013904223u;
    return static_cast<float>(state >> 8) / 8388608.0f - 1.0f;
  };
  const float inf = std::numeric_limits<float>::infinity();
  int occluded = 0, open = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int count = trial % (RayScene::kMaxFanRays + 1);
    std::vector<Eigen::Vector3f> origins(static_cast<size_t>(count)), dirs(static_cast<size_t>(count));
    for (int i = 0; i < count; ++i) {
      origins[static_cast<size_t>(i)] = Eigen::Vector3f(3 * uniform(), 3 * uniform(), 1.5f + 1.5f * uniform());
      dirs[static_cast<size_t>(i)] = Eigen::Vector3f(uniform(), uniform(), uniform()).normalized();
    }
    if (count > 2) dirs[1] = Eigen::Vector3f::Zero();  // outside the contract: not occluded
    const int skip = trial % 3 == 0 ? ground : -1;
    const uint32_t packet = scene.OccludedPacket(origins.data(), dirs.data(), count, 0.0f, inf, skip);
    for (int i = 0; i < count; ++i) {
      const bool one = scene.Occluded(origins[static_cast<size_t>(i)], dirs[static_cast<size_t>(i)], 0.0f, inf, skip);
      ASSERT_EQ((packet >> i & 1u) != 0, one) << "trial " << trial << " ray " << i;
      (one ? occluded : open)++;
    }
    EXPECT_EQ(packet >> count, 0u);
  }
  EXPECT_GT(occluded, 300);
  EXPECT_GT(open, 300);
}

// A scene that keeps a second BVH without its often-skipped mesh answers every query as the scene with one BVH
// does, whatever is skipped: the often-skipped mesh (traced in the second BVH), another mesh or none (the first).
// So does a scene with SetFastOcclusion's BVH for its occlusion fans and packets, with or without an often-skipped
// mesh, for rays that do not graze an edge (random rays here).
TEST(RayScene, OftenSkippedMeshGivesTheSameAnswers) {
  const auto build = [](bool second_bvh, bool fast_occlusion) {
    RayScene scene;
    const int ground = scene.AddMesh(Quad({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 20, 20));
    scene.AddMesh(Box({-1, -1, 0}, {1, 1, 2}));
    scene.AddMesh(std::make_shared<TriangleMesh>());
    scene.AddMesh(Box({2, -0.5f, 0}, {3, 0.5f, 3}));
    if (second_bvh) scene.SetOftenSkipped(ground);
    scene.SetFastOcclusion(fast_occlusion);
    scene.Commit();
    return scene;
  };
  const RayScene one = build(false, false);
  GTEST_FLAG_SET(death_test_style, "threadsafe");  // Embree's worker threads are running
  EXPECT_DEATH(RayScene().SetOftenSkipped(0), "mesh 0 of 0");
  EXPECT_DEATH(build(false, false).SetFastOcclusion(), "SetFastOcclusion after Commit");
  for (const auto& [second_bvh, fast_occlusion] : {std::pair{true, false}, std::pair{true, true}, std::pair{false, true}}) {
    SCOPED_TRACE(testing::Message() << "second BVH " << second_bvh << ", fast occlusion " << fast_occlusion);
    const RayScene two = build(second_bvh, fast_occlusion);
    uint32_t state = 99;
    const auto uniform = [&] {  // [-1, 1)
      state = state * 1664525u + 1013904223u;
      return static_cast<float>(state >> 8) / 8388608.0f - 1.0f;
    };
    const float inf = std::numeric_limits<float>::infinity();
    int hits = 0, occluded = 0, ground_hits = 0;
    for (int trial = 0; trial < 300; ++trial) {
      const int skip = trial % 3 - 1;  // none, the ground, the first box
      const Eigen::Vector3f origin(4 * uniform(), 4 * uniform(), 2.0f + 2.0f * uniform());
      std::vector<Eigen::Vector3f> dirs(RayScene::kMaxFanRays), origins(RayScene::kMaxFanRays);
      for (size_t i = 0; i < dirs.size(); ++i) {
        dirs[i] = Eigen::Vector3f(uniform(), uniform(), uniform()).normalized();
        origins[i] = Eigen::Vector3f(3 * uniform(), 3 * uniform(), 1.5f + 1.5f * uniform());
      }
      std::vector<RayHit> fan_one(dirs.size()), fan_two(dirs.size());
      one.IntersectFan(origin, dirs.data(), static_cast<int>(dirs.size()), 0.0f, inf, skip, fan_one.data());
      two.IntersectFan(origin, dirs.data(), static_cast<int>(dirs.size()), 0.0f, inf, skip, fan_two.data());
      for (size_t i = 0; i < dirs.size(); ++i) {
        const RayHit a = one.Intersect(origin, dirs[i], 0.0f, inf, skip), b = two.Intersect(origin, dirs[i], 0.0f, inf, skip);
        ASSERT_EQ(a.mesh, b.mesh) << "trial " << trial << " ray " << i;
        ASSERT_EQ(a.face, b.face) << "trial " << trial << " ray " << i;
        ASSERT_EQ(fan_two[i].mesh, b.mesh);
        ASSERT_EQ(fan_two[i].face, b.face);
        if (a.Hit()) {
          EXPECT_NEAR(a.t, b.t, 1e-6f * (1 + a.t));
          ++hits;
        }
        ground_hits += a.mesh == 0;
        const bool o = one.Occluded(origin, dirs[i], 0.0f, inf, skip);
        ASSERT_EQ(o, two.Occluded(origin, dirs[i], 0.0f, inf, skip)) << "trial " << trial << " ray " << i;
        occluded += o;
      }
      const int n = RayScene::kMaxFanRays;
      ASSERT_EQ(one.OccludedFan(origin, dirs.data(), n, 0.0f, inf, skip), two.OccludedFan(origin, dirs.data(), n, 0.0f, inf, skip));
      ASSERT_EQ(one.OccludedPacket(origins.data(), dirs.data(), n, 0.0f, inf, skip),
                two.OccludedPacket(origins.data(), dirs.data(), n, 0.0f, inf, skip));
    }
    EXPECT_GT(hits, 1000);
    EXPECT_GT(occluded, 1000);
    EXPECT_GT(ground_hits, 300);  // where the ground is not skipped, it is hit in both
  }
}

// The gatherer sums the weights of the open rays over several packets, as ray-by-ray tracing does.
TEST(RayScene, OcclusionFanSumsTheOpenRaysWeightsAcrossPackets) {
  RayScene scene;
  scene.AddMesh(Box({-1, -1, 0}, {1, 1, 2}));
  scene.Commit();
  const Eigen::Vector3f origin(1.5f, 0, 0.5f);
  OcclusionFan fan(scene, origin);
  double want = 0;
  for (int k = 0; k < 2 * RayScene::kMaxFanRays + 5; ++k) {  // two full packets and a part
    const float a = 0.37f * static_cast<float>(k);
    const Eigen::Vector3f d = Eigen::Vector3f(std::cos(a), std::sin(a), 0.3f).normalized();
    const double weight = 1.0 + 0.1 * k;
    fan.Add(d, weight);
    if (!scene.Occluded(origin, d, 0.0f, std::numeric_limits<float>::infinity())) want += weight;
  }
  const double got = fan.OpenWeight();
  EXPECT_EQ(got, want);
  EXPECT_GT(want, 0.0);
  EXPECT_LT(want, 37 * 1.0 + 0.1 * 36 * 37 / 2);  // some rays hit the box
}

// Rays outside Embree's contract (non-finite or zero origin or direction, t_near < 0 or past t_far) are misses;
// they used to reach the traversal, where an infinite direction aborted Embree.
TEST(RayScene, RaysOutsideEmbreesContractAreMisses) {
  RayScene scene;
  scene.AddMesh(Quad({0, 0, 1}, {1, 0, 0}, {0, 1, 0}, 1, 1));
  scene.Commit();
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const Eigen::Vector3f o = Eigen::Vector3f::Zero(), d(0, 0, 1);
  ASSERT_TRUE(scene.Intersect(o, d).Hit());
  for (const auto& [origin, dir] : std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>>{
           {Eigen::Vector3f(nan, 0, 0), d}, {o, Eigen::Vector3f(0, 0, inf)}, {o, Eigen::Vector3f(nan, nan, nan)},
           {o, Eigen::Vector3f::Zero()}, {Eigen::Vector3f(-inf, 0, 0), d}}) {
    EXPECT_FALSE(scene.Intersect(origin, dir).Hit()) << origin.transpose() << " -> " << dir.transpose();
    EXPECT_FALSE(scene.Occluded(origin, dir, 0, 10));
  }
  EXPECT_FALSE(scene.Intersect(o, d, nan).Hit());
  EXPECT_FALSE(scene.Intersect(o, d, -1).Hit());
  EXPECT_FALSE(scene.Intersect(o, d, 2, 1).Hit());
  EXPECT_FALSE(scene.Occluded(o, d, 0, nan));
  EXPECT_EQ(scene.IntersectMany({o, Eigen::Vector3f(nan, 0, 0)}, {d, d})[1].mesh, -1);
}

TEST(RayScene, IntersectManyMatchesIntersect) {
  const RayScene scene = PlaneScene();
  std::vector<Eigen::Vector3f> origins, dirs;
  for (int i = 0; i < 5000; ++i) {
    const float a = 0.0002f * i;  // up to 1 rad: stays within the 20 m quad
    origins.emplace_back(0.001f * i, 0, 0);
    dirs.emplace_back(std::sin(a), 0, (i % 7 == 0 ? -1.0f : 1.0f) * std::cos(a));
  }
  const std::vector<RayHit> hits = scene.IntersectMany(origins, dirs);
  ASSERT_EQ(hits.size(), origins.size());
  for (size_t i = 0; i < hits.size(); ++i) {
    const RayHit one = scene.Intersect(origins[i], dirs[i]);
    ASSERT_EQ(hits[i].Hit(), one.Hit()) << i;
    ASSERT_EQ(hits[i].Hit(), i % 7 != 0) << i;
    if (one.Hit()) {
      ASSERT_EQ(hits[i].t, one.t) << i;
    }
  }
}

TEST(RayScene, BaseColorCheckerTexture) {
  // 2x2 sRGB texture: texel (0,0) red-ish, (1,0) green-ish, (0,1) blue-ish, (1,1) grey.
  auto tex = std::make_shared<ImageU8>(2, 2, 3, 0);
  const uint8_t texels[2][2][3] = {{{200, 0, 0}, {0, 150, 0}}, {{0, 0, 100}, {60, 60, 60}}};  // [y][x]
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x)
      for (int c = 0; c < 3; ++c) tex->at(x, y, c) = texels[y][x][c];
  const auto linear = [&](int x, int y) {
    return Eigen::Vector3f(SrgbToLinear(texels[y][x][0] / 255.0f), SrgbToLinear(texels[y][x][1] / 255.0f),
                           SrgbToLinear(texels[y][x][2] / 255.0f));
  };

  // Quad in z = 1 over [0,2]x[0,2] with UV = (x, y) / 2 * 2 = (x, y): UVs run 0..2 to exercise repeat.
  auto mesh = Quad({1, 1, 1}, {1, 0, 0}, {0, 1, 0}, 1, 1);
  mesh->uvs = {{0, 0}, {2, 0}, {2, 2}, {0, 2}};
  Material mat;
  mat.base_color_factor = Eigen::Vector4f(0.5f, 1.0f, 1.0f, 1.0f);
  mat.base_color_texture = tex;
  mesh->materials = {mat};
  RayScene scene;
  scene.AddMesh(mesh);
  scene.Commit();

  const auto color_at = [&](float u, float v) {  // UV (u, v) sits at (x, y) = (u, v)
    const RayHit hit = scene.Intersect({u, v, 0}, {0, 0, 1});
    EXPECT_TRUE(hit.Hit());
    return scene.BaseColor(hit);
  };
  const Eigen::Vector3f factor(0.5f, 1, 1);
  // Texel centres, in the first tile and in the repeated one.
  for (float off : {0.0f, 1.0f}) {
    EXPECT_NEAR((color_at(0.25f + off, 0.25f).head<3>() - factor.cwiseProduct(linear(0, 0))).norm(), 0, 1e-5f);
    EXPECT_NEAR((color_at(0.75f + off, 0.25f).head<3>() - factor.cwiseProduct(linear(1, 0))).norm(), 0, 1e-5f);
    EXPECT_NEAR((color_at(0.25f + off, 0.75f).head<3>() - factor.cwiseProduct(linear(0, 1))).norm(), 0, 1e-5f);
    EXPECT_NEAR((color_at(0.75f + off, 0.75f).head<3>() - factor.cwiseProduct(linear(1, 1))).norm(), 0, 1e-5f);
  }
  EXPECT_NEAR(color_at(0.25f, 0.25f).w(), 1.0f, 1e-6f);
  // At u = 1.0 (tile seam) repeat addressing blends texel x=1 and the wrapped x=0 half and half, in linear.
  const Eigen::Vector3f seam = 0.5f * (linear(1, 0) + linear(0, 0));
  EXPECT_NEAR((color_at(1.0f, 0.25f).head<3>() - factor.cwiseProduct(seam)).norm(), 0, 1e-5f);

  // Vertex colours multiply; without UVs only the factor (and vertex colours) apply.
  auto plain = Quad({0, 0, 1}, {1, 0, 0}, {0, 1, 0}, 1, 1);
  plain->uvs.clear();
  plain->materials = {mat};
  plain->colors.assign(4, Eigen::Vector4f(0.5f, 0.5f, 0.25f, 1.0f));
  RayScene scene2;
  scene2.AddMesh(plain);
  scene2.Commit();
  const Eigen::Vector4f c = scene2.BaseColor(scene2.Intersect({0.1f, 0.2f, 0}, {0, 0, 1}));
  EXPECT_NEAR((c - Eigen::Vector4f(0.25f, 0.5f, 0.25f, 1.0f)).norm(), 0, 1e-6f);
}

TEST(RayScene, ShadingNormalInterpolatesVertexNormals) {
  auto mesh = Quad({0, 0, 1}, {1, 0, 0}, {0, 1, 0}, 1, 1);
  mesh->normals = {Eigen::Vector3f(-1, 0, 1).normalized(), Eigen::Vector3f(1, 0, 1).normalized(),
                   Eigen::Vector3f(1, 0, 1).normalized(), Eigen::Vector3f(-1, 0, 1).normalized()};
  RayScene scene;
  scene.AddMesh(mesh);
  scene.Commit();
  const RayHit mid = scene.Intersect({0, 0.3f, 0}, {0, 0, 1});  // halfway between x = -1 and x = 1
  EXPECT_NEAR((scene.ShadingNormal(mid) - Eigen::Vector3f(0, 0, 1)).norm(), 0, 1e-5f);
  EXPECT_NEAR((scene.GeometricNormal(mid) - Eigen::Vector3f(0, 0, 1)).norm(), 0, 1e-6f);
}

}  // namespace
}  // namespace sd
