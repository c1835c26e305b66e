#include "assetgen/uv_atlas.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <numeric>

#include <gtest/gtest.h>

#include "core/error.h"
#include "geometry/test_meshes.h"
#include "io/mesh_io.h"
#include "raster/raster.h"
#include "testing/testing.h"

namespace sd {
namespace {

double Cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

std::vector<Eigen::Vector2d> TexelCorners(const TriangleMesh& m, size_t f, int size) {
  std::vector<Eigen::Vector2d> t(3);
  for (int k = 0; k < 3; ++k) t[k] = m.uvs[m.faces[f][k]].cast<double>() * size;
  return t;
}

double PointTriangleDistance(const Eigen::Vector2d& p, const std::vector<Eigen::Vector2d>& t) {
  const double area = Cross2(t[1] - t[0], t[2] - t[0]);
  const double w0 = Cross2(t[1] - p, t[2] - p) / area, w1 = Cross2(t[2] - p, t[0] - p) / area;
  if (w0 >= 0 && w1 >= 0 && 1 - w0 - w1 >= 0) return 0;
  double best = 1e300;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector2d e = t[(k + 1) % 3] - t[k];
    const double s = std::clamp((p - t[k]).dot(e) / e.squaredNorm(), 0.0, 1.0);
    best = std::min(best, (t[k] + s * e - p).norm());
  }
  return best;
}

// Charts of an atlas = faces connected through shared vertices or identical UVs (a chart keeps the input's
// split vertices, e.g. at its old normal seams, but they land on the same UV; distinct charts never touch).
std::vector<int> ChartOfFace(const TriangleMesh& m) {
  std::vector<int> parent(m.NumVertices());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  std::map<std::pair<float, float>, int> at_uv;
  for (size_t v = 0; v < m.NumVertices(); ++v) {
    const auto [it, inserted] = at_uv.emplace(std::make_pair(m.uvs[v].x(), m.uvs[v].y()), int(v));
    if (!inserted) parent[find(int(v))] = find(it->second);
  }
  for (const auto& f : m.faces) {
    parent[find(f[1])] = find(f[0]);
    parent[find(f[2])] = find(f[0]);
  }
  std::vector<int> chart(m.NumFaces());
  for (size_t f = 0; f < m.NumFaces(); ++f) chart[f] = find(m.faces[f][0]);
  return chart;
}

// The atlas contract, checked independently of how it was built.
void ExpectValidAtlas(const TriangleMesh& in, const TriangleMesh& atlas, const UvAtlasOptions& options,
                      const UvAtlasStats& stats, float min_utilisation) {
  const int size = options.texture_size, pad = options.padding_px;
  ASSERT_EQ(atlas.NumFaces(), in.NumFaces());
  ASSERT_EQ(atlas.uvs.size(), atlas.NumVertices());
  EXPECT_EQ(atlas.Validate(), "");
  // Positions per face corner unchanged (bit for bit), UVs in [0, 1].
  int moved = 0;
  for (size_t f = 0; f < in.NumFaces(); ++f)
    for (int k = 0; k < 3; ++k) moved += atlas.positions[atlas.faces[f][k]] != in.positions[in.faces[f][k]];
  EXPECT_EQ(moved, 0);
  for (const auto& uv : atlas.uvs) {
    ASSERT_TRUE(uv.x() >= 0 && uv.x() <= 1 && uv.y() >= 0 && uv.y() <= 1) << uv.transpose();
  }
  // Every face has positive UV area, and the same orientation as every other (no flipped triangle).
  double area = 0;
  int non_positive = 0;
  for (size_t f = 0; f < atlas.NumFaces(); ++f) {
    const auto t = TexelCorners(atlas, f, size);
    const double a = 0.5 * Cross2(t[1] - t[0], t[2] - t[0]);
    non_positive += !(a > 0);
    area += std::abs(a);
  }
  EXPECT_EQ(non_positive, 0);
  const double utilisation = area / (double(size) * size);
  EXPECT_NEAR(stats.utilisation, utilisation, 1e-4);
  EXPECT_GT(stats.utilisation, min_utilisation);
  // No overlap: texel centres at least 1e-3 texel inside two triangles (points on a shared edge do not count).
  std::vector<uint8_t> claims(size_t(size) * size, 0);
  // Gutters: the disks of radius `pad` about different charts are disjoint (charts 2 * pad apart).
  std::vector<int> near_chart(size_t(size) * size, -1);
  const std::vector<int> chart = ChartOfFace(atlas);
  int twice = 0, gutter_conflicts = 0;
  for (size_t f = 0; f < atlas.NumFaces(); ++f) {
    const auto t = TexelCorners(atlas, f, size);
    const double a = Cross2(t[1] - t[0], t[2] - t[0]);
    const Eigen::Vector2d lo = t[0].cwiseMin(t[1]).cwiseMin(t[2]), hi = t[0].cwiseMax(t[1]).cwiseMax(t[2]);
    const int x0 = std::max(0, int(std::floor(lo.x())) - pad - 1), x1 = std::min(size - 1, int(hi.x()) + pad + 1);
    const int y0 = std::max(0, int(std::floor(lo.y())) - pad - 1), y1 = std::min(size - 1, int(hi.y()) + pad + 1);
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d p(x + 0.5, y + 0.5);
        const size_t i = size_t(y) * size + x;
        bool inside = true;
        for (int k = 0; k < 3; ++k) {
          const Eigen::Vector2d e = t[(k + 1) % 3] - t[k];
          inside &= Cross2(e, p - t[k]) / a * e.norm() > 1e-3;  // distance to the edge line, inward
        }
        if (inside && ++claims[i] == 2) ++twice;
        if (pad > 0 && PointTriangleDistance(p, t) < pad - 0.05) {
          if (near_chart[i] >= 0 && near_chart[i] != chart[f]) ++gutter_conflicts;
          near_chart[i] = chart[f];
        }
      }
    }
  }
  EXPECT_EQ(twice, 0) << "texels claimed by two triangles";
  EXPECT_EQ(gutter_conflicts, 0) << "texels within the gutter of two charts";
  std::vector<int> roots(chart);
  std::sort(roots.begin(), roots.end());
  EXPECT_EQ(std::unique(roots.begin(), roots.end()) - roots.begin(), stats.charts);
}

