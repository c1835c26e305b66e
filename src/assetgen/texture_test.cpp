#include "assetgen/texture.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "core/error.h"
#include "geometry/test_meshes.h"
#include "models/super_resolution.h"
#include "raster/raster.h"

namespace sd {
namespace {

// Rasterises `mesh` at `view` (hard edges) and colours each pixel with `shade(triangle, pixel)`; the mask is
// the coverage. Background is black, so any bleed of it into a fused colour would show.
template <typename Shade>
ColorView Render(const TriangleMesh& mesh, const ViewCamera& view, Shade shade) {
  const PinholeCamera& cam = view.camera;
  const float dist = static_cast<float>(view.T_world_cam.translation.norm());
  const Eigen::Matrix4f M = raster::ClipFromWorld(cam, view.T_world_cam.Inverse(), 0.05f * dist, 3.0f * dist);
  std::vector<float> clip(4 * mesh.NumVertices());
  raster::TransformToClip({reinterpret_cast<const float*>(mesh.positions.data()), 3 * mesh.NumVertices()}, M, clip);
  raster::RasterBuffer rast;
  raster::Rasterize(
      {clip, {reinterpret_cast<const int32_t*>(mesh.faces.data()), 3 * mesh.NumFaces()}, cam.width, cam.height}, &rast);
  ColorView out;
  out.view = view;
  out.color = ImageF(cam.width, cam.height, 3);
  out.mask = ImageF(cam.width, cam.height, 1);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const size_t p = static_cast<size_t>(y) * cam.width + x;
      if (rast.triangle[p] < 0) continue;
      const Eigen::Vector3f c = shade(rast, p);
      for (int k = 0; k < 3; ++k) out.color.at(x, y, k) = c[k];
      out.mask.at(x, y) = 1.0f;
    }
  }
  return out;
}

// A view whose image is one constant colour, all object.
ColorView ConstantView(const ViewCamera& view, const Eigen::Vector3f& c) {
  ColorView out;
  out.view = view;
  out.color = ImageF(view.camera.width, view.camera.height, 3);
  for (int y = 0; y < view.camera.height; ++y)
    for (int x = 0; x < view.camera.width; ++x)
      for (int k = 0; k < 3; ++k) out.color.at(x, y, k) = c[k];
  out.mask = ImageF(view.camera.width, view.camera.height, 1, 1.0f);
  return out;
}

// n x n grid of quads on the plane through `origin` spanned by `du`, `dv` (vertex (i, j) at origin + i/n du +
// j/n dv), wound so that its normal is du x dv. Appended to `mesh` with its own vertices.
void AppendGrid(TriangleMesh* mesh, int n, const Eigen::Vector3f& origin, const Eigen::Vector3f& du,
                const Eigen::Vector3f& dv) {
  const int base = static_cast<int>(mesh->NumVertices());
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) mesh->positions.push_back(origin + du * (float(i) / n) + dv * (float(j) / n));
  auto id = [&](int i, int j) { return base + j * (n + 1) + i; };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      mesh->faces.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      mesh->faces.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  }
}

const Eigen::Vector3f kRed(0.8f, 0.1f, 0.1f), kBlue(0.1f, 0.2f, 0.9f);

