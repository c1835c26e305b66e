// The road's shade under inserted objects (ReceiverShadowImage, the "camera shadows" stage of synth) against
// ReceiverShadowRatio called at every pixel (what the image did before it traced the sun's disk only near the
// edges of its centre's hard shadow), on the real keyframe: the demo's objects (5) and 20 of them placed by
// SynthesizeFrame, under the frame's own environment map (sky radiance, SH, sun), in every camera they touch, over
// each object's box-and-shadow rectangle as synth shades it.
//
// Variants (sun rays over the disk / sky rays per pixel):
//   per pixel:   8 / 16, ReceiverShadowRatio at every pixel;
//   image:       8 / 16, ReceiverShadowImage (the synth default);
//   image 1 BVH: the same in a scene without the second BVH that leaves the receiver out
//                (RayScene::SetOftenSkipped): the receiver's hits filtered out of every sky and sun ray instead;
//   image 4 sky: 8 / 4, ReceiverShadowImage (what a quarter of the sky rays would give).
// Quality: against a reference of 64 disk rays and 256 sky rays, ReceiverShadowRatio at every pixel, the error of
// the ratio (the factor the real road's light is multiplied by, 0-1) over the receiver pixels the reference or
// any variant darkens by more than 1 %: raw, as the camera look shows it (the shade map blurred with sigma 1.5
// px, the look's least), and over penumbra pixels (the reference changes by more than 0.1 to a 4-neighbour,
// grown by 1 px).
// Time: median of 5, interleaved. Crops: bench/results/road_shade/<scene>_<camera>_<object>.png, each a strip of
// the reference, per-pixel and image shade maps as seen (blurred), grey, enlarged up to 4x.
//
// Usage: bench_road_shade [--no-crops]. Repo root: $SYNTHDRIVE_SOURCE_DIR, else build/bin/../../.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "assetgen/asset.h"
#include "core/image.h"
#include "core/mesh.h"
#include "core/parallel.h"
#include "datasets/readers.h"
#include "io/image_io.h"
#include "render/camera_render.h"
#include "render/ray_scene.h"
#include "synth/camera_look.h"
#include "synth/environment.h"
#include "synth/frame.h"
#include "synth/frame_stages.h"
#include "synth/scenario.h"

#include "bench_demo.h"

