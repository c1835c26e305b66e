#include "synth/realism.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "geometry/box_projection.h"
#include "geometry/polygon.h"
#include "io/geometry_json.h"
#include "io/image_io.h"
#include "io/json.h"
#include "synth/real_shadows.h"

namespace sd {
namespace {

constexpr double kNearM = 0.5;
// Real objects worth measuring: a projected box of at least 24 x 12 pixels.
constexpr int kMinRealPixels = 24 * 12;

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

double Saturation(const uint8_t* p) { return HsvSaturation(p[0], p[1], p[2]); }

// Calls fn(x, y) for every pixel of `camera`'s image whose centre lies inside `box_ego`'s projected outline;
// nothing when the outline's rectangle inside the image covers less than `min_area` pixels.
template <typename Fn>
void ForEachOutlinePixel(const CameraSensor& camera, const Box3& box_ego, Fn fn, double min_area = 0) {
  const auto in_image = geometry::ProjectBoxToImage(camera.intrinsics, camera.T_ego_cam.Inverse(), box_ego, kNearM);
  if (!in_image || in_image->clipped.Empty() || in_image->clipped.Area() < min_area) return;
  const Box2& r = in_image->clipped;
  const int x0 = std::max(0, static_cast<int>(std::floor(r.x1))), y0 = std::max(0, static_cast<int>(std::floor(r.y1)));
  const int x1 = std::min(camera.intrinsics.width, static_cast<int>(std::ceil(r.x2)));
  const int y1 = std::min(camera.intrinsics.height, static_cast<int>(std::ceil(r.y2)));
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x)
      if (geometry::InsideConvexPolygon(in_image->outline, {x + 0.5, y + 0.5})) fn(x, y);
}

}  // namespace

int OutlinePixels(const CameraSensor& camera, const Box3& box_ego) {
  int count = 0;
  ForEachOutlinePixel(camera, box_ego, [&](int, int) { ++count; });
  return count;
}

double MeasureSaturation(const ImageU8& image, const CameraSensor& camera, const Box3& box_ego, int* pixels) {
  if (pixels) *pixels = 0;
  if (image.width() != camera.intrinsics.width || image.height() != camera.intrinsics.height) return 0;  // not its image
  std::vector<double> saturation;
  ForEachOutlinePixel(camera, box_ego, [&](int x, int y) { saturation.push_back(Saturation(image.pixel(x, y))); });
  if (pixels) *pixels = static_cast<int>(saturation.size());
  return OutlineSaturation(std::move(saturation));
}

ObjectLook MeasureObjectLook(const ImageU8& image, const CameraSensor& camera, const Box3& box_ego, const CameraLook& look) {
  ObjectLook out;
  const auto in_image = geometry::ProjectBoxToImage(camera.intrinsics, camera.T_ego_cam.Inverse(), box_ego, kNearM);
  if (!in_image || in_image->clipped.Empty()) return out;
  const Box2& r = in_image->clipped;
  const int x0 = static_cast<int>(std::floor(r.x1)), y0 = static_cast<int>(std::floor(r.y1));
  const int x1 = std::min(image.width(), static_cast<int>(std::ceil(r.x2)));
  const int y1 = std::min(image.height(), static_cast<int>(std::ceil(r.y2)));
  if (image.width() != camera.intrinsics.width || image.height() != camera.intrinsics.height) return out;  // not its image
  ImageF mask(image.width(), image.height(), 1, 0.0f);
  std::vector<double> saturation;
  ForEachOutlinePixel(camera, box_ego, [&](int x, int y) {
    mask.at(x, y) = 1;
    saturation.push_back(Saturation(image.pixel(x, y)));
  });
  out.pixels = static_cast<int>(saturation.size());
  if (out.pixels == 0) return out;
  out.saturation = OutlineSaturation(std::move(saturation));

  std::vector<double> ratios;
  for (int by = y0 / 8; by * 8 + 8 <= y1; ++by)
    for (int bx = x0 / 8; bx * 8 + 8 <= x1; ++bx) {
      bool inside = true;
      double mean = 0;
      for (int y = 0; y < 8 && inside; ++y)
        for (int x = 0; x < 8; ++x) {
          if (mask.at(bx * 8 + x, by * 8 + y) <= 0) {
            inside = false;
            break;
          }
          mean += image.at(bx * 8 + x, by * 8 + y, 1);
        }
      if (!inside) continue;
      mean /= 64;
      if (mean < 8 || mean > 247) continue;
      const double model = look.noise.Sigma(1, mean);
      if (model <= 0) continue;
      ratios.push_back(BlockNoiseSigma(image, bx, by, 1) / model);
    }
  out.noise_blocks = static_cast<int>(ratios.size());
  if (!ratios.empty()) {
    std::sort(ratios.begin(), ratios.end());
    out.noise_ratio = ratios[static_cast<size_t>(0.2 * static_cast<double>(ratios.size()))];
  }
  const std::array<int, 4> region{x0, y0, x1, y1};
  const std::vector<double> widths = EdgeRiseWidths(image, &region, &mask);
  out.edges = static_cast<int>(widths.size());
  if (!widths.empty()) out.edge_rise_px = widths[widths.size() / 2];
  return out;
}