// Cube [-0.5, 0.5]^3, each face an n x n grid with its own vertices (split at every edge, as a loader splits a
// cube with per-face normals), faces coloured with distinct colours; rendered at the Zero123++ rig.
TEST(FuseVertexColors, SplitCubeAtTheRigReproducesItsFaceColours) {
  constexpr int n = 8;
  const std::vector<Eigen::Vector3f> face_color = {{0.9f, 0.1f, 0.1f}, {0.1f, 0.8f, 0.1f}, {0.1f, 0.2f, 0.9f},
                                                   {0.9f, 0.9f, 0.1f}, {0.1f, 0.9f, 0.9f}, {0.8f, 0.2f, 0.8f}};
  TriangleMesh cube;
  std::vector<Eigen::Vector3f> face_normal;
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      const Eigen::Vector3f normal = sign * Eigen::Vector3f::Unit(axis);
      Eigen::Vector3f du = Eigen::Vector3f::Unit((axis + 1) % 3), dv = Eigen::Vector3f::Unit((axis + 2) % 3);
      if (du.cross(dv).dot(normal) < 0) std::swap(du, dv);  // outward winding
      AppendGrid(&cube, n, 0.5f * normal - 0.5f * du - 0.5f * dv, du, dv);
      face_normal.push_back(normal);
    }
  }
  const int verts_per_face = (n + 1) * (n + 1), tris_per_face = 2 * n * n;
  ColorViewSet views;
  for (const ViewCamera& cam : Zero123PlusPlusRig(320)) {
    views.push_back(Render(cube, cam, [&](const raster::RasterBuffer& r, size_t p) {
      return face_color[r.triangle[p] / tris_per_face];
    }));
  }
  // The rule checked independently: the view with the largest signed cosine between the face normal and the
  // direction to its camera, or none (-1) where even that is below min_cosine (the bottom face's middle is
  // seen at a cosine of 0.049 from the -10 degree views, whose cameras sit only 0.2 below it).
  const VertexFusionOptions defaults;
  auto expected_view = [&](size_t v, int face) {
    int best = -1;
    float best_cos = defaults.min_cosine;
    for (size_t k = 0; k < views.size(); ++k) {
      const Eigen::Vector3f to_eye = views[k].view.T_world_cam.translation.cast<float>() - cube.positions[v];
      const float c = face_normal[face].dot(to_eye.normalized());
      if (c >= best_cos && (best < 0 || c > best_cos)) best_cos = c, best = static_cast<int>(k);
    }
    return best;
  };
  // Distance in grid steps from the vertex to its face's edges.
  auto margin = [&](size_t v) {
    const int i = static_cast<int>(v) % verts_per_face % (n + 1), j = static_cast<int>(v) % verts_per_face / (n + 1);
    return std::min({i, j, n - i, n - j});
  };

  // Without smoothing: vertices two or more grid steps from their face's edges read four pixels of their own
  // face (one step is under two pixels at the grazing bottom views), so they reproduce the face colour to
  // float rounding, and their view is the expected one. Unseen ones are filled from their neighbours, which
  // have the same colour.
  VertexFusionOptions unsmoothed;
  unsmoothed.seam_smoothing_iterations = 0;
  const VertexFusionResult raw = FuseVertexColors(cube, views, unsmoothed);
  ASSERT_EQ(raw.colors.size(), cube.NumVertices());
  ASSERT_EQ(raw.source_view.size(), cube.NumVertices());
  int checked = 0, unseen = 0;
  for (size_t v = 0; v < cube.NumVertices(); ++v) {
    const int face = static_cast<int>(v) / verts_per_face;
    if (margin(v) < 2) continue;
    ++checked;
    EXPECT_LT((raw.colors[v] - face_color[face]).cwiseAbs().maxCoeff(), 1e-5f) << "vertex " << v << " face " << face;
    const int best = expected_view(v, face);
    if (best < 0) ++unseen;
    EXPECT_EQ(raw.source_view[v], best) << "vertex " << v << " face " << face;
  }
  EXPECT_EQ(checked, 6 * (n - 3) * (n - 3));
  EXPECT_LT(unseen, (n - 3) * (n - 3));  // only part of the bottom face

  // With the default seam smoothing: a view seam runs through the side faces (perspective makes the two
  // nearest rig views swap rank across a face), so the band reaches their edges and the blend of the edge
  // vertices (which sample on the edge, between two faces) diffuses a few steps in. Measured: at most 0.033 on
  // a colour channel two steps in, 0.0029 on average.
  const VertexFusionResult r = FuseVertexColors(cube, views);
  double sum = 0, worst = 0;
  for (size_t v = 0; v < cube.NumVertices(); ++v) {
    const int face = static_cast<int>(v) / verts_per_face;
    EXPECT_TRUE(r.colors[v].allFinite());
    EXPECT_GE(r.colors[v].minCoeff(), 0.0f);
    EXPECT_LE(r.colors[v].maxCoeff(), 1.0f);
    EXPECT_EQ(r.source_view[v], raw.source_view[v]);  // smoothing changes colours, never the choice
    // Every vertex, edges included, is a blend of face colours: the mask weighting keeps the black background
    // out of silhouette samples, so the brightest channel stays well above black.
    EXPECT_GT(r.colors[v].maxCoeff(), 0.3f) << "vertex " << v;
    if (margin(v) < 2) continue;
    const double e = (r.colors[v] - face_color[face]).cwiseAbs().maxCoeff();
    sum += e;
    worst = std::max(worst, e);
  }
  std::printf("cube, default smoothing: worst %.4f mean %.5f two or more steps from an edge\n", worst, sum / checked);
  EXPECT_LT(worst, 0.05);
  EXPECT_LT(sum / checked, 0.005);
  EXPECT_EQ(r.propagated, raw.propagated);
}

