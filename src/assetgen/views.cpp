#include "assetgen/views.h"

#include "assetgen/texture_eval.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/parallel.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "raster/raster.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr char kFormat[] = "synthdrive-views/1";

Eigen::Vector3f DecodeNormal(const uint8_t* rgb) {
  return Eigen::Vector3f(rgb[0], rgb[1], rgb[2]) / 127.5f - Eigen::Vector3f::Ones();
}

uint8_t EncodeUnit(float v) { return static_cast<uint8_t>(std::clamp(std::lround((v + 1.0f) * 127.5f), 0L, 255L)); }

// Separable Gaussian blur, clamped at the border.
ImageF GaussianBlur(const ImageF& in, float sigma) {
  if (sigma <= 0) return in;
  const int radius = std::max(1, static_cast<int>(std::ceil(3 * sigma)));
  std::vector<float> kernel(2 * radius + 1);
  float sum = 0;
  for (int i = -radius; i <= radius; ++i) sum += kernel[i + radius] = std::exp(-0.5f * i * i / (sigma * sigma));
  for (float& k : kernel) k /= sum;
  const int w = in.width(), h = in.height(), c = in.channels();
  ImageF tmp(w, h, c), out(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int ch = 0; ch < c; ++ch) {
        float acc = 0;
        for (int i = -radius; i <= radius; ++i) acc += kernel[i + radius] * in.at(std::clamp(x + i, 0, w - 1), y, ch);
        tmp.at(x, y, ch) = acc;
      }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int ch = 0; ch < c; ++ch) {
        float acc = 0;
        for (int i = -radius; i <= radius; ++i) acc += kernel[i + radius] * tmp.at(x, std::clamp(y + i, 0, h - 1), ch);
        out.at(x, y, ch) = acc;
      }
  return out;
}

Rigid3d PerturbPose(const Rigid3d& T_world_cam, const OracleDegradation& d, std::mt19937_64& rng) {
  std::normal_distribution<double> gauss(0.0, 1.0);
  Eigen::Vector3d axis(gauss(rng), gauss(rng), gauss(rng));
  const double angle = d.pose_error_deg * kPi / 180.0;
  Eigen::Vector3d shift(gauss(rng), gauss(rng), gauss(rng));
  if (shift.norm() > 0) shift = shift.normalized() * d.pose_error_translation;
  const Eigen::Quaterniond dq(Eigen::AngleAxisd(angle, axis.normalized()));
  return Rigid3d(T_world_cam.rotation * dq, T_world_cam.translation + shift);
}

MultiView RenderOne(const TriangleMesh& mesh, const BoundingSphere& sphere, const std::vector<Eigen::Vector3f>& face_normals,
                    const ViewCamera& nominal, const Rigid3d& T_world_cam_render, int ss) {
  const PinholeCamera cam = Supersampled(nominal.camera, ss);
  const raster::RasterBuffer rast = RasterizeView(mesh, cam, T_world_cam_render, sphere);

  const Eigen::Vector3f eye = T_world_cam_render.translation.cast<float>();
  MultiView out;
  out.view = nominal;
  const int w = nominal.camera.width, h = nominal.camera.height;
  out.normals = ImageF(w, h, 3);
  out.mask = ImageF(w, h, 1);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      Eigen::Vector3f n_sum = Eigen::Vector3f::Zero();
      const int covered = VisitCoveredSamples(rast, cam.width, x, y, ss, [&](size_t p) {
        const int32_t t = rast.triangle[p];
        Eigen::Vector3f n = face_normals[t];
        // What an estimator sees is the side facing the camera: open or inconsistently wound scans
        // show back faces, whose stored normal points away.
        const Eigen::Vector3i& f = mesh.faces[t];
        if (n.dot(mesh.positions[f[0]] - eye) > 0) n = -n;
        n_sum += n;
      });
      out.mask.at(x, y) = static_cast<float>(covered) / (ss * ss);
      if (covered > 0 && n_sum.norm() > 1e-6f) {
        const Eigen::Vector3f n = n_sum.normalized();
        for (int c = 0; c < 3; ++c) out.normals.at(x, y, c) = n[c];
      }
    }
  }
  return out;
}