TEST(BuildUvAtlas, IcosphereIsAValidAtlas) {
  const TriangleMesh sphere = geometry::testing::Icosphere(3);  // 1280 faces
  UvAtlasOptions options;
  UvAtlasStats stats;
  const TriangleMesh atlas = BuildUvAtlas(sphere, options, &stats);
  std::printf("icosphere(3): %d charts, utilisation %.3f\n", stats.charts, stats.utilisation);
  // A 60-degree cone cuts a sphere into caps: at least 4 (each cap holds at most a quarter of the sphere).
  EXPECT_GE(stats.charts, 4);
  ExpectValidAtlas(sphere, atlas, options, stats, 0.45f);  // 0.496 measured
}

TEST(BuildUvAtlas, TrafficConeIsAValidAtlas) {
  const TriangleMesh cone = LoadMesh(testing::RepoData("assets/metadrive_traffic_cone/scene.gltf"));
  UvAtlasOptions options;
  UvAtlasStats stats;
  const TriangleMesh atlas = BuildUvAtlas(cone, options, &stats);
  std::printf("traffic cone (%zu faces): %d charts, utilisation %.3f\n", cone.NumFaces(), stats.charts,
              stats.utilisation);
  ExpectValidAtlas(cone, atlas, options, stats, 0.45f);  // 0.502 measured
  // Attributes other than UVs follow their vertices.
  ASSERT_EQ(atlas.normals.size(), atlas.NumVertices());
  for (size_t f = 0; f < cone.NumFaces(); ++f)
    for (int k = 0; k < 3; ++k) ASSERT_EQ(atlas.normals[atlas.faces[f][k]], cone.normals[cone.faces[f][k]]);
}

// Real assets of the shared set (skipped without ../shared): scans, a low-poly car with degenerate slivers, a
// detailed car with duplicated faces and many parts. Utilisation falls with the number of charts (each
// pays its gutter).
TEST(BuildUvAtlas, SharedAssetsAreValidAtlases) {
  SD_REQUIRE_SHARED(root, "assets");
  const std::pair<const char*, float> assets[] = {
      {"scanned_stanford/stanford_bunny_lowres/bunny.obj", 0.45f},
      {"scanned_gso/gso_chefmate_8_frypan/chefmate_8_frypan.obj", 0.35f},
      {"car/trigger_evo_wrc/evo_wrc.obj", 0.45f},
      {"car/metadrive_beetle/vehicle.gltf", 0.12f}};
  for (const auto& [rel, min_utilisation] : assets) {
    SCOPED_TRACE(rel);
    const TriangleMesh mesh = LoadMesh(root / rel);
    UvAtlasOptions options;
    UvAtlasStats stats;
    const TriangleMesh atlas = BuildUvAtlas(mesh, options, &stats);
    std::printf("%s (%zu faces): %d charts, utilisation %.3f\n", rel, mesh.NumFaces(), stats.charts, stats.utilisation);
    ExpectValidAtlas(mesh, atlas, options, stats, min_utilisation);
  }
}