TEST(FuseVertexColors, AVertexSeenTwiceTakesTheMoreFrontalView) {
  TriangleMesh quad;  // z = 0, facing +z
  AppendGrid(&quad, 4, Eigen::Vector3f(-0.5f, -0.5f, 0), Eigen::Vector3f::UnitX(), Eigen::Vector3f::UnitY());
  const ViewCamera frontal = OrbitCamera("frontal", 0, 80, 4, 30, 64, 64);
  const ViewCamera oblique = OrbitCamera("oblique", 0, 40, 4, 30, 64, 64);
  // Both orders, so that the view index is not what decides.
  for (const bool frontal_first : {true, false}) {
    ColorViewSet views;
    views.push_back(frontal_first ? ConstantView(frontal, kRed) : ConstantView(oblique, kBlue));
    views.push_back(frontal_first ? ConstantView(oblique, kBlue) : ConstantView(frontal, kRed));
    const VertexFusionResult r = FuseVertexColors(quad, views);
    const int frontal_index = frontal_first ? 0 : 1;
    EXPECT_EQ(r.propagated, 0);
    for (size_t v = 0; v < quad.NumVertices(); ++v) {
      EXPECT_EQ(r.source_view[v], frontal_index) << "vertex " << v;
      EXPECT_LT((r.colors[v] - kRed).cwiseAbs().maxCoeff(), 1e-6f) << "vertex " << v;
    }
  }
}

// A synthetic view (a shape prior's copy of real pixels) gives colour only where it sees the surface clearly
// more head-on than every real view; the provenance says where each vertex's colour came from.
TEST(FuseVertexColors, RealViewsWinOverSyntheticOnesUnlessFarLessHeadOn) {
  TriangleMesh quad;  // z = 0, facing +z
  AppendGrid(&quad, 4, Eigen::Vector3f(-0.5f, -0.5f, 0), Eigen::Vector3f::UnitX(), Eigen::Vector3f::UnitY());
  const ViewCamera frontal = OrbitCamera("frontal", 0, 80, 4, 30, 64, 64);
  ColorView synthetic = ConstantView(frontal, kRed);
  synthetic.synthetic = true;
  // Real view at 40 degrees elevation (cosine ~0.64 > 0.5 x ~0.98): the real view wins.
  {
    const ColorViewSet views = {synthetic, ConstantView(OrbitCamera("real", 0, 40, 4, 30, 64, 64), kBlue)};
    const VertexFusionResult r = FuseVertexColors(quad, views);
    for (size_t v = 0; v < quad.NumVertices(); ++v) EXPECT_EQ(r.source_view[v], 1) << "vertex " << v;
    EXPECT_NEAR(r.provenance.real, 1.0, 1e-9);
    EXPECT_NEAR(r.provenance.synthetic, 0.0, 1e-9);
  }
  // Real view at 20 degrees (cosine ~0.34 < 0.5 x ~0.98): the synthetic view sees it far more head-on.
  {
    const ColorViewSet views = {synthetic, ConstantView(OrbitCamera("real", 0, 20, 4, 30, 64, 64), kBlue)};
    const VertexFusionResult r = FuseVertexColors(quad, views);
    for (size_t v = 0; v < quad.NumVertices(); ++v) EXPECT_EQ(r.source_view[v], 0) << "vertex " << v;
    EXPECT_NEAR(r.provenance.synthetic, 1.0, 1e-9);
    EXPECT_NEAR(r.provenance.real + r.provenance.synthetic + r.provenance.propagated, 1.0, 1e-9);
  }
}

