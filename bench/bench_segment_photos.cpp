// The classical segmentation path on real web photos: the traffic-cone frames of the Road Anomaly dataset in
// ../shared/data/images/roadanomaly-cones (1280x720 Wikimedia Commons street photos with per-pixel ground truth;
// its SOURCES.md says where they come from).
//
// Objects: the 8-connected components of each photo's ground-truth mask (labels_semantic.png != 0) holding at
// least kMinObjectPixels pixels; a component is one object even where it holds several touching cones (the
// "instances" column counts the ids of labels_instance.png inside it). Smaller components are counted, not scored.
// Per object and per box margin (10 % and 25 % of the component's bounding-box width / height added on each side,
// clipped to the image): Segmenter::Classical().Segment() — GrabCut (models/grabcut.h) with the default options,
// then the "no object found" check generate makes — on the whole photo with that box, timed; the mask IoU against
// that component alone over the box's pixels (another component's pixels inside the box are background for the
// truth; GrabCut labels every pixel outside the box background). An object whose segmentation throws scores 0.
//
// Usage: bench_segment_photos [--crops DIR]
//   --crops DIR  also writes, per object and margin, DIR/<photo>_<k>_<margin>.png: the photo's box | the truth |
//                the result (green = both, red = result only, blue = truth only), enlarged to >= 240 px high.
// Prints a markdown table and writes bench/results/segment_photos.json. A plain program; exits 0 with a message
// when ../shared/data is absent.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <filesystem>
#include <iterator>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_demo.h"
#include "core/error.h"
#include "core/image.h"
#include "io/files.h"
#include "io/image_io.h"
#include "models/segmentation.h"

namespace fs = std::filesystem;
using sd::Box2;
using sd::ImageF;
using sd::ImageU8;

namespace {

// Components below this are specks of the annotation or cones too far away to be an asset source.
constexpr int64_t kMinObjectPixels = 200;
constexpr double kMargins[] = {0.10, 0.25};
constexpr size_t kSettings = std::size(kMargins);

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}
double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? NAN : s / static_cast<double>(v.size());
}
double Min(const std::vector<double>& v) { return v.empty() ? NAN : *std::min_element(v.begin(), v.end()); }

struct Component {
  int id = 0;          // label in the photo's component image (1-based)
  int64_t pixels = 0;
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // pixel bounds, [x0, x1) x [y0, y1)
  int instances = 0;   // distinct non-zero ids of labels_instance.png inside the component
};

// 8-connected components of `mask` != 0; `labels` gets each pixel's component id (0 = background).
std::vector<Component> Components(const ImageU8& mask, const ImageU8* instance, std::vector<int>* labels) {
  const int w = mask.width(), h = mask.height();
  labels->assign(static_cast<size_t>(w) * h, 0);
  std::vector<Component> out;
  std::vector<int> stack;
  for (int start = 0; start < w * h; ++start) {
    if (mask.data()[start] == 0 || (*labels)[start] != 0) continue;
    Component c;
    c.id = static_cast<int>(out.size()) + 1;
    c.x0 = w, c.y0 = h;
    std::set<int> ids;
    (*labels)[start] = c.id;
    stack.assign(1, start);
    while (!stack.empty()) {
      const int p = stack.back();
      stack.pop_back();
      const int x = p % w, y = p / w;
      ++c.pixels;
      c.x0 = std::min(c.x0, x), c.y0 = std::min(c.y0, y), c.x1 = std::max(c.x1, x + 1), c.y1 = std::max(c.y1, y + 1);
      if (instance && instance->data()[p] != 0) ids.insert(instance->data()[p]);
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
          const int q = ny * w + nx;
          if (mask.data()[q] != 0 && (*labels)[q] == 0) {
            (*labels)[q] = c.id;
            stack.push_back(q);
          }
        }
    }
    c.instances = static_cast<int>(ids.size());
    out.push_back(c);
  }
  return out;
}

// The component's bounds grown by `margin` of their width / height on each side, clipped to the image.
Box2 GrownBox(const Component& c, double margin, int width, int height) {
  const double mx = margin * (c.x1 - c.x0), my = margin * (c.y1 - c.y0);
  return {std::max(0.0, c.x0 - mx), std::max(0.0, c.y0 - my), std::min<double>(width, c.x1 + mx),
          std::min<double>(height, c.y1 + my)};
}