TEST(BuildUvAtlas, BadInput) {
  EXPECT_THROW(BuildUvAtlas(TriangleMesh{}, {}), InputError);
  const TriangleMesh sphere = geometry::testing::Icosphere(1);
  UvAtlasOptions options;
  options.texture_size = 16;
  EXPECT_THROW(BuildUvAtlas(sphere, options), InputError);
  options.texture_size = 1 << 20;
  EXPECT_THROW(BuildUvAtlas(sphere, options), InputError);
  options.texture_size = 256;
  options.padding_px = -1;
  EXPECT_THROW(BuildUvAtlas(sphere, options), InputError);
  options.padding_px = 4;
  options.max_normal_angle_deg = 120;
  EXPECT_THROW(BuildUvAtlas(sphere, options), InputError);
}

// --- baking ----------------------------------------------------------------------------------------------

raster::RasterBuffer RasterizeAt(const TriangleMesh& mesh, const ViewCamera& view) {
  const float dist = float(view.T_world_cam.translation.norm());
  const Eigen::Matrix4f M = raster::ClipFromWorld(view.camera, view.T_world_cam.Inverse(), dist - 2, dist + 2);
  std::vector<float> clip(4 * mesh.NumVertices());
  raster::TransformToClip({reinterpret_cast<const float*>(mesh.positions.data()), 3 * mesh.NumVertices()}, M, clip);
  raster::RasterBuffer rast;
  raster::Rasterize({clip, {reinterpret_cast<const int32_t*>(mesh.faces.data()), 3 * mesh.NumFaces()},
                     view.camera.width, view.camera.height},
                    &rast);
  return rast;
}

// Colour views of a mesh whose faces have known linear colours (no shading: what the baker must reproduce).
ColorViewSet RenderFaceColours(const TriangleMesh& mesh, const std::vector<Eigen::Vector3f>& face_colour,
                               const std::vector<ViewCamera>& cameras) {
  ColorViewSet views;
  for (const ViewCamera& cam : cameras) {
    const raster::RasterBuffer rast = RasterizeAt(mesh, cam);
    ColorView v;
    v.view = cam;
    v.color = ImageF(cam.camera.width, cam.camera.height, 3);
    v.mask = ImageF(cam.camera.width, cam.camera.height, 1);
    for (int y = 0; y < rast.height; ++y) {
      for (int x = 0; x < rast.width; ++x) {
        const int t = rast.triangle[size_t(y) * rast.width + x];
        if (t < 0) continue;
        for (int c = 0; c < 3; ++c) v.color.at(x, y, c) = face_colour[t][c];
        v.mask.at(x, y) = 1;
      }
    }
    views.push_back(std::move(v));
  }
  return views;
}

// sRGB [0, 1] images of the mesh at a camera: per-face colours (ground truth) or the texture through UVs.
ImageF RenderGroundTruth(const TriangleMesh& mesh, const std::vector<Eigen::Vector3f>& face_colour,
                         const ViewCamera& cam, std::vector<uint8_t>* covered) {
  const raster::RasterBuffer rast = RasterizeAt(mesh, cam);
  ImageF out(rast.width, rast.height, 3);
  covered->assign(rast.NumPixels(), 0);
  for (size_t p = 0; p < rast.NumPixels(); ++p) {
    if (rast.triangle[p] < 0) continue;
    (*covered)[p] = 1;
    for (int c = 0; c < 3; ++c) out.data()[3 * p + c] = LinearToSrgb(face_colour[rast.triangle[p]][c]);
  }
  return out;
}