ImageF ObjectOutlinesMask(const CameraSensor& camera, const std::vector<Box3>& boxes_ego, int min_pixels) {
  ImageF mask(camera.intrinsics.width, camera.intrinsics.height, 1, 0.0f);
  for (const Box3& box : boxes_ego) ForEachOutlinePixel(camera, box, [&](int x, int y) { mask.at(x, y) = 1; }, min_pixels);
  return mask;
}

std::vector<std::pair<int, int>> ObjectOutlinePixels(const CameraSensor& camera, const Box3& box_ego) {
  std::vector<std::pair<int, int>> pixels;
  ForEachOutlinePixel(camera, box_ego, [&](int x, int y) { pixels.emplace_back(x, y); });
  return pixels;
}

LookComparison CompareLooks(const std::vector<ObjectLook>& objects) {
  LookComparison c;
  std::vector<double> noise[2], edges[2], saturation[2];
  for (const ObjectLook& o : objects) {
    const int k = o.inserted ? 1 : 0;
    (o.inserted ? c.inserted : c.real) += 1;
    if (o.noise_blocks > 0) noise[k].push_back(o.noise_ratio);
    if (o.edges > 0) edges[k].push_back(o.edge_rise_px);
    if (o.pixels > 0) saturation[k].push_back(o.saturation);
  }
  c.real_noise = Median(noise[0]), c.inserted_noise = Median(noise[1]);
  c.real_edge_rise = Median(edges[0]), c.inserted_edge_rise = Median(edges[1]);
  c.real_saturation = Median(saturation[0]), c.inserted_saturation = Median(saturation[1]);
  return c;
}

bool HasStandardLivery(const std::string& canonical_category) {
  static const std::set<std::string> kLiveried = {"traffic_cone", "barrier", "warning_tripod", "a_frame_sign",
                                                  "portable_traffic_light"};
  return kLiveried.count(canonical_category) > 0;
}