void Renormalize(ImageF* normals) {
  for (int y = 0; y < normals->height(); ++y)
    for (int x = 0; x < normals->width(); ++x) {
      float* n = normals->pixel(x, y);
      const float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      for (int c = 0; c < 3; ++c) n[c] = len > 1e-6f ? n[c] / len : 0.0f;
    }
}

}  // namespace

ViewCamera OrbitCamera(const std::string& name, double azimuth_deg, double elevation_deg, double distance,
                       double vertical_fov_deg, int width, int height) {
  const double az = azimuth_deg * kPi / 180.0, el = elevation_deg * kPi / 180.0;
  const Eigen::Vector3d eye = distance * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  const Eigen::Vector3d forward = (-eye).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d R;
  R << right, down, forward;
  ViewCamera v;
  v.name = name;
  v.T_world_cam = Rigid3d(R, eye);
  const double f = 0.5 * height / std::tan(0.5 * vertical_fov_deg * kPi / 180.0);
  v.camera.width = width;
  v.camera.height = height;
  v.camera.fx = v.camera.fy = f;
  v.camera.cx = 0.5 * width;
  v.camera.cy = 0.5 * height;
  return v;
}

std::vector<ViewCamera> Zero123PlusPlusRig(int image_size) {
  std::vector<ViewCamera> rig;
  for (int i = 0; i < 6; ++i) {
    char name[16];
    std::snprintf(name, sizeof(name), "view_%02d", i);
    rig.push_back(OrbitCamera(name, 30.0 + 60.0 * i, i % 2 == 0 ? 20.0 : -10.0, kRigDistance, 30.0, image_size, image_size));
  }
  return rig;
}

BoundingSphere BoundingSphereOf(const std::vector<Eigen::Vector3f>& positions) {
  AlignedBox3f box;
  for (const auto& p : positions) box.Extend(p);
  BoundingSphere sphere;
  sphere.centre = box.Center();
  for (const auto& p : positions) sphere.radius = std::max(sphere.radius, (p - sphere.centre).norm());
  return sphere;
}

Eigen::Matrix4f ClipFromWorldAround(const PinholeCamera& camera, const Rigid3d& T_world_cam, const BoundingSphere& sphere) {
  // Near and far about the sphere's depth along the optical axis, not its distance: the two differ for an
  // object far off the axis (a photo's crop keeps the full camera's principal point, outside the crop).
  const Rigid3d T_cam_world = T_world_cam.Inverse();
  const float dist = (T_world_cam.translation.cast<float>() - sphere.centre).norm();
  const float depth = static_cast<float>((T_cam_world * sphere.centre.cast<double>()).z());
  const float near = std::max(1e-4f * dist, depth - 1.5f * sphere.radius);
  const float far = std::max(near * 1.001f, depth + 1.5f * sphere.radius);
  return raster::ClipFromWorld(camera, T_cam_world, near, far);
}

PinholeCamera Supersampled(const PinholeCamera& camera, int factor) {
  SD_CHECK(factor >= 1, << factor);
  PinholeCamera c = camera;
  c.width *= factor;
  c.height *= factor;
  c.fx *= factor;
  c.fy *= factor;
  c.cx *= factor;
  c.cy *= factor;
  return c;
}

raster::RasterBuffer RasterizeView(const TriangleMesh& mesh, const PinholeCamera& camera, const Rigid3d& T_world_cam,
                                   const BoundingSphere& sphere) {
  std::vector<float> clip(4 * mesh.NumVertices());
  raster::TransformToClip({reinterpret_cast<const float*>(mesh.positions.data()), 3 * mesh.NumVertices()},
                          ClipFromWorldAround(camera, T_world_cam, sphere), clip);
  raster::RasterBuffer rast;
  raster::Rasterize(
      {clip, {reinterpret_cast<const int32_t*>(mesh.faces.data()), 3 * mesh.NumFaces()}, camera.width, camera.height},
      &rast);
  return rast;
}