ImageF RenderTextured(const TriangleMesh& mesh, const ImageU8& texture, const ViewCamera& cam) {
  const raster::RasterBuffer rast = RasterizeAt(mesh, cam);
  std::vector<float> uv(2 * rast.NumPixels());
  raster::Interpolate({{reinterpret_cast<const float*>(mesh.uvs.data()), 2 * mesh.NumVertices()}, 2,
                       {reinterpret_cast<const int32_t*>(mesh.faces.data()), 3 * mesh.NumFaces()}, rast},
                      uv);
  ImageF out(rast.width, rast.height, 3);
  for (size_t p = 0; p < rast.NumPixels(); ++p) {
    if (rast.triangle[p] < 0) continue;
    float c[3];
    SampleBilinear(texture, uv[2 * p] * texture.width(), uv[2 * p + 1] * texture.height(), c);
    for (int k = 0; k < 3; ++k) out.data()[3 * p + k] = c[k] / 255.0f;
  }
  return out;
}

double Psnr(const ImageF& a, const ImageF& b, const std::vector<uint8_t>& covered) {
  double se = 0;
  size_t n = 0;
  for (size_t p = 0; p < covered.size(); ++p) {
    if (!covered[p]) continue;
    for (int c = 0; c < 3; ++c) se += std::pow(double(a.data()[3 * p + c]) - b.data()[3 * p + c], 2);
    n += 3;
  }
  return 10 * std::log10(1.0 / std::max(se / double(n), 1e-12));
}

// Half-size 0.35: the rig's -10 degree views then see the bottom at a cosine of about 0.09, above the
// fusion's 0.05 cut-off (a half-size 0.5 cube's bottom is at 0.05, so it would be partly unseen).
struct ColouredCube {
  TriangleMesh mesh = geometry::testing::Cube(Eigen::Vector3f::Constant(-0.35f), Eigen::Vector3f::Constant(0.35f));
  std::vector<Eigen::Vector3f> face_colour;  // per triangle (pairs share their cube face's colour)
  ColouredCube() {
    const Eigen::Vector3f side[6] = {{0.8f, 0.1f, 0.1f}, {0.1f, 0.7f, 0.1f}, {0.1f, 0.1f, 0.8f},
                                     {0.8f, 0.8f, 0.1f}, {0.1f, 0.8f, 0.8f}, {0.8f, 0.1f, 0.8f}};
    for (int t = 0; t < 12; ++t) face_colour.push_back(side[t / 2]);  // Cube(): triangles 2k, 2k+1 = side k
  }
};

TEST(BakeTexture, CubeFacesKeepTheirColours) {
  const ColouredCube cube;
  const ColorViewSet views = RenderFaceColours(cube.mesh, cube.face_colour, Zero123PlusPlusRig(320));
  UvAtlasOptions options;
  options.texture_size = 256;
  UvAtlasStats stats;
  const TriangleMesh atlas = BuildUvAtlas(cube.mesh, options, &stats);
  EXPECT_EQ(stats.charts, 6);  // one per side: neighbouring sides are 90 degrees apart
  const ImageU8 tex = BakeTexture(atlas, views, 256);
  ASSERT_EQ(tex.width(), 256);
  ASSERT_EQ(tex.channels(), 3);

  // At each triangle's UV centroid the texture holds its side's colour, to one 8-bit sRGB level (rounding).
  for (size_t f = 0; f < atlas.NumFaces(); ++f) {
    Eigen::Vector2f c = Eigen::Vector2f::Zero();
    for (int k = 0; k < 3; ++k) c += atlas.uvs[atlas.faces[f][k]] / 3;
    float got[3];
    SampleBilinear(tex, c.x() * 256.0, c.y() * 256.0, got);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], 255 * LinearToSrgb(cube.face_colour[f][k]), 1.0) << f << " " << k;
  }

  // Gutters: every texel within padding_px - 0.5 texels of a side's chart holds that side's colour (dilation),
  // so bilinear lookups at chart borders never mix in a neighbour or the background.
  int wrong_gutter = 0, checked = 0;
  for (size_t f = 0; f < atlas.NumFaces(); ++f) {
    const auto t = TexelCorners(atlas, f, 256);
    const Eigen::Vector2d lo = t[0].cwiseMin(t[1]).cwiseMin(t[2]), hi = t[0].cwiseMax(t[1]).cwiseMax(t[2]);
    for (int y = std::max(0, int(lo.y()) - 4); y <= std::min(255, int(hi.y()) + 4); ++y) {
      for (int x = std::max(0, int(lo.x()) - 4); x <= std::min(255, int(hi.x()) + 4); ++x) {
        if (PointTriangleDistance({x + 0.5, y + 0.5}, t) > options.padding_px - 0.5) continue;
        ++checked;
        for (int k = 0; k < 3; ++k)
          wrong_gutter += std::abs(tex.at(x, y, k) - 255 * LinearToSrgb(cube.face_colour[f][k])) > 1.0f;
      }
    }
  }
  EXPECT_GT(checked, 6 * 40 * 40);
  EXPECT_EQ(wrong_gutter, 0);

  // Held-out view (azimuth 0, elevation 35: no rig view): the textured cube matches the per-face render.
  const ViewCamera held_out = OrbitCamera("held_out", 0, 35, kRigDistance, 30, 320, 320);
  std::vector<uint8_t> covered;
  const ImageF truth = RenderGroundTruth(cube.mesh, cube.face_colour, held_out, &covered);
  const ImageF textured = RenderTextured(atlas, tex, held_out);
  const double psnr = Psnr(truth, textured, covered);
  std::printf("cube, held-out view: PSNR %.1f dB\n", psnr);
  EXPECT_GT(psnr, 40.0);
}