std::map<std::string, SaturationReference> RealSaturation(const Log& log, const std::vector<size_t>& frames,
                                                          const std::set<std::string>& categories, const FrameImage& image) {
  std::map<std::string, SaturationReference> out;
  std::map<std::string, std::vector<double>> seen;
  for (const std::string& c : categories) out[c] = {};
  for (size_t fi : frames) {
    const Frame& frame = log.frames.at(fi);
    for (size_t ci = 0; ci < frame.cameras.size(); ++ci) {
      const CameraSensor& cam = frame.cameras[ci];
      std::optional<ImageU8> read;
      const ImageU8* photo = nullptr;
      for (const Annotation& a : frame.annotations) {
        if (a.detected) continue;  // a guessed class is no colour reference
        const auto it = out.find(CanonicalCategory(a.category));
        if (it == out.end() || OutlinePixels(cam, a.box) < kMinRealPixels) continue;
        if (!photo) photo = image ? &image(fi, ci) : &read.emplace(ReadImage(cam.image_path, 3));
        int pixels = 0;
        const double saturation = MeasureSaturation(*photo, cam, a.box, &pixels);
        if (pixels < kMinRealPixels) continue;
        seen[it->first].push_back(saturation);
      }
    }
  }
  for (auto& [category, ref] : out) {
    const std::vector<double>& v = seen[category];
    ref.views = static_cast<int>(v.size());
    if (v.empty()) continue;
    if (HasStandardLivery(category) && v.size() >= 3) {
      ref.ceiling = Median(v);
      ref.statistic = "median";
    } else {
      ref.ceiling = *std::max_element(v.begin(), v.end());
      ref.statistic = "max";
    }
  }
  return out;
}

namespace {

using Features = std::array<double, 3>;

// Class-weighted, L2-regularised logistic regression (Newton's method; 3 features + bias). Returns (w, b).
std::pair<Features, double> FitLogistic(const std::vector<Features>& x, const std::vector<int>& y, double lambda) {
  double n1 = 0, n0 = 0;
  for (int v : y) (v ? n1 : n0) += 1;
  const double w1 = 0.5 * y.size() / std::max(n1, 1.0), w0 = 0.5 * y.size() / std::max(n0, 1.0);
  Eigen::Vector4d theta = Eigen::Vector4d::Zero();  // w0..w2, b
  for (int it = 0; it < 25; ++it) {
    Eigen::Vector4d grad = Eigen::Vector4d::Zero();
    Eigen::Matrix4d hess = Eigen::Matrix4d::Zero();
    for (size_t i = 0; i < x.size(); ++i) {
      const Eigen::Vector4d xi(x[i][0], x[i][1], x[i][2], 1.0);
      const double p = 1.0 / (1.0 + std::exp(-theta.dot(xi)));
      const double w = y[i] ? w1 : w0;
      grad += w * (p - y[i]) * xi;
      hess += w * p * (1 - p) * xi * xi.transpose();
    }
    for (int k = 0; k < 3; ++k) {  // the bias is not shrunk
      grad[k] += lambda * theta[k];
      hess(k, k) += lambda;
    }
    hess(3, 3) += 1e-9;
    const Eigen::Vector4d step = hess.ldlt().solve(grad);
    theta -= step;
    if (step.norm() < 1e-10) break;
  }
  return {{theta[0], theta[1], theta[2]}, theta[3]};
}

}  // namespace

nlohmann::json TwoSampleTest::ToJson() const {
  nlohmann::json j = {{"real", real}, {"inserted", inserted}, {"folds", folds}};
  if (folds > 0) {
    j["balanced_accuracy"] = balanced_accuracy;
    j["weights"] = {{"log_noise_ratio", weights[0]}, {"log_edge_rise", weights[1]}, {"saturation", weights[2]}};
  } else {
    j["note"] = "fewer than two objects in a class: no cross-validated figure";
  }
  return j;
}

