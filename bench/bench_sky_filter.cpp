// The objects' sky denoised (CameraRenderOptions::sky_filter_radius, the synth default) against the sky traced
// alone, on the real keyframe: the demo's objects (5) and 20 of them placed by SynthesizeFrame, rendered in every
// camera they touch with the frame's own object scene (receiver patches included, as blockers).
//
// Quality, at 1 sub-sample per pixel, where the primary rays do not depend on the sky's ray count (a pixel's
// jitter is drawn before its sky rays), so the difference is the sky's alone: the error of
//   plain:    64 sky rays per pixel, unfiltered (what the old default traced per pixel: 4 sub-samples x 16),
//   filtered: 16 sky rays per pixel, radius 3 (what the new default traces per pixel),
// against 1024 unfiltered rays, over pixels fully covered in both, and over those within 2 pixels of another
// mesh (edges, creases, contact), where a filter that blurs would show. Error in luminance, relative to the mean.
// Time, at the default 4 sub-samples: RenderCamera with 16 rays per sub-sample unfiltered against 4 per
// sub-sample filtered (median of 5, interleaved). Crops: bench/results/sky_filter/<scene>_<camera>_<object>.png,
// each a strip of the converged (4 sub-samples x 256 rays), plain and filtered renders, enlarged up to 4x.
//
// Usage: bench_sky_filter [--no-crops]. Repo root: $SYNTHDRIVE_SOURCE_DIR, else build/bin/../../.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "assetgen/asset.h"
#include "core/image.h"
#include "datasets/readers.h"
#include "io/image_io.h"
#include "render/camera_render.h"
#include "synth/frame.h"
#include "synth/frame_stages.h"
#include "synth/scenario.h"

#include "bench_demo.h"

namespace {
namespace fs = std::filesystem;

float Luma(const sd::ImageF& c, int x, int y) {
  return 0.2126f * c.at(x, y, 0) + 0.7152f * c.at(x, y, 1) + 0.0722f * c.at(x, y, 2);
}

bool NearAnotherMesh(const sd::CameraRender& r, int x, int y) {
  const int id = r.object.at(x, y);
  for (int yy = std::max(0, y - 2); yy <= std::min(r.object.height() - 1, y + 2); ++yy)
    for (int xx = std::max(0, x - 2); xx <= std::min(r.object.width() - 1, x + 2); ++xx)
      if (r.object.at(xx, yy) != id) return true;
  return false;
}

struct Error {
  double se = 0, sum = 0, value = 0;
  long n = 0;
  void Add(double d, double v) { se += d * d, sum += d, value += v, ++n; }
  double Rmse() const { return n ? std::sqrt(se / n) : 0; }
  double Bias() const { return n ? sum / n : 0; }
  double Mean() const { return n ? value / n : 0; }
};

struct Comparison {
  Error all, edges;
};
void Compare(const sd::CameraRender& r, const sd::CameraRender& ref, Comparison* c) {
  for (int y = 0; y < ref.color.height(); ++y)
    for (int x = 0; x < ref.color.width(); ++x) {
      if (ref.coverage.at(x, y) < 1 || r.coverage.at(x, y) < 1) continue;
      const double v = Luma(ref.color, x, y), d = Luma(r.color, x, y) - v;
      c->all.Add(d, v);
      if (NearAnotherMesh(ref, x, y)) c->edges.Add(d, v);
    }
}

sd::CameraRender Render(const sd::frame_stages::ObjectScene& s, const sd::CameraSensor& cam, const sd::Lighting& light,
                        const std::vector<std::array<int, 4>>& rects, int spp, int ao, int radius) {
  sd::CameraRenderOptions o;
  o.samples_per_pixel = spp;
  o.ao_samples = ao;
  o.sky_filter_radius = radius;
  o.receiver_mesh = s.receiver_id;
  o.receiver_shadow = false;  // as under the map's light: the road's shade is another stage's
  o.rects = rects;
  return sd::RenderCamera(s.scene, cam.intrinsics, cam.T_ego_cam, light, o);
}

}  // namespace