TEST(FuseVertexColors, SeamSmoothingOnlyTouchesTheSeamBand) {
  // A roof: two planes meeting at x = 0, each seen head-on by its own view (red from -x, blue from +x), so the
  // seam runs along the ridge.
  TriangleMesh roof;
  constexpr int n = 6;
  AppendGrid(&roof, n, Eigen::Vector3f(-0.6f, -0.5f, -0.3f), Eigen::Vector3f(0.6f, 0, 0.3f),
             Eigen::Vector3f(0, 1, 0));
  AppendGrid(&roof, n, Eigen::Vector3f(0, -0.5f, 0), Eigen::Vector3f(0.6f, 0, -0.3f), Eigen::Vector3f(0, 1, 0));
  const double tilt = std::atan2(0.6, 0.3) * 180 / 3.14159265358979323846;  // the planes' normals' elevation
  ColorViewSet views = {ConstantView(OrbitCamera("left", 180, tilt, 4, 30, 96, 96), kRed),
                        ConstantView(OrbitCamera("right", 0, tilt, 4, 30, 96, 96), kBlue)};
  VertexFusionOptions no_smoothing;
  no_smoothing.seam_smoothing_iterations = 0;
  const VertexFusionResult raw = FuseVertexColors(roof, views, no_smoothing);
  const VertexFusionResult smooth = FuseVertexColors(roof, views);
  ASSERT_EQ(raw.propagated, 0);
  int band = 0, blended = 0;
  for (size_t v = 0; v < roof.NumVertices(); ++v) {
    const Eigen::Vector3f& own = raw.source_view[v] == 0 ? kRed : kBlue;
    EXPECT_LT((raw.colors[v] - own).cwiseAbs().maxCoeff(), 1e-6f) << "vertex " << v;
    const float x = roof.positions[v].x();
    // The ridge vertices (x = 0) take one view, their neighbours on the other plane the other: the band is the
    // ridge plus the column next to it on the other side; everything else is untouched.
    if (std::abs(x) > 0.1f + 1e-4f) {
      EXPECT_EQ(smooth.colors[v], raw.colors[v]) << "vertex " << v << " x " << x;
    } else {
      ++band;
      // A blend of red and blue: weights sum to one, both present.
      const float t = (smooth.colors[v].z() - kRed.z()) / (kBlue.z() - kRed.z());
      EXPECT_LT((smooth.colors[v] - ((1 - t) * kRed + t * kBlue)).norm(), 1e-5f) << "vertex " << v;
      if (t > 0.01f && t < 0.99f) ++blended;
    }
  }
  EXPECT_GT(band, 0);
  EXPECT_GT(blended, n);  // at least one column of the band changed colour
}

TEST(FuseVertexColors, NoColourPassesThroughAnOccluder) {
  // Seen from +x (view 0, red): a large quad at x = 0.5 hides a small quad at x = -0.3 completely. Both face
  // +x. View 1 (blue) at azimuth 60 sees the small quad past the large one's edge, less head-on.
  TriangleMesh front, back;
  AppendGrid(&front, 4, Eigen::Vector3f(0.5f, -0.3f, -0.3f), 0.6f * Eigen::Vector3f::UnitY(),
             0.6f * Eigen::Vector3f::UnitZ());
  AppendGrid(&back, 2, Eigen::Vector3f(-0.3f, -0.2f, -0.2f), 0.4f * Eigen::Vector3f::UnitY(),
             0.4f * Eigen::Vector3f::UnitZ());
  TriangleMesh both = front;
  both.Append(back);
  const size_t num_front = front.NumVertices(), num_back = back.NumVertices();
  const ViewCamera head_on = OrbitCamera("head_on", 0, 0, 4, 30, 128, 128);
  const ViewCamera side = OrbitCamera("side", 60, 0, 4, 30, 128, 128);

  // Control: without the occluder the small quad takes view 0's red.
  {
    const VertexFusionResult r = FuseVertexColors(back, {ConstantView(head_on, kRed), ConstantView(side, kBlue)});
    for (size_t v = 0; v < num_back; ++v) EXPECT_EQ(r.source_view[v], 0) << "vertex " << v;
  }
  // With it, the small quad takes view 1's blue.
  {
    const VertexFusionResult r = FuseVertexColors(both, {ConstantView(head_on, kRed), ConstantView(side, kBlue)});
    for (size_t v = 0; v < num_front; ++v) EXPECT_EQ(r.source_view[v], 0) << "vertex " << v;
    for (size_t v = num_front; v < num_front + num_back; ++v) {
      EXPECT_EQ(r.source_view[v], 1) << "vertex " << v;
      EXPECT_LT((r.colors[v] - kBlue).cwiseAbs().maxCoeff(), 1e-6f) << "vertex " << v;
    }
    EXPECT_EQ(r.propagated, 0);
  }
  // With view 0 only, nothing sees it: it is its own component, so it gets the mid grey and counts as
  // propagated.
  {
    const VertexFusionResult r = FuseVertexColors(both, {ConstantView(head_on, kRed)});
    EXPECT_EQ(r.propagated, static_cast<int>(num_back));
    const float grey = SrgbToLinear(0.5f);
    for (size_t v = num_front; v < num_front + num_back; ++v) {
      EXPECT_EQ(r.source_view[v], -1) << "vertex " << v;
      EXPECT_LT((r.colors[v] - Eigen::Vector3f::Constant(grey)).cwiseAbs().maxCoeff(), 1e-6f) << "vertex " << v;
    }
  }
}