TwoSampleTest ClassifyRealVsInserted(const std::vector<ObjectLook>& objects) {
  TwoSampleTest t;
  std::vector<double> noise, rise;
  for (const ObjectLook& o : objects) {
    if (o.pixels == 0) continue;
    (o.inserted ? t.inserted : t.real) += 1;
    if (o.noise_blocks > 0 && o.noise_ratio > 0) noise.push_back(std::log(o.noise_ratio));
    if (o.edges > 0 && o.edge_rise_px > 0) rise.push_back(std::log(o.edge_rise_px));
  }
  const int k = std::min(5, std::min(t.real, t.inserted));
  if (k < 2) return t;
  const double noise_fill = Median(noise), rise_fill = Median(rise);
  std::vector<Features> x;
  std::vector<int> y;
  for (const ObjectLook& o : objects) {
    if (o.pixels == 0) continue;
    x.push_back({o.noise_blocks > 0 && o.noise_ratio > 0 ? std::log(o.noise_ratio) : noise_fill,
                 o.edges > 0 && o.edge_rise_px > 0 ? std::log(o.edge_rise_px) : rise_fill, o.saturation});
    y.push_back(o.inserted ? 1 : 0);
  }
  // Standardised over all objects (the folds share the scaling: it carries no label).
  for (int f = 0; f < 3; ++f) {
    double mean = 0, var = 0;
    for (const Features& v : x) mean += v[f];
    mean /= x.size();
    for (const Features& v : x) var += (v[f] - mean) * (v[f] - mean);
    const double sd = std::sqrt(var / x.size());
    for (Features& v : x) v[f] = sd > 1e-12 ? (v[f] - mean) / sd : 0.0;
  }
  std::vector<int> fold(x.size());
  int seen[2] = {0, 0};
  for (size_t i = 0; i < x.size(); ++i) fold[i] = seen[y[i]]++ % k;
  double correct[2] = {0, 0};
  for (int f = 0; f < k; ++f) {
    std::vector<Features> xt;
    std::vector<int> yt;
    for (size_t i = 0; i < x.size(); ++i)
      if (fold[i] != f) xt.push_back(x[i]), yt.push_back(y[i]);
    const auto [w, b] = FitLogistic(xt, yt, 1.0);
    for (size_t i = 0; i < x.size(); ++i) {
      if (fold[i] != f) continue;
      const double score = w[0] * x[i][0] + w[1] * x[i][1] + w[2] * x[i][2] + b;
      correct[y[i]] += (score > 0) == (y[i] == 1);
    }
  }
  t.folds = k;
  t.balanced_accuracy = 0.5 * (correct[0] / t.real + correct[1] / t.inserted);
  t.weights = FitLogistic(x, y, 1.0).first;
  return t;
}

namespace {

nlohmann::json ComparisonJson(const LookComparison& c) {
  auto ratio = [](double ins, double real) { return real > 0 && ins > 0 ? nlohmann::json(ins / real) : nlohmann::json(nullptr); };
  return {{"real_objects", c.real},
          {"inserted_objects", c.inserted},
          {"noise", {{"real", c.real_noise}, {"inserted", c.inserted_noise}, {"ratio", ratio(c.inserted_noise, c.real_noise)}}},
          {"edge_rise_px",
           {{"real", c.real_edge_rise}, {"inserted", c.inserted_edge_rise}, {"ratio", ratio(c.inserted_edge_rise, c.real_edge_rise)}}},
          {"saturation",
           {{"real", c.real_saturation}, {"inserted", c.inserted_saturation}, {"ratio", ratio(c.inserted_saturation, c.real_saturation)}}}};
}

}  // namespace