// The crop picture of --crops: photo | truth | result coded against the truth, side by side.
void WriteCrop(const fs::path& file, const ImageU8& photo, const std::vector<int>& labels, int id, const ImageF* mask,
               const sd::models::PixelRect& r) {
  const int cw = r.x1 - r.x0, ch = r.y1 - r.y0, s = std::max(1, (240 + ch - 1) / ch), gap = 4;
  ImageU8 out(3 * cw * s + 2 * gap, ch * s, 3, 255);
  for (int y = 0; y < ch; ++y)
    for (int x = 0; x < cw; ++x) {
      const int px = r.x0 + x, py = r.y0 + y;
      const uint8_t* p = photo.pixel(px, py);
      const bool truth = labels[static_cast<size_t>(py) * photo.width() + px] == id;
      const bool result = mask && mask->at(px, py) >= 0.5f;
      uint8_t coded[3] = {static_cast<uint8_t>(p[0] / 3), static_cast<uint8_t>(p[1] / 3), static_cast<uint8_t>(p[2] / 3)};
      if (truth && result) coded[1] = 255;
      else if (result) coded[0] = 255;
      else if (truth) coded[2] = 255;
      const uint8_t t = truth ? 255 : 0;
      const uint8_t* panels[3] = {p, nullptr, coded};
      for (int k = 0; k < 3; ++k)
        for (int sy = 0; sy < s; ++sy)
          for (int sx = 0; sx < s; ++sx) {
            uint8_t* o = out.pixel(k * (cw * s + gap) + x * s + sx, y * s + sy);
            for (int c = 0; c < 3; ++c) o[c] = panels[k] ? panels[k][c] : t;
          }
    }
  sd::WriteImage(file, out);
}

}  // namespace

