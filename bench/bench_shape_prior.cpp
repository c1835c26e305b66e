// bench_shape_prior: one photo → one asset with no learned model (assetgen/shape_prior.h), against ground truth.
//
// For each benchmark object (bench_objects.h, plus the milk truck): the ground truth is put upright (+z), turned
// so its longer horizontal side is +x (a vehicle's length: the mirror prior's symmetry plane is then y = 0),
// resting on z = 0 and centred, in its own units. One "photo" is rendered as a driving camera sees such an object:
// 640x480, 50° vertical field of view, elevation 10°, azimuth 30° from its front, at the distance where it is
// 120 px tall, unlit base colour on a grey road. ShapeFromPhoto gets the photo, its exact mask and the object's
// box size (what a log's label or --size gives); the intrinsics are known (a log's camera). Each object runs with
// its class's prior and with the single-view hull inside the same box (the baseline), both through the same
// back end (GenerateFromPhotoShape: mask-only refinement, x2 SR, UV texture, canonical frame). The ground truth
// is mapped into each asset's frame with the asset's own transform; figures: Chamfer / F-score / volume IoU
// (geometry/metrics.h) and PSNR / SSIM at the 8 held-out views of texture_eval.h (textured objects only), and the
// seconds from photo to asset.
//
// Real photos (skipped with --no-photos or when absent): every cone of the Road Anomaly photos in
// ../shared/data/images/roadanomaly-cones whose ground-truth instance (labels_instance.png) is one cone touching
// no other and at least 1500 px, as `generate --image` runs on it with no model: intrinsics assumed (50°
// vertical), traffic_cone's size, the prior chosen by category and symmetry, the elevation from the base. Once
// with the ground-truth mask and once with GrabCut inside the instance's box grown 10 % (no mask given). There is
// no 3D truth: the figures are the photo silhouette IoU (the asset redrawn at the photo's camera against the
// ground-truth mask), the masked PSNR there, the symmetry and elevation found, and seconds; a turntable strip per
// cone (the photo's crop, then 8 unlit views) goes to bench/results/shape_prior_photos/.
//
// Usage: bench_shape_prior [--objects a,b] [--steps N] [--height-px H] [--elevation DEG] [--no-photos]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/canonical.h"
#include "assetgen/preview.h"
#include "assetgen/generate.h"
#include "assetgen/shape_prior.h"
#include "assetgen/texture_eval.h"
#include "assetgen/views.h"
#include "core/error.h"
#include "core/log.h"
#include "geometry/metrics.h"
#include "io/json.h"
#include "io/image_io.h"
#include "io/mesh_io.h"
#include "models/segmentation.h"

#include "bench_objects.h"

