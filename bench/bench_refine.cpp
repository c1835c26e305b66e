// bench_refine: mesh refinement quality and speed on real meshes with ground truth.
//
// For each object (the scanned objects of ../shared/data/assets, category B, and a few road objects):
// normalise the ground truth into the unit sphere, render oracle normal maps and masks at the 6 Zero123++
// rig views (320x320), once clean and once degraded (blur + noise + small pose error, what a learned normal
// estimator and segmenter deliver), take the visual hull of the masks as the coarse mesh, refine, and compare
// coarse and refined meshes with the ground truth (geometry/metrics.h protocol). Prints a table per condition
// and writes everything to --json (default bench/results/refine.json) and an HTML page with the normal
// renders of GT / coarse / refined (--html, default bench/results/refine.html).
//
// Usage: bench_refine [--objects name,name] [--conditions clean,degraded] [--repeats N] [--steps N] [--iters N]
//                     [--device cpu|cuda]
//                     [--hull N] [--lambda-normal X] [--lambda-lap X] [--lambda-mask X] [--lr X] [--edge-min X] [--edge-max X]
// Seconds per object are the median of --repeats runs of the refinement (visual hull and metrics excluded),
// split into remesh / views / update as refine.h's RefineStepLog defines them (each the median over the runs,
// so the three need not add up to s/obj exactly).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/canonical.h"
#include "assetgen/refine.h"
#include "assetgen/views.h"
#include "core/device.h"
#include "core/error.h"
#include "core/log.h"
#include "geometry/metrics.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "raster/raster.h"
#include "io/mesh_io.h"

#include "bench_objects.h"