int main(int argc, char** argv) {
  fs::path crops;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--crops" && i + 1 < argc) crops = argv[++i];
    else {
      std::fprintf(stderr, "usage: bench_segment_photos [--crops DIR]\n");
      return 2;
    }
  }
  const auto root = sd::bench::FindRepoRoot();
  if (!root) {
    std::fprintf(stderr, "bench_segment_photos: cannot find the repo's data/ (set SYNTHDRIVE_SOURCE_DIR)\n");
    return 2;
  }
  const fs::path frames = fs::weakly_canonical(*root / ".." / "shared" / "data" / "images" / "roadanomaly-cones" / "frames");
  if (!fs::is_directory(frames)) {
    std::printf("bench_segment_photos: %s not present (needs ../shared/data beside the repo); skipped\n", frames.string().c_str());
    return 0;
  }
  if (!crops.empty()) fs::create_directories(crops);
  std::vector<fs::path> photos;
  for (const auto& e : fs::directory_iterator(frames))
    if (e.path().extension() == ".jpg" && fs::is_directory(fs::path(e.path()).replace_extension(".labels"))) photos.push_back(e.path());
  std::sort(photos.begin(), photos.end());

  const sd::models::Segmenter segmenter = sd::models::Segmenter::Classical();
  std::printf("segmenter: %s\nphotos: %zu in %s\n", segmenter.Describe().c_str(), photos.size(), frames.string().c_str());

  struct Row {
    std::string photo;
    Component c;
    double iou[kSettings] = {};
    double seconds[kSettings] = {};
    int64_t result_pixels[kSettings] = {};
    Box2 box[kSettings];
    std::string error[kSettings];
  };
  std::vector<Row> rows;
  nlohmann::json photo_info = nlohmann::json::array();
  for (const fs::path& file : photos) {
    const std::string name = file.stem().string();
    const fs::path labels_dir = fs::path(file).replace_extension(".labels");
    const ImageU8 photo = sd::ReadImage(file, 3);
    const ImageU8 truth = sd::ReadImage(labels_dir / "labels_semantic.png", 1);
    std::optional<ImageU8> instance;
    if (fs::exists(labels_dir / "labels_instance.png")) instance = sd::ReadImage(labels_dir / "labels_instance.png", 1);
    if (truth.width() != photo.width() || truth.height() != photo.height() ||
        (instance && (instance->width() != photo.width() || instance->height() != photo.height()))) {
      std::fprintf(stderr, "bench_segment_photos: %s: masks are not the photo's size\n", name.c_str());
      return 1;
    }
    std::vector<int> labels;
    const std::vector<Component> components = Components(truth, instance ? &*instance : nullptr, &labels);
    int64_t small_pixels = 0;
    int small = 0;
    for (const Component& c : components) {
      if (c.pixels < kMinObjectPixels) {
        ++small, small_pixels += c.pixels;
        continue;
      }
      Row row;
      row.photo = name;
      row.c = c;
      for (size_t k = 0; k < kSettings; ++k) {
        row.box[k] = GrownBox(c, kMargins[k], photo.width(), photo.height());
        const sd::models::PixelRect r = sd::models::PixelsOf(row.box[k], photo.width(), photo.height());
        std::optional<ImageF> mask;
        const auto t0 = std::chrono::steady_clock::now();
        try {
          mask = segmenter.Segment(photo, row.box[k]).mask;
        } catch (const sd::InputError& e) {
          row.error[k] = e.what();
        }
        row.seconds[k] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        int64_t inter = 0, uni = 0;
        for (int y = r.y0; y < r.y1; ++y)
          for (int x = r.x0; x < r.x1; ++x) {
            const bool t = labels[static_cast<size_t>(y) * photo.width() + x] == c.id;
            const bool m = mask && mask->at(x, y) >= 0.5f;
            inter += t && m, uni += t || m, row.result_pixels[k] += m;
          }
        row.iou[k] = uni ? static_cast<double>(inter) / static_cast<double>(uni) : 0.0;
        if (!crops.empty())
          WriteCrop(crops / (name.substr(0, name.find('_')) + "_" + std::to_string(rows.size()) + "_" +
                             std::to_string(static_cast<int>(std::lround(100 * kMargins[k]))) + ".png"),
                    photo, labels, c.id, mask ? &*mask : nullptr, r);
      }
      std::printf("%s #%d: %lld px, IoU %.3f / %.3f, %.2f / %.2f s\n", name.c_str(), c.id, static_cast<long long>(c.pixels),
                  row.iou[0], row.iou[1], row.seconds[0], row.seconds[1]);
      std::fflush(stdout);
      rows.push_back(std::move(row));
    }
    std::printf("%s: %zu components, %d below %lld px (%lld px in all)\n", name.c_str(), components.size(), small,
                static_cast<long long>(kMinObjectPixels), static_cast<long long>(small_pixels));
    photo_info.push_back({{"photo", name}, {"components", components.size()}, {"below_min", small}, {"below_min_pixels", small_pixels}});
  }

  std::printf("\n| photo | object (box x0,y0 w×h) | instances | size (px) | IoU 10%% | IoU 25%% | s 10%% | s 25%% |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  std::vector<double> iou[kSettings], seconds[kSettings];
  nlohmann::json objects = nlohmann::json::array();
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& row = rows[i];
    std::printf("| %s | %zu (%d,%d %d×%d) | %d | %lld | %.3f%s | %.3f%s | %.2f | %.2f |\n", row.photo.c_str(), i, row.c.x0,
                row.c.y0, row.c.x1 - row.c.x0, row.c.y1 - row.c.y0, row.c.instances, static_cast<long long>(row.c.pixels),
                row.iou[0], row.error[0].empty() ? "" : " (none found)", row.iou[1], row.error[1].empty() ? "" : " (none found)",
                row.seconds[0], row.seconds[1]);
    nlohmann::json settings = nlohmann::json::array();
    for (size_t k = 0; k < kSettings; ++k) {
      iou[k].push_back(row.iou[k]);
      seconds[k].push_back(row.seconds[k]);
      settings.push_back({{"margin", kMargins[k]},
                          {"box", {row.box[k].x1, row.box[k].y1, row.box[k].x2, row.box[k].y2}},
                          {"iou", row.iou[k]},
                          {"result_pixels", row.result_pixels[k]},
                          {"seconds", row.seconds[k]},
                          {"error", row.error[k]}});
    }
    objects.push_back({{"photo", row.photo},
                       {"object", i},
                       {"pixels", row.c.pixels},
                       {"instances", row.c.instances},
                       {"bounds", {row.c.x0, row.c.y0, row.c.x1, row.c.y1}},
                       {"settings", settings}});
  }
  std::printf("| **median** | %zu objects | | | %.3f | %.3f | %.2f | %.2f |\n", rows.size(), Median(iou[0]), Median(iou[1]),
              Median(seconds[0]), Median(seconds[1]));
  std::printf("| **mean** | | | | %.3f | %.3f | | |\n", Mean(iou[0]), Mean(iou[1]));
  std::printf("| **min** | | | | %.3f | %.3f | | |\n", Min(iou[0]), Min(iou[1]));

  nlohmann::json summary = nlohmann::json::array();
  for (size_t k = 0; k < kSettings; ++k)
    summary.push_back({{"margin", kMargins[k]},
                       {"iou_median", Median(iou[k])},
                       {"iou_mean", Mean(iou[k])},
                       {"iou_min", Min(iou[k])},
                       {"seconds_median", Median(seconds[k])}});
  const nlohmann::json j = {{"dataset", "roadanomaly-cones"},
                            {"segmenter", segmenter.Describe()},
                            {"min_object_pixels", kMinObjectPixels},
                            {"photos", photo_info},
                            {"objects", objects},
                            {"summary", summary}};
  sd::WriteFileAtomic(*root / "bench" / "results" / "segment_photos.json", j.dump(1));
  return 0;
}