namespace {

namespace fs = std::filesystem;
using namespace sd;

// The class each benchmark object belongs to for this benchmark: what its shape is, not where it came from.
std::string CategoryOf(const std::string& name) {
  static const std::map<std::string, std::string> kCategory = {
      {"metadrive_traffic_cone", "traffic_cone"}, {"quaternius_traffic_cone", "traffic_cone"},
      {"hope_alphabet_soup", "barrel"},           {"hope_bbq_sauce", "bottle"},
      {"hope_orange_juice", "crate"},             {"hope_new_salad_dressing", "bottle"},
      {"hope_butter", "crate"},                   {"hope_cream_cheese", "crate"},
      {"hope_macaroni_and_cheese", "crate"},      {"hope_chocolate_pudding", "crate"},
      {"metadrive_road_barrier", "barrier"},      {"torcs_p406", "car"},
      {"cesium_milk_truck", "truck"},             {"torcs_155_dtm", "car"}};
  const auto it = kCategory.find(name);
  return it == kCategory.end() ? "debris" : it->second;
}

// The crop of `image` the photo's view shows: PhotoShape's view camera is the full camera shifted by the crop.
ImageF CropLike(const ImageF& full, const PhotoShape& shape) {
  const PinholeCamera& c = shape.views.front().view.camera;
  const int x0 = static_cast<int>(std::lround(shape.camera.cx - c.cx)), y0 = static_cast<int>(std::lround(shape.camera.cy - c.cy));
  ImageF out(c.width, c.height, full.channels(), 0.0f);
  for (int y = 0; y < c.height; ++y)
    for (int x = 0; x < c.width; ++x)
      for (int k = 0; k < full.channels(); ++k) out.at(x, y, k) = full.at(x + x0, y + y0, k);
  return out;
}

int RunPhotos(const fs::path& frames, const fs::path& out_dir, int steps) {
  if (!fs::exists(frames)) {
    std::printf("\nreal photos: %s not found, skipped\n", frames.c_str());
    return 0;
  }
  fs::create_directories(out_dir);
  std::printf("\nreal photos (%s): intrinsics assumed 50 deg, traffic_cone size, no model\n", frames.c_str());
  std::printf("%-38s %4s %6s | %-7s %5s %6s %6s %6s | %6s %6s %6s\n", "photo", "id", "px", "prior", "sym", "elev",
              "IoU", "PSNR", "GC IoU", "GC sil", "s");
  std::vector<fs::path> photos;
  for (const auto& e : fs::directory_iterator(frames))
    if (e.path().extension() == ".jpg") photos.push_back(e.path());
  std::sort(photos.begin(), photos.end());
  const models::Segmenter grabcut = models::Segmenter::Classical();
  std::vector<double> ious, gc_ious, psnrs, secs;
  for (const fs::path& photo_file : photos) {
    const fs::path labels = frames / (photo_file.stem().string() + ".labels") / "labels_instance.png";
    if (!fs::exists(labels)) continue;
    const ImageU8 image = ReadImage(photo_file, 3);
    const ImageU8 inst = ReadImage(labels, 1);
    std::map<int, int> count;
    for (uint8_t v : inst.vector()) if (v) ++count[v];
    for (const auto& [id, pixels] : count) {
      if (pixels < 1500) continue;
      ImageF mask(inst.width(), inst.height(), 1, 0.0f);
      bool touching = false;
      int x0 = inst.width(), y0 = inst.height(), x1 = 0, y1 = 0;
      for (int y = 0; y < inst.height(); ++y)
        for (int x = 0; x < inst.width(); ++x) {
          if (inst.at(x, y) != id) continue;
          mask.at(x, y) = 1.0f;
          x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x + 1), y1 = std::max(y1, y + 1);
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int u = x + dx, v = y + dy;
              if (u >= 0 && v >= 0 && u < inst.width() && v < inst.height() && inst.at(u, v) && inst.at(u, v) != id)
                touching = true;
            }
        }
      if (touching) continue;
      PhotoObservation photo;
      photo.image = image;
      photo.mask = mask;
      ShapePriorOptions prior_options;
      prior_options.category = "traffic_cone";
      prior_options.size = Eigen::Vector3d(0.41, 0.41, 1.07);
      GenerateOptions options;
      options.refine.steps = steps;
      options.refine.show_progress = false;
      options.upscale = "bicubic";
      options.canonical.target_size = prior_options.size;
      const std::string name = photo_file.stem().string().substr(0, 38);
      try {
        const auto start = std::chrono::steady_clock::now();
        const PhotoShape shape = ShapeFromPhoto(photo, prior_options);
        const GeneratedMesh g = GenerateFromPhotoShape(shape, options);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const auto [iou, psnr] = AgreementAtView(g, shape.views.front(), shape.views.front().mask);
        // The no-mask path: GrabCut in the box grown 10 %, then the same; scored against the truth.
        const double gx = 0.1 * (x1 - x0), gy = 0.1 * (y1 - y0);
        const Box2 box{std::max(0.0, x0 - gx), std::max(0.0, y0 - gy), std::min<double>(image.width(), x1 + gx),
                       std::min<double>(image.height(), y1 + gy)};
        double gc_iou = 0, gc_sil = 0;
        try {
          PhotoObservation gc = photo;
          gc.mask = grabcut.Segment(image, box).mask;
          const PhotoShape gshape = ShapeFromPhoto(gc, prior_options);
          const GeneratedMesh gg = GenerateFromPhotoShape(gshape, options);
          gc_iou = AgreementAtView(gg, gshape.views.front(), CropLike(mask, gshape)).silhouette_iou;
          gc_sil = AgreementAtView(gg, gshape.views.front(), gshape.views.front().mask).silhouette_iou;
        } catch (const InputError&) {
        }
        std::printf("%-38s %4d %6d | %-7s %5.3f %6.1f %6.3f %6.2f | %6.3f %6.3f %6.2f\n", name.c_str(), id, pixels,
                    ToString(shape.prior), shape.symmetry_iou, shape.elevation_deg, iou, psnr, gc_iou, gc_sil, seconds);
        std::fflush(stdout);
        ious.push_back(iou), gc_ious.push_back(gc_iou), psnrs.push_back(psnr), secs.push_back(seconds);
        // Turntable strip: the photo's crop (scaled to the strip's height), then the asset's 8 views.
        const int size = 160;
        const ImageU8 turn = RenderTurntable(g.mesh, 8, size);
        const ImageU8 crop = ToSrgb8(shape.views.front().color);
        ImageU8 strip(turn.width() + size, size, 3, 217);
        const double scale = std::min(double(size) / crop.width(), double(size) / crop.height());
        for (int y = 0; y < size; ++y)
          for (int x = 0; x < size; ++x) {
            const int sx = static_cast<int>((x - 0.5 * (size - scale * crop.width())) / scale);
            const int sy = static_cast<int>((y - 0.5 * (size - scale * crop.height())) / scale);
            if (sx >= 0 && sy >= 0 && sx < crop.width() && sy < crop.height())
              for (int c = 0; c < 3; ++c) strip.at(x, y, c) = crop.at(sx, sy, c);
          }
        for (int y = 0; y < size; ++y)
          for (int x = 0; x < turn.width(); ++x)
            for (int c = 0; c < 3; ++c) strip.at(size + x, y, c) = turn.at(x, y, c);
        WriteImage(out_dir / (photo_file.stem().string() + "_" + std::to_string(id) + ".png"), strip);
      } catch (const InputError& e) {
        std::printf("%-38s %4d %6d | refused: %s\n", name.c_str(), id, pixels, e.what());
      }
    }
  }
  auto median = [](std::vector<double> v) -> double {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
  };
  std::printf("median over %zu cones: photo IoU %.3f, PSNR %.2f dB, GrabCut-path IoU %.3f, %.2f s\n", ious.size(),
              median(ious), median(psnrs), median(gc_ious), median(secs));
  std::printf("turntables: %s\n", out_dir.c_str());
  return 0;
}