namespace {

namespace fs = std::filesystem;
using namespace sd;
using bench::BenchObject;
using bench::LoadGeometry;
using bench::Objects;

fs::path RepoRoot(const char* argv0) {
  if (const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR")) return env;
  return fs::weakly_canonical(fs::path(argv0)).parent_path().parent_path().parent_path();
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

nlohmann::json MetricsJson(const geometry::GeometryMetrics& m) {
  return {{"chamfer", m.chamfer}, {"fscore", m.fscore}, {"volume_iou", m.volume_iou}, {"normal_consistency", m.normal_consistency}};
}

std::string DataUri(const ImageU8& img) {
  static const char* kB64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  const std::string bytes = EncodeImage(img, "png");
  std::string out = "data:image/png;base64,";
  for (size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t v = static_cast<uint8_t>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<uint8_t>(bytes[i + 1]) << 8;
    if (i + 2 < bytes.size()) v |= static_cast<uint8_t>(bytes[i + 2]);
    out += kB64[(v >> 18) & 63];
    out += kB64[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kB64[(v >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kB64[v & 63] : '=';
  }
  return out;
}

// Normal renders of a mesh at two rig views, side by side (for the HTML page).
ImageU8 Thumbnail(const TriangleMesh& mesh, const std::vector<ViewCamera>& rig) {
  const std::vector<ViewCamera> two = {rig[0], rig[3]};
  const MultiViewSet v = RenderOracleViews(mesh, two, 1);
  const int w = v[0].normals.width(), h = v[0].normals.height();
  ImageU8 out(2 * w, h, 3);
  for (int i = 0; i < 2; ++i) {
    const ImageU8 p = NormalMapPreview(v[i]);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) out.at(i * w + x, y, c) = p.at(x, y, c);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> only, conditions = {"clean", "degraded"};
  int repeats = 1, hull_resolution = 96;
  RefineOptions options;
  options.show_progress = false;
  fs::path json_out, html_out;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_refine: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--objects") only = Split(next());
    else if (a == "--conditions") conditions = Split(next());
    else if (a == "--repeats") repeats = std::max(1, std::atoi(next().c_str()));
    else if (a == "--steps") options.steps = std::atoi(next().c_str());
    else if (a == "--iters") options.iterations_per_step = std::atoi(next().c_str());
    else if (a == "--lambda-lap") options.lambda_lap = std::stof(next());
    else if (a == "--lambda-mask") options.lambda_mask = std::stof(next());
    else if (a == "--lambda-normal") options.lambda_normal = std::stof(next());
    else if (a == "--lr") options.remesh.learning_rate = std::stof(next());
    else if (a == "--edge-min") options.remesh.edge_length_min = std::stof(next());
    else if (a == "--edge-max") options.remesh.edge_length_max = std::stof(next());
    else if (a == "--hull") hull_resolution = std::atoi(next().c_str());
    else if (a == "--json") json_out = next();
    else if (a == "--html") html_out = next();
    else if (a == "--device") SetDevice(ParseDevice(next()));
    else {
      std::fprintf(stderr, "bench_refine: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  const fs::path root = RepoRoot(argv[0]);
  const fs::path assets = root / ".." / "shared" / "data" / "assets";
  if (!fs::exists(assets)) {
    std::fprintf(stderr, "bench_refine: %s not found (the benchmark needs ../shared/data beside the repo)\n", assets.c_str());
    return 2;
  }
  if (json_out.empty()) json_out = root / "bench" / "results" / "refine.json";
  if (html_out.empty()) html_out = root / "bench" / "results" / "refine.html";

  const geometry::GeometryMetricsOptions metric_options;
  std::printf("device: %s%s\n", ToString(CurrentDevice()),
              CurrentDevice() == Device::kCuda ? (" (" + raster::CudaDeviceDescription() + ")").c_str() : "");
  std::printf("protocol: %s\n", geometry::DescribeProtocol(metric_options).c_str());
  std::printf("refine: %d steps x %d iterations, lambda normal %.2f mask %.2f lap %.2f, lr %.2f, edge %.3f..%.3f\n\n",
              options.steps, options.iterations_per_step, options.lambda_normal, options.lambda_mask, options.lambda_lap,
              options.remesh.learning_rate, options.remesh.edge_length_min, options.remesh.edge_length_max);

  const std::vector<ViewCamera> rig = Zero123PlusPlusRig(320);
  nlohmann::json results = nlohmann::json::array();
  std::string html = "<!doctype html><meta charset=utf-8><title>bench_refine</title><style>body{font-family:sans-serif}"
                     "td{padding:2px 8px;vertical-align:top}img{height:160px}</style><h1>Mesh refinement</h1>"
                     "<p>Normal renders (rig views 0 and 3): ground truth, visual hull (coarse), refined.</p><table>";
  for (const std::string& condition : conditions) {
    OracleDegradation degradation;
    if (condition == "degraded") {
      degradation.blur_sigma_px = 1.0f;
      degradation.normal_noise = 0.05f;
      degradation.pose_error_deg = 0.5f;
      degradation.pose_error_translation = 0.01f;  // unit-sphere units: 1% of the object's radius
    } else if (condition != "clean") {
      std::fprintf(stderr, "bench_refine: unknown condition %s (clean, degraded)\n", condition.c_str());
      return 2;
    }
    std::printf("== %s ==\n%-26s %9s %9s %7s %7s %7s %7s %7s %7s %8s %7s %7s %7s %7s\n", condition.c_str(), "object",
                "CD coarse", "CD refine", "F coar", "F ref", "IoU co", "IoU ref", "NC co", "NC ref", "faces", "s/obj",
                "remesh", "views", "update");
    std::vector<double> cd_c, cd_r, f_c, f_r, iou_c, iou_r, secs, remesh_secs, views_secs, update_secs;
    for (const BenchObject& obj : Objects()) {
      if (!only.empty() && std::find(only.begin(), only.end(), obj.name) == only.end()) continue;
      TriangleMesh gt = LoadGeometry(assets / obj.file, fs::temp_directory_path());
      gt.Transform(Rigid3d(AxesToCanonical(obj.up, obj.up == "+z" ? "+x" : "+z").cast<double>(), Eigen::Vector3d::Zero()));
      NormalizeIntoSphere(gt).Apply(&gt);
      gt.uvs.clear();
      gt.normals.clear();
      const MultiViewSet views = RenderOracleViews(gt, rig, 2, degradation);
      const TriangleMesh coarse = CoarseMeshFromViews(views, hull_resolution);
      RefineResult refined;
      // Seconds per run, and per run where they went (refine.h RefineStepLog), summed over the steps.
      std::vector<double> times, remesh_times, views_times, update_times;
      for (int r = 0; r < repeats; ++r) {
        refined = RefineMesh(coarse, views, options);
        times.push_back(refined.seconds);
        double remesh_s = 0, views_s = 0, update_s = 0;
        for (const RefineStepLog& s : refined.log) remesh_s += s.remesh_seconds, views_s += s.views_seconds, update_s += s.update_seconds;
        remesh_times.push_back(remesh_s);
        views_times.push_back(views_s);
        update_times.push_back(update_s);
      }
      const geometry::GeometryMetrics mc = geometry::CompareMeshes(coarse, gt, metric_options);
      const geometry::GeometryMetrics mr = geometry::CompareMeshes(refined.mesh, gt, metric_options);
      const double sec = Median(times);
      std::printf("%-26s %9.5f %9.5f %7.4f %7.4f %7.4f %7.4f %7.4f %7.4f %8zu %7.2f %7.2f %7.2f %7.2f\n", obj.name.c_str(),
                  mc.chamfer, mr.chamfer, mc.fscore, mr.fscore, mc.volume_iou, mr.volume_iou, mc.normal_consistency,
                  mr.normal_consistency, refined.mesh.NumFaces(), sec, Median(remesh_times), Median(views_times),
                  Median(update_times));
      std::fflush(stdout);
      cd_c.push_back(mc.chamfer);
      cd_r.push_back(mr.chamfer);
      f_c.push_back(mc.fscore);
      f_r.push_back(mr.fscore);
      iou_c.push_back(mc.volume_iou);
      iou_r.push_back(mr.volume_iou);
      secs.push_back(sec);
      remesh_secs.push_back(Median(remesh_times));
      views_secs.push_back(Median(views_times));
      update_secs.push_back(Median(update_times));
      nlohmann::json steps = nlohmann::json::array();
      for (const auto& s : refined.log)
        steps.push_back({{"normal", s.loss_normal}, {"mask", s.loss_mask}, {"lap", s.loss_lap}, {"faces", s.faces}});
      results.push_back({{"object", obj.name}, {"kind", obj.category}, {"condition", condition},
                         {"coarse", MetricsJson(mc)}, {"refined", MetricsJson(mr)}, {"coarse_faces", coarse.NumFaces()},
                         {"refined_faces", refined.mesh.NumFaces()}, {"seconds", times},
                         {"seconds_remesh", remesh_times}, {"seconds_views", views_times}, {"seconds_update", update_times},
                         {"steps", steps}});
      html += "<tr><td>" + obj.name + "<br>" + condition + "<br>CD " + std::to_string(mc.chamfer) + " &rarr; " +
              std::to_string(mr.chamfer) + "</td><td><img src='" + DataUri(Thumbnail(gt, rig)) + "'></td><td><img src='" +
              DataUri(Thumbnail(coarse, rig)) + "'></td><td><img src='" + DataUri(Thumbnail(refined.mesh, rig)) +
              "'></td></tr>\n";
    }
    auto mean = [](const std::vector<double>& v) {
      double s = 0;
      for (double x : v) s += x;
      return v.empty() ? 0.0 : s / v.size();
    };
    std::printf("%-26s %9.5f %9.5f %7.4f %7.4f %7.4f %7.4f %15s %8s %7.2f %7.2f %7.2f %7.2f\n", "MEAN", mean(cd_c),
                mean(cd_r), mean(f_c), mean(f_r), mean(iou_c), mean(iou_r), "", "", Median(secs), Median(remesh_secs),
                Median(views_secs), Median(update_secs));
    int better = 0;
    for (size_t i = 0; i < cd_c.size(); ++i) better += cd_r[i] < cd_c[i];
    std::printf("refined CD better than coarse on %d/%zu objects; mean CD reduced by %.1f%%; median %.2f s per object\n\n",
                better, cd_c.size(), 100.0 * (1.0 - mean(cd_r) / std::max(mean(cd_c), 1e-12)), Median(secs));
  }
  html += "</table>";
  WriteJsonFile(json_out, {{"protocol", geometry::DescribeProtocol(metric_options)},
                           {"options", {{"steps", options.steps}, {"iterations", options.iterations_per_step},
                                        {"lambda_mask", options.lambda_mask}, {"lambda_lap", options.lambda_lap}}},
                           {"results", results}});
  WriteFileAtomic(html_out, html);
  std::printf("wrote %s and %s\n", json_out.c_str(), html_out.c_str());
  return 0;
}