nlohmann::json RealismReport::ToJson() const {
  nlohmann::json j;
  j["protocol"] = "synth/realism.h: over each object's projected 3D box in the output image; noise = 20th percentile of "
                  "its 8x8 blocks' residual sigma over the original image's noise model; edge rise = median 10-90 % rise "
                  "of its step edges; saturation = 90th percentile of its pixels' HSV saturation";
  j["summaries"] = nlohmann::json::array();
  for (const RealismSummary& s : summaries) {
    nlohmann::json c = ComparisonJson(s.comparison);
    c["category"] = s.category.empty() ? nlohmann::json("all") : nlohmann::json(s.category);
    j["summaries"].push_back(c);
  }
  j["classifier"] = classifier.ToJson();
  j["shadow_protocol"] = "synth/realism.h MeasureShadowContrasts: 20th percentile of linear luminance of the road the "
                         "object's shadow covers against the same road mirrored through its footprint (1 = no shadow)";
  j["shadow"] = {{"real", shadow.real},
                 {"inserted", shadow.inserted},
                 {"real_median_contrast", shadow.real_contrast},
                 {"inserted_median_contrast", shadow.inserted_contrast}};
  j["shadows"] = nlohmann::json::array();
  for (const ShadowContrast& sc : shadows)
    j["shadows"].push_back({{"frame", sc.frame}, {"camera", sc.channel}, {"category", sc.category},
                            {"inserted", sc.inserted}, {"contrast", sc.contrast}});
  j["contact_protocol"] = "synth/realism.h MeasureContactDarkening: median linear luminance of the road 0.6-1 m from the "
                          "footprint over that 3-20 cm from it, outside every box's shadow (1 = no contact darkening)";
  j["contact"] = nlohmann::json::array();
  for (const ContactComparison& c : contact)
    j["contact"].push_back({{"category", c.category.empty() ? nlohmann::json(nullptr) : nlohmann::json(c.category)},
                            {"real", c.real},
                            {"inserted", c.inserted},
                            {"real_median_darkening", c.real_darkening},
                            {"inserted_median_darkening", c.inserted_darkening}});
  j["contacts"] = nlohmann::json::array();
  for (const ContactDarkening& c : contacts)
    j["contacts"].push_back({{"frame", c.frame}, {"camera", c.channel}, {"category", c.category},
                             {"inserted", c.inserted}, {"darkening", c.darkening}});
  j["objects"] = nlohmann::json::array();
  for (const RealismRow& r : rows)
    j["objects"].push_back({{"frame", r.frame},
                            {"camera", r.channel},
                            {"category", r.look.category},
                            {"inserted", r.look.inserted},
                            {"noise", r.look.noise_blocks > 0 ? nlohmann::json(r.look.noise_ratio) : nlohmann::json(nullptr)},
                            {"noise_blocks", r.look.noise_blocks},
                            {"edge_rise_px", r.look.edges > 0 ? nlohmann::json(r.look.edge_rise_px) : nlohmann::json(nullptr)},
                            {"edges", r.look.edges},
                            {"saturation", r.look.saturation},
                            {"pixels", r.look.pixels}});
  return j;
}

namespace {

// The frame with the inserts as annotations after its real ones: every box, real or not, hides the road behind
// it from the camera and casts its shadow.
Frame WithInsertsAsAnnotations(const Frame& frame, const std::vector<std::pair<std::string, Box3>>& inserted) {
  Frame scene = frame;
  for (const auto& [category, box] : inserted) {
    Annotation a;
    a.category = category;
    a.box = box;
    scene.annotations.push_back(a);
  }
  return scene;
}

}  // namespace

std::vector<ShadowContrast> MeasureShadowContrasts(const Frame& frame,
                                                   const std::vector<std::pair<std::string, Box3>>& inserted,
                                                   const LinearImages& linear, const Eigen::Vector3d& sun_dir_ego) {
  const Frame scene = WithInsertsAsAnnotations(frame, inserted);
  const size_t real = frame.annotations.size();
  ShadowCheckOptions options;
  options.min_height_m = 0.5;  // cones, posts and barriers as well as vehicles
  options.cell_m = 0.05;       // a cone's shadow is a few decimetres wide
  // An object is compared with itself only where no other box's shadow (or footprint) reaches the road it is
  // compared against: in a closure of cones a neighbour's shadow on the mirrored side would read as no shadow.
  const Eigen::Vector3d sun = sun_dir_ego.normalized();
  std::vector<std::vector<Eigen::Vector2d>> shadow_of;
  for (const Annotation& a : scene.annotations) shadow_of.push_back(ShadowHull(a.box, sun, false));
  std::vector<ShadowContrast> out;
  for (const ShadowCheckBox& b : CheckSunAgainstShadows(scene, linear, sun, options).boxes) {
    if (!(b.CoreContrast() > 0)) continue;
    const std::vector<Eigen::Vector2d> mirrored = ShadowHull(scene.annotations[b.annotation].box, sun, true);
    bool confounded = false;
    for (size_t k = 0; k < shadow_of.size() && !confounded; ++k)
      confounded = k != b.annotation && geometry::ConvexPolygonsOverlap(mirrored, shadow_of[k]);
    if (confounded) continue;
    const bool is_inserted = b.annotation >= real;
    out.push_back({frame.token, b.channel,
                   is_inserted ? scene.annotations[b.annotation].category : CanonicalCategory(scene.annotations[b.annotation].category),
                   is_inserted, b.CoreContrast()});
  }
  return out;
}