void SphereNormalization::Apply(TriangleMesh* mesh) const {
  for (auto& p : mesh->positions) p = scale * (p - centre);
}
void SphereNormalization::Undo(TriangleMesh* mesh) const {
  for (auto& p : mesh->positions) p = p / scale + centre;
}

SphereNormalization NormalizeIntoSphere(const TriangleMesh& mesh, float radius) {
  if (mesh.positions.empty()) throw InputError({}, "cannot normalise an empty mesh");
  const BoundingSphere sphere = BoundingSphereOf(mesh.positions);
  SphereNormalization n;
  n.centre = sphere.centre;
  const float r = sphere.radius;
  if (!(r > 0)) throw InputError({}, "cannot normalise a mesh whose vertices all coincide");
  n.scale = radius / r;
  return n;
}

MultiViewSet RenderOracleViews(const TriangleMesh& mesh, const std::vector<ViewCamera>& cameras, int supersample,
                               const OracleDegradation& degradation) {
  if (mesh.NumFaces() == 0) throw InputError({}, "oracle views: the mesh has no triangles");
  SD_CHECK(supersample >= 1, << supersample);
  std::vector<Eigen::Vector3f> face_normals(mesh.NumFaces());
  for (size_t f = 0; f < mesh.NumFaces(); ++f) face_normals[f] = mesh.FaceNormal(f);
  const BoundingSphere sphere = BoundingSphereOf(mesh.positions);

  // One generator per view, seeded from the set's seed, so the result does not depend on thread timing.
  MultiViewSet views(cameras.size());
  ParallelFor(0, cameras.size(), [&](size_t i) {
    std::mt19937_64 rng(degradation.seed * 1000003ull + i);
    const Rigid3d T_render = degradation.pose_error_deg > 0 || degradation.pose_error_translation > 0
                                 ? PerturbPose(cameras[i].T_world_cam, degradation, rng)
                                 : cameras[i].T_world_cam;
    MultiView v = RenderOne(mesh, sphere, face_normals, cameras[i], T_render, supersample);
    ViewCamera render_camera = cameras[i];
    render_camera.T_world_cam = T_render;
    v.color = RenderAlbedo(mesh, render_camera, supersample).color;
    if (degradation.blur_sigma_px > 0) {
      v.normals = GaussianBlur(v.normals, degradation.blur_sigma_px);
      v.mask = GaussianBlur(v.mask, degradation.blur_sigma_px);
      v.color = GaussianBlur(v.color, degradation.blur_sigma_px);
    }
    if (degradation.normal_noise > 0) {
      std::normal_distribution<float> noise(0.0f, degradation.normal_noise);
      for (int y = 0; y < v.normals.height(); ++y)
        for (int x = 0; x < v.normals.width(); ++x)
          if (v.mask.at(x, y) > 0)
            for (int c = 0; c < 3; ++c) v.normals.at(x, y, c) += noise(rng);
    }
    if (degradation.Any()) Renormalize(&v.normals);
    views[i] = std::move(v);
  });
  return views;
}

