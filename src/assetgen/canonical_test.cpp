#include "assetgen/canonical.h"

#include <gtest/gtest.h>

#include "assetgen/asset.h"
#include "core/error.h"
#include "io/mesh_io.h"
#include "testing/testing.h"

namespace sd {
namespace {

// A 2 x 1 x 0.5 box in a y-up file whose front is +z: canonical length is the file's z.
TriangleMesh FileBox() {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i) m.positions.emplace_back((i & 1) ? 1.0f : 0.0f, (i & 2) ? 0.5f : 0.0f, (i & 4) ? 2.0f : 0.0f);
  m.faces = {{0, 1, 3}, {0, 3, 2}, {4, 6, 7}, {4, 7, 5}, {0, 4, 5}, {0, 5, 1}, {2, 3, 7}, {2, 7, 6}, {0, 2, 6}, {0, 6, 4}, {1, 5, 7}, {1, 7, 3}};
  return m;
}

TEST(Canonical, AxesScaleAndGroundContact) {
  CanonicalizeOptions o;
  o.up = "+y";
  o.front = "+z";
  o.scale = 2.0;
  const CanonicalizeResult r = Canonicalize(FileBox(), o);
  EXPECT_TRUE(r.extent.isApprox(Eigen::Vector3d(4.0, 2.0, 1.0), 1e-6)) << r.extent.transpose();
  const AlignedBox3f b = r.mesh.Bounds();
  EXPECT_NEAR(b.min.z(), 0.0, 1e-6);                 // resting on z = 0
  EXPECT_NEAR(b.Center().x(), 0.0, 1e-6);            // centred on the ground contact
  EXPECT_NEAR(b.Center().y(), 0.0, 1e-6);
  EXPECT_NEAR(r.rotation.determinant(), 1.0, 1e-12);  // a rotation, never a mirror
  // The file's +z (front) is now +x.
  EXPECT_TRUE((r.rotation * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitX()));
}

TEST(Canonical, ScaleFromTargets) {
  CanonicalizeOptions o;
  o.up = "+y";
  o.front = "+z";
  o.target_height = 1.5;
  EXPECT_NEAR(Canonicalize(FileBox(), o).scale, 3.0, 1e-9);
  o.target_height.reset();
  o.target_size = Eigen::Vector3d(4.0, 2.0, 1.0);
  EXPECT_NEAR(Canonicalize(FileBox(), o).scale, 2.0, 1e-9);
}

TEST(Canonical, ImpossibleOptionsAreErrors) {
  CanonicalizeOptions o;
  o.up = "+y";
  o.front = "-y";
  o.scale = 1;
  EXPECT_THROW(Canonicalize(FileBox(), o), InputError);
  o.front = "+w";
  EXPECT_THROW(Canonicalize(FileBox(), o), InputError);
  o.front = "+x";
  o.scale = -1;
  EXPECT_THROW(Canonicalize(FileBox(), o), InputError);
  o.scale = 0;
  EXPECT_THROW(Canonicalize(FileBox(), o), InputError);  // no scale source at all
  EXPECT_THROW(Canonicalize(TriangleMesh{}, CanonicalizeOptions{}), InputError);
}

TEST(Asset, SaveLoadRoundTripKeepsTheCanonicalTexturedMesh) {
  CanonicalizeOptions o;
  o.up = "+y";
  o.target_height = 0.7;
  const CanonicalizeResult r = Canonicalize(LoadMesh(testing::RepoData("assets/metadrive_traffic_cone/scene.gltf")), o);
  Asset a;
  a.mesh = r.mesh;
  a.info.id = "cone";
  a.info.category = "traffic_cone";
  a.info.extent = r.extent;
  testing::TempDir dir;
  SaveAsset(a, dir / "cone", false);
  EXPECT_THROW(SaveAsset(a, dir / "cone", false), InputError);  // never overwrites silently
  const Asset back = LoadAsset(dir / "cone");
  EXPECT_EQ(back.info.id, "cone");
  EXPECT_EQ(back.mesh.NumFaces(), a.mesh.NumFaces());
  EXPECT_NEAR(back.info.extent.z(), 0.7, 1e-6);
  EXPECT_NEAR(back.mesh.Bounds().min.z(), 0.0, 1e-5);
  EXPECT_FALSE(back.mesh.uvs.empty());
  ASSERT_FALSE(back.mesh.materials.empty());
  EXPECT_TRUE(back.mesh.materials[0].base_color_texture != nullptr);
  EXPECT_TRUE(std::filesystem::exists(dir / "cone" / "preview.png"));
}

}  // namespace
}  // namespace sd