ShadowComparison CompareShadows(const std::vector<ShadowContrast>& shadows) {
  std::vector<double> real, inserted;
  for (const ShadowContrast& s : shadows) (s.inserted ? inserted : real).push_back(s.contrast);
  ShadowComparison c;
  c.real = static_cast<int>(real.size());
  c.inserted = static_cast<int>(inserted.size());
  c.real_contrast = Median(real);  // 0 with none
  c.inserted_contrast = Median(inserted);
  return c;
}

std::vector<ContactDarkening> MeasureContactDarkening(const Frame& frame,
                                                      const std::vector<std::pair<std::string, Box3>>& inserted,
                                                      const LinearImages& linear,
                                                      const std::optional<Eigen::Vector3d>& sun_dir_ego) {
  const Frame scene = WithInsertsAsAnnotations(frame, inserted);
  const size_t real = frame.annotations.size();
  std::optional<Eigen::Vector3d> sun;
  if (sun_dir_ego) sun = sun_dir_ego->normalized();
  std::vector<ContactDarkening> out;
  for (const ContactCheckBox& b : CheckContactDarkening(scene, linear, sun)) {
    const bool is_inserted = b.annotation >= real;
    const Annotation& a = scene.annotations[b.annotation];
    out.push_back({frame.token, b.channel, is_inserted ? a.category : CanonicalCategory(a.category), is_inserted, b.Darkening()});
  }
  return out;
}

std::vector<ContactComparison> CompareContacts(const std::vector<ContactDarkening>& contacts) {
  auto compare = [&](const std::string& category) {
    std::vector<double> real, inserted;
    for (const ContactDarkening& c : contacts)
      if (category.empty() || c.category == category) (c.inserted ? inserted : real).push_back(c.darkening);
    ContactComparison out;
    out.category = category;
    out.real = static_cast<int>(real.size());
    out.inserted = static_cast<int>(inserted.size());
    out.real_darkening = Median(real);
    out.inserted_darkening = Median(inserted);
    return out;
  };
  std::vector<ContactComparison> out = {compare("")};
  std::set<std::string> categories;
  for (const ContactDarkening& c : contacts)
    if (c.inserted) categories.insert(c.category);
  for (const std::string& category : categories) out.push_back(compare(category));
  return out;
}