MultiViewSet LoadViews(const std::filesystem::path& dir) {
  const std::filesystem::path json_path = dir / "cameras.json";
  if (!std::filesystem::exists(json_path)) throw InputError(json_path, Msg() << "missing (a views folder needs cameras.json)");
  const nlohmann::json j = ReadJsonFile(json_path);
  const JsonReader root(j, json_path);
  const std::string format = root.StringOr("format", kFormat);
  if (format != kFormat) root["format"].Fail("unsupported format '" + format + "' (expected " + kFormat + ")");
  const std::string frame = root.StringOr("normal_frame", "camera");
  if (frame != "camera" && frame != "world") root["normal_frame"].Fail("must be \"camera\" or \"world\", not \"" + frame + "\"");
  const JsonReader list = root["views"];
  if (list.Size() == 0) list.Fail("no views");

  MultiViewSet views(list.Size());
  for (size_t i = 0; i < list.Size(); ++i) {
    const JsonReader v = list[i];
    MultiView& mv = views[i];
    mv.view.name = v.StringOr("name", "view_" + std::to_string(i));
    PinholeCamera& cam = mv.view.camera;
    cam.width = static_cast<int>(v["width"].Integer());
    cam.height = static_cast<int>(v["height"].Integer());
    cam.fx = v["fx"].Number();
    cam.fy = v["fy"].Number();
    cam.cx = v["cx"].Number();
    cam.cy = v["cy"].Number();
    if (cam.width <= 0 || cam.height <= 0) v["width"].Fail("image size must be positive");
    if (!(cam.fx > 0 && cam.fy > 0)) v["fx"].Fail("focal lengths must be positive");
    const JsonReader T = v["T_world_cam"];
    if (T.Size() != 4) T.Fail("must be a 4x4 matrix (4 rows of 4 numbers)");
    Eigen::Matrix4d m;
    for (int r = 0; r < 4; ++r) {
      if (T[r].Size() != 4) T[r].Fail("must be a row of 4 numbers");
      for (int c = 0; c < 4; ++c) m(r, c) = T[r][c].Number();
    }
    const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
    if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-3 || R.determinant() < 0 ||
        (m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-6)
      T.Fail("is not a rigid transform (rotation must be orthonormal with determinant +1, last row 0 0 0 1)");
    mv.view.T_world_cam = Rigid3d::FromMatrix(m);

    // Every image of a view is read at its camera's size.
    auto read_view_image = [&](const std::string& name, int channels) {
      const std::filesystem::path file = dir / name;
      ImageU8 img = ReadImage(file, channels);
      if (img.width() != cam.width || img.height() != cam.height)
        throw InputError(file, Msg() << "image is " << img.width() << "x" << img.height()
                               << " but its camera in cameras.json says " << cam.width << "x" << cam.height);
      return img;
    };
    const ImageU8 normals = read_view_image(v["normals"].String(), 3);
    const ImageU8 mask = read_view_image(v["mask"].String(), 1);
    if (i > 0 && (cam.width != views[0].view.camera.width || cam.height != views[0].view.camera.height))
      throw InputError(json_path, Msg() << "views[" << i << "] is " << cam.width << "x" << cam.height
                             << " but views[0] is " << views[0].view.camera.width << "x" << views[0].view.camera.height
                             << " (all views of a set must have one size)");

    if (v.Has("known")) {
      const ImageU8 known = read_view_image(v["known"].String(), 1);
      mv.known = ImageF(cam.width, cam.height, 1);
      for (size_t k = 0; k < mv.known.vector().size(); ++k) mv.known.vector()[k] = known.data()[k] > 127 ? 1.0f : 0.0f;
    }
    if (v.Has("synthetic")) mv.synthetic = v["synthetic"].Bool();
    if (v.Has("source")) mv.source = v["source"].String();
    if (v.Has("image")) {
      mv.color = ToLinear(read_view_image(v["image"].String(), 3));
    }
    const Eigen::Matrix3f R_world_frame = frame == "camera" ? Eigen::Matrix3f(mv.view.T_world_cam.Rotation().cast<float>())
                                                            : Eigen::Matrix3f(Eigen::Matrix3f::Identity());
    mv.normals = ImageF(cam.width, cam.height, 3);
    mv.mask = ImageF(cam.width, cam.height, 1);
    for (int y = 0; y < cam.height; ++y) {
      for (int x = 0; x < cam.width; ++x) {
        mv.mask.at(x, y) = mask.at(x, y) / 255.0f;
        const Eigen::Vector3f n = DecodeNormal(normals.pixel(x, y));
        // Background is stored as black, which decodes to a long vector; real normals decode near unit length.
        if (mv.mask.at(x, y) > 0 && std::abs(n.norm() - 1.0f) < 0.25f) {
          const Eigen::Vector3f nw = (R_world_frame * n).normalized();
          for (int c = 0; c < 3; ++c) mv.normals.at(x, y, c) = nw[c];
        }
      }
    }
  }
  return views;
}