namespace {
namespace fs = std::filesystem;

struct Variant {
  const char* name;
  int sun_rays, sky_rays;
  bool image;        // ReceiverShadowImage, else ReceiverShadowRatio per pixel
  bool one_bvh = false;  // in the scene without SetOftenSkipped
};
const Variant kReference{"reference", 64, 256, false};
const std::vector<Variant> kVariants = {
    {"per pixel", 8, 16, false},
    {"image", 8, 16, true},
    {"image 1 BVH", 8, 16, true, true},
    {"image 4 sky", 8, 4, true},
};

// ReceiverShadowRatio at every pixel of `rects` whose ray first meets the receiver, seeded as the image seeds.
sd::ImageF PerPixel(const sd::RayScene& scene, const sd::CameraSensor& cam, int receiver, const sd::EnvironmentLight& light,
                    const sd::EnvShadingOptions& options, const std::vector<std::array<int, 4>>& rects) {
  const sd::PinholeCamera& c = cam.intrinsics;
  sd::ImageF out(c.width, c.height, 1, 1.0f);
  const auto [y0, y1] = sd::RowRange(rects, c.height);
  const Eigen::Vector3f origin = cam.T_ego_cam.translation.cast<float>();
  sd::ParallelFor(static_cast<size_t>(std::max(0, y0)), static_cast<size_t>(std::max(y0, y1)), [&](size_t yy) {
    const int y = static_cast<int>(yy);
    for (const auto& [x0, x1] : sd::RowSpans(rects, y, c.width))
      for (int x = x0; x < x1; ++x) {
        const Eigen::Vector3d d = cam.T_ego_cam.rotation * c.RayDirection({x + 0.5, y + 0.5});
        const sd::RayHit hit = scene.Intersect(origin, d.cast<float>());
        if (!hit.Hit() || hit.mesh != receiver) continue;
        Eigen::Vector3d n = scene.GeometricNormal(hit).cast<double>();
        if (n.squaredNorm() == 0) continue;
        if (n.dot(d) > 0) n = -n;
        sd::EnvShadingOptions o = options;
        o.skip_mesh = receiver;
        o.seed = options.seed * 0x9E3779B1u + static_cast<uint32_t>(y * c.width + x);
        out.at(x, y) = sd::ReceiverShadowRatio(scene, scene.HitPoint(hit).cast<double>(), n, light, o);
      }
  });
  return out;
}

struct Error {
  double se = 0, sum = 0;
  long n = 0;
  void Add(double d) { se += d * d, sum += d, ++n; }
  double Rmse() const { return n ? std::sqrt(se / n) : 0; }
  double Bias() const { return n ? sum / n : 0; }
};
struct Comparison {
  Error raw, seen, penumbra;
};

sd::ImageF Blurred(const sd::ImageF& shade) {
  sd::ImageF b = shade;
  sd::GaussianBlurRegion(&b, 1.5, 0, 0, b.width(), b.height());
  return b;
}

// Pixels where the reference's shade steps by more than 0.1 to a 4-neighbour, grown by one pixel.
sd::Image<uint8_t> Penumbra(const sd::ImageF& ref) {
  const int w = ref.width(), h = ref.height();
  sd::Image<uint8_t> step(w, h, 1, 0), out(w, h, 1, 0);
  for (int y = 0; y + 1 < h; ++y)
    for (int x = 0; x + 1 < w; ++x) {
      if (std::abs(ref.at(x, y) - ref.at(x + 1, y)) > 0.1f) step.at(x, y) = step.at(x + 1, y) = 1;
      if (std::abs(ref.at(x, y) - ref.at(x, y + 1)) > 0.1f) step.at(x, y) = step.at(x, y + 1) = 1;
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int yy = std::max(0, y - 1); yy <= std::min(h - 1, y + 1) && !out.at(x, y); ++yy)
        for (int xx = std::max(0, x - 1); xx <= std::min(w - 1, x + 1); ++xx)
          if (step.at(xx, yy)) out.at(x, y) = 1;
  return out;
}

void Compare(const sd::ImageF& v, const sd::ImageF& ref, const sd::ImageF& v_seen, const sd::ImageF& ref_seen,
             const sd::Image<uint8_t>& penumbra, Comparison* c) {
  for (int y = 0; y < ref.height(); ++y)
    for (int x = 0; x < ref.width(); ++x) {
      if (ref.at(x, y) >= 0.99f && v.at(x, y) >= 0.99f) continue;
      c->raw.Add(v.at(x, y) - ref.at(x, y));
      c->seen.Add(v_seen.at(x, y) - ref_seen.at(x, y));
      if (penumbra.at(x, y)) c->penumbra.Add(v.at(x, y) - ref.at(x, y));
    }
}

}  // namespace