RealismReport EvaluateRealism(const std::filesystem::path& synth_out) {
  namespace fs = std::filesystem;
  const fs::path synth_json = synth_out / "synth.json";
  if (!fs::is_regular_file(synth_json))
    throw InputError(synth_out, "no synth.json: not the output of `synthdrive synth`");
  const nlohmann::json j = ReadJsonFile(synth_json);
  const JsonReader r(j, synth_json);
  const fs::path log_path = r["log"].String();
  if (!fs::exists(log_path)) r["log"].Fail("the original log " + log_path.string() + " is gone: its real objects and images are needed");
  const Log log = OpenLog(log_path);
  RealismReport report;
  std::map<std::string, std::vector<ObjectLook>> by_category;
  std::vector<ObjectLook> all;
  for (size_t f = 0; f < r["frames"].Size(); ++f) {
    const JsonReader rf = r["frames"][f];
    const std::string token = rf["token"].String();
    const Frame* frame = nullptr;
    for (const Frame& fr : log.frames)
      if (fr.token == token) frame = &fr;
    if (!frame) rf["token"].Fail("the original log has no such frame");
    std::vector<std::pair<std::string, Box3>> inserted;
    for (size_t k = 0; k < rf["objects"].Size(); ++k) {
      const JsonReader o = rf["objects"][k];
      Box3 b;
      if (o.Has("box_ego")) {
        b = ReadBox3(o["box_ego"]);
      } else {  // written before synth.json held the whole box: the heading alone, level
        b.T_frame_box = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(o["yaw_ego_rad"].Number(), Eigen::Vector3d::UnitZ())),
                                Eigen::Vector3d(o["center_ego_m"][0].Number(), o["center_ego_m"][1].Number(), o["center_ego_m"][2].Number()));
        b.size = Eigen::Vector3d(o["size_m"][0].Number(), o["size_m"][1].Number(), o["size_m"][2].Number());
      }
      inserted.push_back({o["category"].String(), b});
    }
    // The frame's final images, each read once: a camera synth drew from the output, the others (needed only for
    // the shadows, which may fall into any camera) are the originals.
    const bool shadows = rf.Has("sun_direction_ego");
    std::vector<ImageU8> final_images(frame->cameras.size());
    for (size_t k = 0; k < frame->cameras.size(); ++k) {
      const CameraSensor& cam = frame->cameras[k];
      if (rf["camera_light"].raw().contains(cam.channel)) {
        const fs::path rel = cam.image_path.lexically_relative(log.data_root);
        if (rel.empty() || *rel.begin() == "..") throw InputError(cam.image_path, "lies outside the log's data root");
        final_images[k] = ReadImage(synth_out / rel, 3);
      } else {
        final_images[k] = ReadImage(cam.image_path, 3);
      }
    }
    const LinearImages linear(final_images);
    std::optional<Eigen::Vector3d> sun;
    if (shadows) {
      sun.emplace();
      for (int k = 0; k < 3; ++k) (*sun)[k] = rf["sun_direction_ego"][k].Number();
      if (!(sun->norm() > 0.5)) rf["sun_direction_ego"].Fail("is not a direction");
      for (ShadowContrast& sc : MeasureShadowContrasts(*frame, inserted, linear, *sun)) report.shadows.push_back(std::move(sc));
    }
    for (ContactDarkening& c : MeasureContactDarkening(*frame, inserted, linear, sun)) report.contacts.push_back(std::move(c));
    for (const auto& [channel, light] : rf["camera_light"].raw().items()) {
      const CameraSensor* cam = frame->FindCamera(channel);
      if (!cam) rf["camera_light"].Fail("the original log's frame has no camera " + channel);
      const ImageU8& after = final_images[static_cast<size_t>(cam - frame->cameras.data())];
      const CameraLook look = EstimateCameraLook(ReadImage(cam->image_path, 3), std::nullopt);
      auto add = [&](ObjectLook o) {
        report.rows.push_back({token, channel, o});
        all.push_back(o);
        by_category[o.category].push_back(o);
      };
      for (const Annotation& a : frame->annotations) {
        ObjectLook o = MeasureObjectLook(after, *cam, a.box, look);
        o.category = CanonicalCategory(a.category);
        if (o.pixels >= kMinRealPixels) add(o);
      }
      for (const auto& [category, box] : inserted) {
        ObjectLook o = MeasureObjectLook(after, *cam, box, look);
        o.category = category;
        o.inserted = true;
        if (o.pixels > 0) add(o);
      }
    }
  }
  report.summaries.push_back({"", CompareLooks(all)});
  for (const auto& [category, objects] : by_category) {
    const LookComparison c = CompareLooks(objects);
    if (c.inserted > 0) report.summaries.push_back({category, c});
  }
  report.classifier = ClassifyRealVsInserted(all);
  report.shadow = CompareShadows(report.shadows);
  report.contact = CompareContacts(report.contacts);
  return report;
}

}  // namespace sd