void SaveViews(const MultiViewSet& views, const std::filesystem::path& dir, const std::string& normal_frame,
               bool overwrite) {
  SD_CHECK(normal_frame == "camera" || normal_frame == "world", << normal_frame);
  StagingDirectory out(dir, overwrite);
  nlohmann::json list = nlohmann::json::array();
  for (size_t i = 0; i < views.size(); ++i) {
    const MultiView& v = views[i];
    const PinholeCamera& cam = v.view.camera;
    char nf[32], mf[32];
    std::snprintf(nf, sizeof(nf), "normal_%02zu.png", i);
    std::snprintf(mf, sizeof(mf), "mask_%02zu.png", i);
    const Eigen::Matrix3f R_frame_world = normal_frame == "camera"
                                              ? Eigen::Matrix3f(v.view.T_world_cam.Rotation().transpose().cast<float>())
                                              : Eigen::Matrix3f(Eigen::Matrix3f::Identity());
    ImageU8 normals(cam.width, cam.height, 3), mask(cam.width, cam.height, 1);
    for (int y = 0; y < cam.height; ++y) {
      for (int x = 0; x < cam.width; ++x) {
        mask.at(x, y) = static_cast<uint8_t>(std::lround(std::clamp(v.mask.at(x, y), 0.0f, 1.0f) * 255.0f));
        const Eigen::Vector3f n(v.normals.at(x, y, 0), v.normals.at(x, y, 1), v.normals.at(x, y, 2));
        if (n.squaredNorm() == 0) continue;  // black background
        const Eigen::Vector3f nf3 = R_frame_world * n;
        for (int c = 0; c < 3; ++c) normals.at(x, y, c) = EncodeUnit(nf3[c]);
      }
    }
    WriteImage(out.path() / nf, normals);
    WriteImage(out.path() / mf, mask);
    const Eigen::Matrix4d T = v.view.T_world_cam.Matrix();
    nlohmann::json rows = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({T(r, 0), T(r, 1), T(r, 2), T(r, 3)});
    nlohmann::json entry = {{"name", v.view.name}, {"normals", nf}, {"mask", mf}, {"width", cam.width},
                             {"height", cam.height}, {"fx", cam.fx}, {"fy", cam.fy}, {"cx", cam.cx}, {"cy", cam.cy},
                             {"T_world_cam", rows}};
    if (!v.color.empty()) {
      char cf[32];
      std::snprintf(cf, sizeof(cf), "image_%02zu.png", i);
      WriteImage(out.path() / cf, ToSrgb8(v.color));
      entry["image"] = cf;
    }
    if (!v.known.empty()) {
      char kf[32];
      std::snprintf(kf, sizeof(kf), "known_%02zu.png", i);
      ImageU8 known(cam.width, cam.height, 1, 0);
      for (size_t k = 0; k < v.known.vector().size(); ++k) known.data()[k] = v.known.vector()[k] > 0.5f ? 255 : 0;
      WriteImage(out.path() / kf, known);
      entry["known"] = kf;
    }
    if (v.synthetic) entry["synthetic"] = true;
    if (!v.source.empty()) entry["source"] = v.source;
    list.push_back(entry);
  }
  WriteJsonFile(out.path() / "cameras.json", {{"format", kFormat}, {"normal_frame", normal_frame}, {"views", list}});
  out.Commit();
}

bool IsWhole(const MultiView& view) {
  return std::all_of(view.known.vector().begin(), view.known.vector().end(), [](float k) { return k > 0.5f; });
}

ImageF MaskOrUnknown(const MultiView& view) {
  ImageF out = view.mask;
  if (view.known.empty()) return out;
  for (size_t k = 0; k < out.vector().size(); ++k)
    if (view.known.vector()[k] <= 0.5f) out.vector()[k] = 1.0f;
  return out;
}

ImageU8 NormalMapPreview(const MultiView& view) {
  const int w = view.normals.width(), h = view.normals.height();
  ImageU8 out(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = std::clamp(view.mask.at(x, y), 0.0f, 1.0f);
      for (int c = 0; c < 3; ++c) {
        const float v = 0.5f * (view.normals.at(x, y, c) + 1.0f);
        out.at(x, y, c) = static_cast<uint8_t>(std::lround(255.0f * (a * v + (1 - a) * 0.25f)));
      }
    }
  return out;
}

}  // namespace sd
