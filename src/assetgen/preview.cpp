#include "assetgen/preview.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include "assetgen/texture_eval.h"
#include "assetgen/views.h"
#include "render/camera_render.h"
#include "render/ray_scene.h"

namespace sd {

ImageU8 RenderPreview(const TriangleMesh& mesh, int width, int height) {
  const AlignedBox3f b = mesh.Bounds();
  const Eigen::Vector3d center = b.Center().cast<double>();
  const double radius = std::max(0.5 * static_cast<double>(b.Size().norm()), 1e-3);

  RayScene scene;
  auto object = std::make_shared<TriangleMesh>(mesh);
  if (object->normals.empty()) object->ComputeVertexNormals();
  scene.AddMesh(object);
  auto floor = std::make_shared<TriangleMesh>();
  const float f = static_cast<float>(radius * 6);
  floor->positions = {{-f, -f, b.min.z()}, {f, -f, b.min.z()}, {f, f, b.min.z()}, {-f, f, b.min.z()}};
  floor->faces = {{0, 1, 2}, {0, 2, 3}};
  const int floor_id = scene.AddMesh(floor);
  scene.Commit();

  // Camera on a sphere around the object: azimuth 35 deg left of the front, 25 deg up.
  PinholeCamera cam;
  cam.width = width;
  cam.height = height;
  const double fov_y = 30.0 * M_PI / 180.0;
  cam.fy = cam.fx = 0.5 * height / std::tan(0.5 * fov_y);
  cam.cx = 0.5 * width;
  cam.cy = 0.5 * height;
  const double dist = 1.15 * radius / std::sin(0.5 * fov_y);
  const double az = 35.0 * M_PI / 180.0, el = 25.0 * M_PI / 180.0;
  const Eigen::Vector3d eye = center + dist * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  const Eigen::Vector3d z = (center - eye).normalized();                      // camera forward
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();  // camera right
  const Eigen::Vector3d y = z.cross(x);                                       // camera down
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = y;
  R.col(2) = z;
  const Rigid3d T_scene_cam(R, eye);

  Lighting light;
  light.sun_direction = Eigen::Vector3f(0.4f, 0.6f, 1.0f).normalized();
  light.sun_irradiance = Eigen::Vector3f::Constant(2.2f);
  light.sky_radiance = Eigen::Vector3f(0.20f, 0.21f, 0.24f);
  CameraRenderOptions opt;
  opt.receiver_mesh = floor_id;
  opt.samples_per_pixel = 4;
  opt.ao_samples = 8;
  const CameraRender r = RenderCamera(scene, cam, T_scene_cam, light, opt);

  ImageF out(width, height, 3);
  const float background = 0.55f;  // linear grey floor/backdrop
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const float a = r.coverage.at(u, v);
      const float shade = r.shadow.at(u, v);
      for (int c = 0; c < 3; ++c) out.at(u, v, c) = r.color.at(u, v, c) + (1 - a) * background * shade;
    }
  return ToSrgb8(out);
}

ImageU8 RenderTurntable(const TriangleMesh& mesh, int views, int size) {
  views = std::max(1, views);
  ImageU8 strip(views * size, size, 3, 0);
  const BoundingSphere sphere = BoundingSphereOf(mesh.positions);
  TriangleMesh centred = mesh;
  for (auto& p : centred.positions) p -= sphere.centre;
  const double fov = 30, distance = 1.1 * std::max(sphere.radius, 1e-3f) / std::sin(0.5 * fov * M_PI / 180.0);
  for (int i = 0; i < views; ++i) {
    const ViewCamera cam = OrbitCamera("turntable", 360.0 * i / views, 15, distance, fov, size, size);
    const AlbedoRender r = RenderAlbedo(centred, cam, 2);
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x) {
        const float m = r.mask.at(x, y);
        for (int c = 0; c < 3; ++c) {
          const float v = m * LinearToSrgb(std::clamp(r.color.at(x, y, c), 0.0f, 1.0f)) + (1 - m) * 0.85f;
          strip.at(i * size + x, y, c) = static_cast<uint8_t>(std::lround(255 * std::clamp(v, 0.0f, 1.0f)));
        }
      }
  }
  return strip;
}

}  // namespace sd