TEST(BakeTexture, SurfaceNoViewSeesTakesTheFusedVertexColours) {
  const ColouredCube cube;
  // Only the first rig view (azimuth 30, elevation +20): the bottom (side 0, z = -0.35) is never seen.
  const ColorViewSet views = RenderFaceColours(cube.mesh, cube.face_colour, {Zero123PlusPlusRig(320)[0]});
  UvAtlasOptions options;
  options.texture_size = 128;
  const TriangleMesh atlas = BuildUvAtlas(cube.mesh, options);
  TextureProvenance provenance;
  const ImageU8 tex = BakeTexture(atlas, views, 128, {}, &provenance);
  const VertexFusionResult fused = FuseVertexColors(atlas, views);
  // Three of the six equal sides face the one view; the bottom and two sides are propagated.
  EXPECT_NEAR(provenance.real, 0.5, 0.08) << provenance.real;
  EXPECT_EQ(provenance.synthetic, 0.0);
  EXPECT_NEAR(provenance.real + provenance.propagated, 1.0, 1e-9);
  auto centroid = [&](int f) {
    Eigen::Vector2f c = Eigen::Vector2f::Zero();
    for (int k = 0; k < 3; ++k) c += atlas.uvs[atlas.faces[f][k]] / 3;
    return c;
  };
  // Bottom triangles: the barycentric interpolation of the fused vertex colours, at the texel centre nearest
  // the centroid (0.6 sRGB levels of rounding, plus the colour's change across half a texel: 2 levels).
  for (int f : {0, 1}) {
    const Eigen::Vector2f c = centroid(f) * 128;
    const int x = int(c.x()), y = int(c.y());
    const Eigen::Vector2d p(x + 0.5, y + 0.5);
    const auto t = TexelCorners(atlas, f, 128);
    const double area = Cross2(t[1] - t[0], t[2] - t[0]);
    const double b0 = Cross2(t[1] - p, t[2] - p) / area, b1 = Cross2(t[2] - p, t[0] - p) / area;
    const Eigen::Vector3i& face = atlas.faces[f];
    const Eigen::Vector3f expected = float(b0) * fused.colors[face[0]] + float(b1) * fused.colors[face[1]] +
                                     float(1 - b0 - b1) * fused.colors[face[2]];
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(tex.at(x, y, k), 255 * LinearToSrgb(expected[k]), 2.0) << f << " " << k;
  }
  // The top (side 1) is seen: its own colour.
  const Eigen::Vector2f c = centroid(2);
  float got[3];
  SampleBilinear(tex, c.x() * 128.0, c.y() * 128.0, got);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], 255 * LinearToSrgb(cube.face_colour[2][k]), 1.0);
}