TEST(FuseVertexColors, PropagationFillsEveryVertex) {
  // A sphere seen only from above, with its lower half split off at the equator (own vertices, as a loader
  // splits a UV island): the weld carries the colour across the split. A small sphere hidden inside is a
  // component no view sees: mid grey.
  TriangleMesh sphere = geometry::testing::Icosphere(3, 0.8f);
  const size_t n_outer_welded = sphere.NumVertices();
  std::vector<int> copy(n_outer_welded, -1);
  for (auto& f : sphere.faces) {
    const float cz = (sphere.positions[f[0]] + sphere.positions[f[1]] + sphere.positions[f[2]]).z() / 3;
    if (cz >= 0) continue;
    for (int k = 0; k < 3; ++k) {
      if (copy[f[k]] < 0) {
        copy[f[k]] = static_cast<int>(sphere.positions.size());
        sphere.positions.push_back(sphere.positions[f[k]]);
      }
      f[k] = copy[f[k]];
    }
  }
  const size_t n_outer = sphere.NumVertices();
  sphere.Append(geometry::testing::Icosphere(1, 0.2f));
  const size_t n_inner = sphere.NumVertices() - n_outer;

  const ColorViewSet views = {ConstantView(OrbitCamera("top", 0, 60, 4, 30, 128, 128), kRed)};
  const VertexFusionResult r = FuseVertexColors(sphere, views);
  int unseen = 0, unseen_lower = 0;
  for (size_t v = 0; v < sphere.NumVertices(); ++v) {
    if (r.source_view[v] < 0) {
      ++unseen;
      if (v >= n_outer_welded && v < n_outer) ++unseen_lower;
    }
  }
  EXPECT_EQ(r.propagated, unseen);
  EXPECT_GT(unseen_lower, 100);  // most of the lower half
  for (size_t v = 0; v < n_outer; ++v) {
    EXPECT_LT((r.colors[v] - kRed).cwiseAbs().maxCoeff(), 1e-5f) << "vertex " << v << " source " << r.source_view[v];
  }
  const float grey = SrgbToLinear(0.5f);
  for (size_t v = n_outer; v < n_outer + n_inner; ++v) {
    EXPECT_EQ(r.source_view[v], -1);
    EXPECT_LT((r.colors[v] - Eigen::Vector3f::Constant(grey)).cwiseAbs().maxCoeff(), 1e-6f);
  }
}