struct Row {
  std::string prior;
  geometry::GeometryMetrics geo;
  TextureMetrics tex;
  double seconds = 0;
  std::string note;
};

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> only;
  int steps = RefineOptions{}.steps;
  double height_px = 120, elevation = 10, azimuth = 30;
  bool photos = true, only_photos = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_shape_prior: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--objects") {
      std::stringstream ss(next());
      for (std::string item; std::getline(ss, item, ',');) only.push_back(item);
    } else if (a == "--steps") {
      steps = std::max(0, std::atoi(next().c_str()));
    } else if (a == "--height-px") {
      height_px = std::atof(next().c_str());
    } else if (a == "--elevation") {
      elevation = std::atof(next().c_str());
    } else if (a == "--only-photos") {
      only_photos = true;
    } else if (a == "--no-photos") {
      photos = false;
    } else {
      std::fprintf(stderr, "bench_shape_prior: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR");
  const fs::path root = env ? fs::path(env) : fs::weakly_canonical(fs::path(argv[0])).parent_path().parent_path().parent_path();
  const fs::path assets = root / ".." / "shared" / "data" / "assets";
  if (!fs::exists(assets)) {
    std::fprintf(stderr, "bench_shape_prior: %s not found (the benchmark needs ../shared/data beside the repo)\n",
                 assets.c_str());
    return 2;
  }
  SetLogLevel(LogLevel::kWarn);
  std::vector<bench::BenchObject> objects = bench::Objects();
  objects.push_back({"cesium_milk_truck", "road", "truck/cesium_milk_truck/obj/cesium_milk_truck.obj", "+y"});
  objects.push_back({"torcs_155_dtm", "road", "car/torcs_155_dtm/obj/torcs_155_dtm.obj", "+y"});

  const geometry::GeometryMetricsOptions metric_options;
  std::printf("geometry protocol: %s\ntexture protocol: %s\n", geometry::DescribeProtocol(metric_options).c_str(),
              DescribeTextureProtocol().c_str());
  std::printf("photo: 640x480, 50 deg vertical fov (known), elevation %.0f deg, azimuth %.0f deg, object %.0f px "
              "tall; refinement %d steps (mask terms)\n\n",
              elevation, azimuth, height_px, steps);
  std::printf("%-26s %-12s %-8s %8s %6s %6s %7s %6s %7s  %s\n", "object", "category", "prior", "CD", "F", "IoU",
              "PSNR", "SSIM", "s", "note");
  nlohmann::json results = nlohmann::json::array();
  for (const bench::BenchObject& obj : objects) {
    if (only_photos) break;
    if (!only.empty() && std::find(only.begin(), only.end(), obj.name) == only.end()) continue;
    TriangleMesh gt;
    bool textured = true;
    try {
      gt = LoadMesh(assets / obj.file);
    } catch (const InputError&) {
      gt = bench::LoadGeometry(assets / obj.file, fs::temp_directory_path());
      textured = false;
    }
    textured = textured && !gt.uvs.empty() &&
               std::any_of(gt.materials.begin(), gt.materials.end(),
                           [](const Material& m) { return m.base_color_texture != nullptr; });
    gt.Transform(Rigid3d(AxesToCanonical(obj.up, obj.up == "+z" ? "+x" : "+z"), Eigen::Vector3d::Zero()));
    {
      const Eigen::Vector3f s = gt.Bounds().Size();
      if (s.y() > s.x()) gt.Transform(Rigid3d::FromYaw(3.14159265358979323846 / 2, Eigen::Vector3d::Zero()));
      const AlignedBox3f b = gt.Bounds();
      const Eigen::Vector3f shift(-b.Center().x(), -b.Center().y(), -b.min.z());
      for (auto& p : gt.positions) p += shift;
    }
    const Eigen::Vector3d size = gt.Bounds().Size().cast<double>();
    const std::string category = CategoryOf(obj.name);

    // The photo: the camera aimed at the box centre, rendered with the object moved down by half its height
    // (OrbitCamera looks at the origin).
    TriangleMesh centred = gt;
    for (auto& p : centred.positions) p.z() -= float(size.z() / 2);
    const double fy = 240.0 / std::tan(25.0 * 3.14159265358979323846 / 180);
    const ViewCamera cam = OrbitCamera("photo", azimuth, elevation, fy * size.z() / height_px, 50, 640, 480);
    const AlbedoRender shot = RenderAlbedo(centred, cam, 3);
    PhotoObservation photo;
    ImageF color = shot.color;
    for (int y = 0; y < color.height(); ++y)
      for (int x = 0; x < color.width(); ++x) {
        const float m = shot.mask.at(x, y);
        for (int c = 0; c < 3; ++c) color.at(x, y, c) = m * color.at(x, y, c) + (1 - m) * 0.05f;
      }
    photo.image = ToSrgb8(color);
    photo.mask = shot.mask;
    photo.camera = cam.camera;

    ShapePriorOptions prior_options;
    prior_options.category = category;
    prior_options.size = size;
    std::vector<std::optional<ShapePrior>> runs = {std::nullopt, ShapePrior::kHull};
    if (DefaultShapePrior(category) == ShapePrior::kHull) runs.pop_back();
    for (const std::optional<ShapePrior>& forced : runs) {
      Row row;
      prior_options.prior = forced;
      const auto start = std::chrono::steady_clock::now();
      try {
        const PhotoShape shape = ShapeFromPhoto(photo, prior_options);
        row.prior = ToString(shape.prior);
        if (!forced && shape.prior != DefaultShapePrior(category)) row.note = shape.prior_reason;
        if (shape.elevation_method != "given")
          row.note += (row.note.empty() ? "" : "; ") + (Msg() << "elevation " << shape.elevation_deg << " ("
                                                              << shape.elevation_method << ")").str();
        GenerateOptions options;
        options.refine.steps = steps;
        options.refine.show_progress = false;
        options.upscale = "bicubic";
        options.canonical.target_size = size;
        const GeneratedMesh g = GenerateFromPhotoShape(shape, options);
        row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const TriangleMesh gt_asset = g.ToAssetFrame(gt);
        row.geo = geometry::CompareMeshes(g.mesh, gt_asset, metric_options);
        if (textured) row.tex = CompareTextures(g.mesh, gt_asset);
      } catch (const InputError& e) {
        std::printf("%-26s %-12s %-8s failed: %s\n", obj.name.c_str(), category.c_str(),
                    forced ? ToString(*forced) : "auto", e.what());
        continue;
      }
      std::printf("%-26s %-12s %-8s %8.5f %6.4f %6.4f %7s %6s %7.2f  %s\n", obj.name.c_str(), category.c_str(),
                  row.prior.c_str(), row.geo.chamfer, row.geo.fscore, row.geo.volume_iou,
                  textured ? (Msg() << row.tex.psnr).str().substr(0, 6).c_str() : "-",
                  textured ? (Msg() << row.tex.ssim).str().substr(0, 6).c_str() : "-", row.seconds, row.note.c_str());
      std::fflush(stdout);
      nlohmann::json j = {{"object", obj.name},          {"category", category},          {"prior", row.prior},
                          {"baseline", forced.has_value()}, {"chamfer", row.geo.chamfer}, {"fscore", row.geo.fscore},
                          {"volume_iou", row.geo.volume_iou}, {"seconds", row.seconds},     {"note", row.note},
                          {"textured", textured}};
      if (textured) j["psnr"] = row.tex.psnr, j["ssim"] = row.tex.ssim;
      results.push_back(j);
    }
  }
  // Per prior: medians of the class run against its hull baseline on the same objects.
  std::printf("\n%-8s %4s %10s %10s %10s %10s %8s\n", "prior", "n", "CD median", "hull CD", "IoU median", "hull IoU",
              "PSNR med");
  for (const std::string prior : {"revolve", "mirror", "extrude", "hull"}) {
    std::vector<double> cd, cd_base, iou, iou_base, psnr;
    for (size_t i = 0; i < results.size(); ++i) {
      const nlohmann::json& r = results[i];
      if (r["baseline"].get<bool>() || r["prior"] != prior) continue;
      cd.push_back(r["chamfer"]), iou.push_back(r["volume_iou"]);
      if (r.contains("psnr")) psnr.push_back(r["psnr"]);
      if (i + 1 < results.size() && results[i + 1]["object"] == r["object"] && results[i + 1]["baseline"].get<bool>())
        cd_base.push_back(results[i + 1]["chamfer"]), iou_base.push_back(results[i + 1]["volume_iou"]);
    }
    if (cd.empty()) continue;
    auto median = [](std::vector<double> v) -> double {
      if (v.empty()) return 0;
      std::sort(v.begin(), v.end());
      return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
    };
    std::printf("%-8s %4zu %10.5f %10.5f %10.4f %10.4f %8.2f\n", prior.c_str(), cd.size(), median(cd), median(cd_base),
                median(iou), median(iou_base), median(psnr));
  }
  const fs::path json_out = root / "bench" / "results" / "shape_prior.json";
  WriteJsonFile(json_out, {{"geometry_protocol", geometry::DescribeProtocol(metric_options)},
                           {"texture_protocol", DescribeTextureProtocol()},
                           {"photo", {{"width", 640}, {"height", 480}, {"vertical_fov_deg", 50},
                                      {"elevation_deg", elevation}, {"azimuth_deg", azimuth},
                                      {"object_height_px", height_px}}},
                           {"refine_steps", steps},
                           {"results", results}});
  std::printf("\nwrote %s\n", json_out.c_str());
  if (photos || only_photos)
    RunPhotos(root / ".." / "shared" / "data" / "images" / "roadanomaly-cones" / "frames",
              root / "bench" / "results" / "shape_prior_photos", steps);
  return 0;
}