TEST(BakeTexture, GlbRoundTripKeepsTextureAndUvs) {
  const TriangleMesh sphere = geometry::testing::Icosphere(2, 0.9f);
  std::vector<Eigen::Vector3f> colour(sphere.NumFaces());
  for (size_t f = 0; f < sphere.NumFaces(); ++f) colour[f] = (sphere.FaceNormal(f).array() * 0.4f + 0.5f).matrix();
  const ColorViewSet views = RenderFaceColours(sphere, colour, Zero123PlusPlusRig(160));
  UvAtlasOptions options;
  options.texture_size = 256;
  TriangleMesh atlas = BuildUvAtlas(sphere, options);
  Material material;
  material.name = "baked";
  material.base_color_texture = std::make_shared<ImageU8>(BakeTexture(atlas, views, 256));
  material.base_color_texture_name = "baked.png";
  atlas.materials = {material};

  testing::TempDir dir;
  SaveGlb(dir / "baked.glb", atlas);
  const TriangleMesh back = LoadGlbZUp(dir / "baked.glb");
  ASSERT_EQ(back.NumVertices(), atlas.NumVertices());
  ASSERT_EQ(back.NumFaces(), atlas.NumFaces());
  ASSERT_EQ(back.uvs.size(), back.NumVertices());
  for (size_t v = 0; v < atlas.NumVertices(); ++v) {
    ASSERT_EQ(back.uvs[v], atlas.uvs[v]) << v;
    ASSERT_LT((back.positions[v] - atlas.positions[v]).norm(), 1e-6f) << v;
  }
  for (size_t f = 0; f < atlas.NumFaces(); ++f) ASSERT_EQ(back.faces[f], atlas.faces[f]);
  ASSERT_EQ(back.materials.size(), 1u);
  ASSERT_TRUE(back.materials[0].base_color_texture);
  EXPECT_EQ(back.materials[0].base_color_texture->width(), 256);
  EXPECT_EQ(back.materials[0].base_color_texture->vector(), atlas.materials[0].base_color_texture->vector());  // PNG
}

TEST(BakeTexture, BadInput) {
  const ColouredCube cube;
  const ColorViewSet views = RenderFaceColours(cube.mesh, cube.face_colour, {Zero123PlusPlusRig(64)[0]});
  EXPECT_THROW(BakeTexture(cube.mesh, views, 256), InputError);  // no UVs
  EXPECT_THROW(BakeTexture(TriangleMesh{}, views, 256), InputError);
  const TriangleMesh atlas = BuildUvAtlas(cube.mesh, {});
  EXPECT_THROW(BakeTexture(atlas, views, 0), InputError);
  EXPECT_THROW(BakeTexture(atlas, views, 1 << 20), InputError);
  EXPECT_THROW(BakeTexture(atlas, {}, 256), InputError);
  ColorViewSet wrong = views;
  wrong[0].color = ImageF(32, 32, 3);
  EXPECT_THROW(BakeTexture(atlas, wrong, 256), InputError);
  BakeOptions bad;
  bad.padding_px = -2;
  EXPECT_THROW(BakeTexture(atlas, views, 256, bad), InputError);
}

// Ad hoc timing at about 20k faces: 6 views of 320x320, a 1024^2 atlas (reported, not bounded).
TEST(BakeTexture, TimingAt20kFaces) {
  const TriangleMesh sphere = geometry::testing::Icosphere(5, 0.9f);  // 20480 faces
  std::vector<Eigen::Vector3f> colour(sphere.NumFaces());
  for (size_t f = 0; f < sphere.NumFaces(); ++f) colour[f] = (sphere.FaceNormal(f).array() * 0.4f + 0.5f).matrix();
  const ColorViewSet views = RenderFaceColours(sphere, colour, Zero123PlusPlusRig(320));
  const auto t0 = std::chrono::steady_clock::now();
  UvAtlasStats stats;
  const TriangleMesh atlas = BuildUvAtlas(sphere, {}, &stats);
  const auto t1 = std::chrono::steady_clock::now();
  const ImageU8 tex = BakeTexture(atlas, views, 1024);
  const auto t2 = std::chrono::steady_clock::now();
  FuseVertexColors(atlas, views);  // part of the bake when some texels are unseen (here: round the poles)
  const auto t3 = std::chrono::steady_clock::now();
  std::printf("%zu faces: BuildUvAtlas %.0f ms (%d charts, utilisation %.3f), BakeTexture 1024^2 from 6 views of "
              "320^2 %.0f ms\n",
              sphere.NumFaces(), std::chrono::duration<double, std::milli>(t1 - t0).count(), stats.charts,
              stats.utilisation, std::chrono::duration<double, std::milli>(t2 - t1).count());
  std::printf("  of which FuseVertexColors (called when some texels are unseen) at most %.0f ms\n",
              std::chrono::duration<double, std::milli>(t3 - t2).count());
  EXPECT_EQ(tex.width(), 1024);
}

}  // namespace
}  // namespace sd