// A smooth colour field on a ~20k-vertex sphere at the rig's 320 x 320 views: what fusion costs and how
// closely it reads a linearly varying colour back.
TEST(FuseVertexColors, ReadsBackASmoothColourField) {
  TriangleMesh sphere;
  constexpr int stacks = 140, slices = 144;
  constexpr double kPi = 3.14159265358979323846;
  sphere.positions.emplace_back(0, 0, 0.9f);
  for (int s = 1; s < stacks; ++s) {
    const double th = kPi * s / stacks;
    for (int k = 0; k < slices; ++k) {
      const double ph = 2 * kPi * k / slices;
      sphere.positions.emplace_back(0.9 * std::sin(th) * std::cos(ph), 0.9 * std::sin(th) * std::sin(ph),
                                    0.9 * std::cos(th));
    }
  }
  sphere.positions.emplace_back(0, 0, -0.9f);
  const int south = static_cast<int>(sphere.positions.size()) - 1;
  auto ring = [&](int s, int k) { return 1 + (s - 1) * slices + (k % slices); };
  for (int k = 0; k < slices; ++k) {
    sphere.faces.emplace_back(0, ring(1, k), ring(1, k + 1));
    sphere.faces.emplace_back(south, ring(stacks - 1, k + 1), ring(stacks - 1, k));
    for (int s = 1; s + 1 < stacks; ++s) {
      sphere.faces.emplace_back(ring(s, k), ring(s + 1, k), ring(s + 1, k + 1));
      sphere.faces.emplace_back(ring(s, k), ring(s + 1, k + 1), ring(s, k + 1));
    }
  }
  ASSERT_GT(sphere.NumVertices(), 20000u);
  auto field = [](const Eigen::Vector3f& p) { return Eigen::Vector3f(0.5f + 0.4f * p.x(), 0.5f + 0.4f * p.y(), 0.5f + 0.4f * p.z()); };
  std::vector<float> attr;
  for (const auto& p : sphere.positions) {
    const Eigen::Vector3f c = field(p);
    attr.insert(attr.end(), c.data(), c.data() + 3);
  }
  ColorViewSet views;
  for (const ViewCamera& cam : Zero123PlusPlusRig(320)) {
    views.push_back(Render(sphere, cam, [&](const raster::RasterBuffer& r, size_t p) {
      const Eigen::Vector3i& f = sphere.faces[r.triangle[p]];
      const float b0 = r.bary[2 * p], b1 = r.bary[2 * p + 1];
      return Eigen::Vector3f(b0 * field(sphere.positions[f[0]]) + b1 * field(sphere.positions[f[1]]) +
                             (1 - b0 - b1) * field(sphere.positions[f[2]]));
    }));
  }
  const VertexFusionResult r = FuseVertexColors(sphere, views);
  // Sampling a pixel off costs more surface distance the more grazing the view (1 / cosine), so the bound is
  // tight where the view is head-on and loose where it grazes (the bottom cap, seen only from -10 degrees).
  double max_frontal = 0, max_seen = 0, max_all = 0, sum = 0;
  for (size_t v = 0; v < sphere.NumVertices(); ++v) {
    const double e = (r.colors[v] - field(sphere.positions[v])).cwiseAbs().maxCoeff();
    sum += e;
    max_all = std::max(max_all, e);
    if (r.source_view[v] < 0) continue;
    max_seen = std::max(max_seen, e);
    const Eigen::Vector3f to_eye =
        views[r.source_view[v]].view.T_world_cam.translation.cast<float>() - sphere.positions[v];
    if (to_eye.normalized().dot(sphere.positions[v].normalized()) >= 0.3f) max_frontal = std::max(max_frontal, e);
  }
  const double mean = sum / sphere.NumVertices();
  std::printf("smooth field: %d of %zu propagated; max error %.5f (cosine >= 0.3) %.5f (seen) %.5f (all), mean %.6f\n",
              r.propagated, sphere.NumVertices(), max_frontal, max_seen, max_all, mean);
  EXPECT_LT(max_frontal, 0.001);
  EXPECT_LT(max_seen, 0.02);
  EXPECT_LT(max_all, 0.08);
  EXPECT_LT(mean, 0.002);
  EXPECT_LT(r.propagated, static_cast<int>(sphere.NumVertices() / 10));
}