int main(int argc, char** argv) {
  const bool crops = !(argc > 1 && std::strcmp(argv[1], "--no-crops") == 0);
  const std::optional<fs::path> found = sd::bench::RepoRootOrSay();
  if (!found) return 1;
  const fs::path root = *found;
  const sd::bench::DemoKeyframe keyframe(root, "road-shade");
  const std::vector<sd::Asset>& assets = keyframe.assets;
  const sd::Log& log = keyframe.log;
  const sd::Scenario& demo = keyframe.demo;
  const fs::path out_dir = root / "bench/results/road_shade";
  if (crops) fs::create_directories(out_dir);
  const sd::Frame& frame = log.frames.at(0);
  std::vector<sd::ImageU8> images;
  for (const sd::CameraSensor& cam : frame.cameras) images.push_back(sd::ReadImage(cam.image_path, 3));

  struct Case {
    const char* name;
    sd::Scenario scenario;
  };
  std::vector<Case> cases = {{"demo5", demo}, {"twenty", sd::bench::ScenarioWithObjects(demo, 12, 4, 4, 5, 45, 12)}};
  std::printf("| scene | camera | objects | shaded pixels (penumbra) |");
  for (const Variant& v : kVariants) std::printf(" %s: raw / seen / penumbra rmse |", v.name);
  for (const Variant& v : kVariants) std::printf(" %s s |", v.name);
  std::printf("\n|---|---|---|---|");
  for (size_t i = 0; i < 2 * kVariants.size(); ++i) std::printf("---|");
  std::printf("\n");
  std::vector<Comparison> total(kVariants.size());
  std::vector<double> total_s(kVariants.size(), 0.0);
  for (const Case& c : cases) {
    sd::SynthOptions options;
    options.report = false;
    const sd::FrameOutcome outcome = sd::SynthesizeFrame(log, 0, assets, c.scenario, options);
    std::vector<sd::PlacedObject> placed;
    for (const sd::ObjectOutcome& o : outcome.objects) placed.push_back(o.placement);
    if (placed.empty()) continue;
    sd::EnvironmentOptions eo;
    eo.ephemeris_sun_ego = outcome.sun_direction_ego;
    const sd::EnvironmentMap map = sd::BuildEnvironmentMap(frame, images, eo);
    const sd::EnvironmentLight light = sd::MakeEnvironmentLight(map);
    const sd::frame_stages::ObjectScene s = sd::frame_stages::BuildObjectScene(placed, light.sun_direction);
    sd::RayScene one_bvh;  // the same meshes, the same ids, one BVH
    for (int m = 0; m < s.scene.NumMeshes(); ++m) one_bvh.AddMesh(std::make_shared<sd::TriangleMesh>(s.scene.Mesh(m)));
    one_bvh.Commit();
    const auto shade = [&](const sd::CameraSensor& cam, const std::vector<std::array<int, 4>>& rects, const Variant& v) {
      sd::EnvShadingOptions o;
      o.sun_rays = v.sun_rays;
      o.sky_rays = v.sky_rays;
      o.seed = 7;
      if (!v.image) return PerPixel(s.scene, cam, s.receiver_id, light, o, rects);
      return sd::ReceiverShadowImage(v.one_bvh ? one_bvh : s.scene, cam.intrinsics, cam.T_ego_cam, s.receiver_id,
                                     std::vector<const sd::EnvironmentLight*>(s.receiver->faces.size(), &light), o, rects);
    };
    for (const sd::CameraSensor& cam : frame.cameras) {
      const sd::Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
      std::vector<std::array<int, 4>> rects;
      std::vector<int> rect_object;
      for (size_t k = 0; k < placed.size(); ++k)
        if (const auto r = sd::ProjectedRect(cam.intrinsics, T_cam_ego, s.extent_of[k], 2))
          rects.push_back(*r), rect_object.push_back(static_cast<int>(k));
      if (rects.empty()) continue;
      const sd::ImageF ref = shade(cam, rects, kReference);
      const sd::ImageF ref_seen = Blurred(ref);
      const sd::Image<uint8_t> penumbra = Penumbra(ref);
      std::vector<sd::ImageF> maps;
      std::vector<Comparison> cmp(kVariants.size());
      for (size_t i = 0; i < kVariants.size(); ++i) {
        maps.push_back(shade(cam, rects, kVariants[i]));
        Compare(maps[i], ref, Blurred(maps[i]), ref_seen, penumbra, &cmp[i]);
        Compare(maps[i], ref, Blurred(maps[i]), ref_seen, penumbra, &total[i]);
      }
      if (cmp[0].raw.n == 0) continue;
      std::vector<std::vector<double>> times(kVariants.size());
      for (int rep = 0; rep < 5; ++rep)
        for (size_t i = 0; i < kVariants.size(); ++i)
          times[i].push_back(sd::bench::Seconds([&] { shade(cam, rects, kVariants[i]); }));
      std::printf("| %s | %s | %zu | %ld (%ld) |", c.name, cam.channel.c_str(), rects.size(), cmp[0].raw.n, cmp[0].penumbra.n);
      for (const Comparison& e : cmp) std::printf(" %.4f / %.4f / %.4f |", e.raw.Rmse(), e.seen.Rmse(), e.penumbra.Rmse());
      for (size_t i = 0; i < kVariants.size(); ++i) {
        std::sort(times[i].begin(), times[i].end());
        total_s[i] += times[i][2];
        std::printf(" %.3f |", times[i][2]);
      }
      std::printf("\n");
      if (!crops) continue;
      const sd::ImageF per_pixel_seen = Blurred(maps[0]), image_seen = Blurred(maps[1]);
      for (size_t i = 0; i < rects.size(); ++i) {
        const auto& r = rects[i];
        if (r[2] - r[0] < 16 || r[3] - r[1] < 16) continue;
        const int zoom = std::clamp(600 / std::max(r[2] - r[0], r[3] - r[1]), 1, 4);
        const std::array<const sd::ImageF*, 3> maps_seen = {&ref_seen, &per_pixel_seen, &image_seen};  // grey
        const fs::path crop = out_dir / (std::string(c.name) + "_" + cam.channel + "_" + std::to_string(rect_object[i]) + ".png");
        sd::bench::WriteZoomedStrip(3, r, zoom, crop,
                                    [&](int panel, int x, int y, int) { return maps_seen[panel]->at(x, y); });
      }
    }
  }
  std::printf("| **all** | | | %ld (%ld) |", total[0].raw.n, total[0].penumbra.n);
  for (const Comparison& e : total)
    std::printf(" %.4f / %.4f / %.4f (bias %+.4f) |", e.raw.Rmse(), e.seen.Rmse(), e.penumbra.Rmse(), e.seen.Bias());
  for (double t : total_s) std::printf(" %.3f |", t);
  std::printf("\n");
  return 0;
}