int main(int argc, char** argv) {
  const bool crops = !(argc > 1 && std::strcmp(argv[1], "--no-crops") == 0);
  const std::optional<fs::path> found = sd::bench::RepoRootOrSay();
  if (!found) return 1;
  const fs::path root = *found;
  const sd::bench::DemoKeyframe keyframe(root, "sky-filter");
  const std::vector<sd::Asset>& assets = keyframe.assets;
  const sd::Log& log = keyframe.log;
  const sd::Scenario& demo = keyframe.demo;
  const fs::path out_dir = root / "bench/results/sky_filter";
  if (crops) fs::create_directories(out_dir);

  sd::Lighting light;  // a sun 40 degrees up, behind the ego's left; the default sun / sky levels
  light.sun_direction = Eigen::Vector3f(-0.6f, 0.45f, 0.84f).normalized();

  struct Case {
    const char* name;
    sd::Scenario scenario;
  };
  std::vector<Case> cases = {{"demo5", demo}, {"twenty", sd::bench::ScenarioWithObjects(demo, 12, 4, 4, 5, 45, 12)}};
  std::printf("| scene | camera | objects | pixels (edges) | plain 64 rays: rmse / bias (edges) | filtered 16 rays: rmse / bias (edges) | render s: 4x16 plain / 4x4 filtered |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  Comparison total_plain, total_filtered;
  double t_plain_total = 0, t_filtered_total = 0;
  for (const Case& c : cases) {
    sd::SynthOptions options;
    options.report = false;
    const sd::FrameOutcome outcome = sd::SynthesizeFrame(log, 0, assets, c.scenario, options);
    std::vector<sd::PlacedObject> placed;
    for (const sd::ObjectOutcome& o : outcome.objects) placed.push_back(o.placement);
    if (placed.empty()) continue;
    const sd::frame_stages::ObjectScene s =
        sd::frame_stages::BuildObjectScene(placed, light.sun_direction.cast<double>());
    const sd::Frame& frame = log.frames.at(0);
    for (const sd::CameraSensor& cam : frame.cameras) {
      const sd::Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
      std::vector<std::array<int, 4>> rects;
      std::vector<int> rect_object;
      for (size_t k = 0; k < placed.size(); ++k) {
        const auto corners = placed[k].box.Corners();
        const auto r = sd::ProjectedRect(cam.intrinsics, T_cam_ego, {corners.begin(), corners.end()}, 2);
        if (r) rects.push_back(*r), rect_object.push_back(static_cast<int>(k));
      }
      if (rects.empty()) continue;
      const sd::CameraRender ref1 = Render(s, cam, light, rects, 1, 1024, 0);
      const sd::CameraRender plain1 = Render(s, cam, light, rects, 1, 64, 0);
      const sd::CameraRender filtered1 = Render(s, cam, light, rects, 1, 16, 3);
      Comparison cp, cf;
      Compare(plain1, ref1, &cp);
      Compare(filtered1, ref1, &cf);
      if (cp.all.n == 0) continue;
      Compare(plain1, ref1, &total_plain);
      Compare(filtered1, ref1, &total_filtered);
      std::vector<double> tp, tf;
      for (int rep = 0; rep < 5; ++rep) {
        tp.push_back(sd::bench::Seconds([&] { Render(s, cam, light, rects, 4, 16, 0); }));
        tf.push_back(sd::bench::Seconds([&] { Render(s, cam, light, rects, 4, 4, 3); }));
      }
      std::sort(tp.begin(), tp.end());
      std::sort(tf.begin(), tf.end());
      t_plain_total += tp[2], t_filtered_total += tf[2];
      const double mean = cp.all.Mean();
      std::printf("| %s | %s | %zu | %ld (%ld) | %.4f / %+.4f (%.4f / %+.4f) | %.4f / %+.4f (%.4f / %+.4f) | %.3f / %.3f |\n",
                  c.name, cam.channel.c_str(), rects.size(), cp.all.n, cp.edges.n, cp.all.Rmse() / mean,
                  cp.all.Bias() / mean, cp.edges.Rmse() / mean, cp.edges.Bias() / mean, cf.all.Rmse() / mean,
                  cf.all.Bias() / mean, cf.edges.Rmse() / mean, cf.edges.Bias() / mean, tp[2], tf[2]);
      if (!crops) continue;
      const sd::CameraRender ref4 = Render(s, cam, light, rects, 4, 256, 0);
      const sd::CameraRender plain4 = Render(s, cam, light, rects, 4, 16, 0);
      const sd::CameraRender filtered4 = Render(s, cam, light, rects, 4, 4, 3);
      for (size_t i = 0; i < rects.size(); ++i) {
        const auto& r = rects[i];
        if (r[2] - r[0] < 16 || r[3] - r[1] < 16) continue;
        const int zoom = std::clamp(600 / std::max(r[2] - r[0], r[3] - r[1]), 1, 4);
        // Each render over mid grey.
        const std::array<const sd::CameraRender*, 3> renders = {&ref4, &plain4, &filtered4};
        const fs::path crop = out_dir / (std::string(c.name) + "_" + cam.channel + "_" + std::to_string(rect_object[i]) + ".png");
        sd::bench::WriteZoomedStrip(3, r, zoom, crop,
                                    [&](int panel, int x, int y, int ch) {
                                      return renders[panel]->color.at(x, y, ch) + (1 - renders[panel]->coverage.at(x, y)) * 0.18f;
                                    });
      }
    }
  }
  const double mean = total_plain.all.Mean();
  std::printf("| **all** | | | %ld (%ld) | %.4f / %+.4f (%.4f / %+.4f) | %.4f / %+.4f (%.4f / %+.4f) | %.3f / %.3f |\n",
              total_plain.all.n, total_plain.edges.n, total_plain.all.Rmse() / mean, total_plain.all.Bias() / mean,
              total_plain.edges.Rmse() / mean, total_plain.edges.Bias() / mean, total_filtered.all.Rmse() / mean,
              total_filtered.all.Bias() / mean, total_filtered.edges.Rmse() / mean, total_filtered.edges.Bias() / mean,
              t_plain_total, t_filtered_total);
  return 0;
}