// Super-resolution ahead of fusion keeps pictures and cameras registered: the split cube's views at 160 px,
// upscaled ×2, come with 320 px cameras of the same field of view, and fusion from them still gives the
// vertices inside each face that face's colour.
TEST(SuperResolveViews, KeepsViewsRegisteredWithTheirCameras) {
  constexpr int n = 6;
  const std::vector<Eigen::Vector3f> face_color = {{0.9f, 0.1f, 0.1f}, {0.1f, 0.8f, 0.1f}, {0.1f, 0.2f, 0.9f},
                                                   {0.9f, 0.9f, 0.1f}, {0.1f, 0.9f, 0.9f}, {0.8f, 0.2f, 0.8f}};
  TriangleMesh cube;
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      const Eigen::Vector3f normal = sign * Eigen::Vector3f::Unit(axis);
      Eigen::Vector3f du = Eigen::Vector3f::Unit((axis + 1) % 3), dv = Eigen::Vector3f::Unit((axis + 2) % 3);
      if (du.cross(dv).dot(normal) < 0) std::swap(du, dv);
      AppendGrid(&cube, n, 0.5f * normal - 0.5f * du - 0.5f * dv, du, dv);
    }
  }
  const int verts_per_face = (n + 1) * (n + 1), tris_per_face = 2 * n * n;
  ColorViewSet views;
  for (const ViewCamera& cam : Zero123PlusPlusRig(160)) {
    views.push_back(Render(cube, cam, [&](const raster::RasterBuffer& r, size_t p) {
      return face_color[r.triangle[p] / tris_per_face];
    }));
  }
  const ColorViewSet up = SuperResolveViews(views, models::Upscaler::Classical(2));
  ASSERT_EQ(up.size(), views.size());
  for (size_t i = 0; i < up.size(); ++i) {
    EXPECT_EQ(up[i].view.camera.width, 320);
    EXPECT_EQ(up[i].color.width(), 320);
    EXPECT_EQ(up[i].mask.height(), 320);
    EXPECT_NEAR(up[i].view.camera.fx, 2 * views[i].view.camera.fx, 1e-9);
    EXPECT_NEAR(up[i].view.camera.cx, 2 * views[i].view.camera.cx, 1e-9);
    EXPECT_TRUE(up[i].view.T_world_cam.translation.isApprox(views[i].view.T_world_cam.translation));
    for (float m : up[i].mask.vector()) ASSERT_TRUE(m >= 0.0f && m <= 1.0f);
  }
  VertexFusionOptions unsmoothed;
  unsmoothed.seam_smoothing_iterations = 0;
  const VertexFusionResult fused = FuseVertexColors(cube, up, unsmoothed);
  // Bicubic overshoot at the silhouette reaches a vertex two steps in only at the grazing bottom views (under 2
  // pixels there): measured 0.006 at worst, 0.0005 on average. A camera off by half a pixel would blend the
  // neighbouring face in at ~0.4.
  int checked = 0;
  double sum = 0;
  for (size_t v = 0; v < cube.NumVertices(); ++v) {
    const int i = static_cast<int>(v) % verts_per_face % (n + 1), j = static_cast<int>(v) % verts_per_face / (n + 1);
    if (std::min({i, j, n - i, n - j}) < 2 || fused.source_view[v] < 0) continue;
    ++checked;
    const float e = (fused.colors[v] - face_color[v / verts_per_face]).cwiseAbs().maxCoeff();
    sum += e;
    EXPECT_LT(e, 0.01f) << "vertex " << v;
  }
  std::printf("cube from x2 bicubic views: mean %.5f over %d vertices\n", sum / checked, checked);
  EXPECT_GT(checked, 4 * 9);
  EXPECT_LT(sum / checked, 1e-3);
}

TEST(FuseVertexColors, RejectsBadInput) {
  const TriangleMesh cube = geometry::testing::Cube(Eigen::Vector3f::Constant(-0.5f), Eigen::Vector3f::Constant(0.5f));
  const ViewCamera cam = OrbitCamera("view_a", 30, 20, 4, 30, 32, 32);
  const ColorView good = ConstantView(cam, kRed);
  EXPECT_NO_THROW(FuseVertexColors(cube, {good}));

  EXPECT_THROW(FuseVertexColors(cube, {}), InputError);
  EXPECT_THROW(FuseVertexColors(TriangleMesh{}, {good}), InputError);

  auto message = [&](const ColorViewSet& views) -> std::string {
    try {
      FuseVertexColors(cube, views);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  ColorView wrong_size = good;
  wrong_size.color = ImageF(16, 32, 3);
  EXPECT_NE(message({good, wrong_size}).find("view 1 ('view_a'): colour image is 16x32"), std::string::npos)
      << message({good, wrong_size});
  ColorView wrong_channels = good;
  wrong_channels.color = ImageF(32, 32, 1);
  EXPECT_NE(message({wrong_channels}).find("view_a"), std::string::npos);
  ColorView wrong_mask = good;
  wrong_mask.mask = ImageF(32, 31, 1);
  EXPECT_NE(message({wrong_mask}).find("view 0 ('view_a'): mask is 32x31"), std::string::npos)
      << message({wrong_mask});
  ColorView no_mask = good;
  no_mask.mask = ImageF();
  EXPECT_NO_THROW(FuseVertexColors(cube, {no_mask}));
  TriangleMesh bad_index = cube;
  bad_index.faces[0][1] = 8;
  EXPECT_THROW(FuseVertexColors(bad_index, {good}), InputError);
}

}  // namespace
}  // namespace sd
