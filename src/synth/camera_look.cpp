#include "synth/camera_look.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"
#include "io/image_io.h"
#include "render/camera_render.h"

namespace sd {
namespace {

constexpr int kBlock = 8;     // the JPEG grid
constexpr int kBins = 16;     // intensity bins of the noise fit
constexpr int kMinBinBlocks = 12;
constexpr double kFlatPercentile = 0.2;
// The 20th percentile of the 36-sample block estimates of white noise lies at 0.811 of its sigma (measured over
// 10^4 blocks; camera_look_test checks the recovered sigma): the fit divides it out.
constexpr double kPercentileBias = 0.811;
// A Gaussian edge's 10-90 % rise in sigmas: 2 * 1.2816.
constexpr double kRisePerSigma = 2.5631;

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<long>(k), v.end());
  return v[k];
}

double Luma(const ImageU8& im, int x, int y) {
  if (im.channels() < 3) return im.at(x, y, 0);
  return 0.299 * im.at(x, y, 0) + 0.587 * im.at(x, y, 1) + 0.114 * im.at(x, y, 2);
}

double BlockMean(const ImageU8& image, int bx, int by, int c) {
  double sum = 0;
  for (int y = 0; y < kBlock; ++y)
    for (int x = 0; x < kBlock; ++x) sum += image.at(bx * kBlock + x, by * kBlock + y, c);
  return sum / (kBlock * kBlock);
}

// The noise fit of one channel: per intensity bin the kFlatPercentile of the blocks' sigma, then the weighted
// least-squares line of variance over value.
void FitChannel(const ImageU8& image, int c, NoiseModel* model) {
  const int nbx = image.width() / kBlock, nby = image.height() / kBlock;
  std::vector<std::vector<double>> bins(kBins);
  for (int by = 0; by < nby; ++by)
    for (int bx = 0; bx < nbx; ++bx) {
      const double mean = BlockMean(image, bx, by, c);
      if (mean < 8 || mean > 247) continue;  // clipped: no noise to see
      bins[static_cast<size_t>(std::min(kBins - 1, static_cast<int>(mean * kBins / 256.0)))].push_back(BlockNoiseSigma(image, bx, by, c));
    }
  double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  int used = 0;
  for (int k = 0; k < kBins; ++k) {
    if (static_cast<int>(bins[k].size()) < kMinBinBlocks) continue;
    const double sigma = Percentile(bins[k], kFlatPercentile) / kPercentileBias;
    const double v = (k + 0.5) * 256.0 / kBins, var = sigma * sigma, w = std::sqrt(static_cast<double>(bins[k].size()));
    sw += w, sx += w * v, sy += w * var, sxx += w * v * v, sxy += w * v * var;
    used += static_cast<int>(bins[k].size());
  }
  if (used == 0) return;
  const double det = sw * sxx - sx * sx;
  double a = sy / sw, b = 0;
  if (det > 1e-9 * sw * sxx) {
    b = (sw * sxy - sx * sy) / det;
    a = (sy - b * sx) / sw;
  }
  // Noise never falls with the signal and is never negative: a negative slope is texture or clipping, so keep
  // the level only.
  if (b < 0 || a < 0) {
    b = std::max(0.0, b);
    a = std::max(0.0, (sy - b * sx) / sw);
  }
  model->a[static_cast<size_t>(c)] = a;
  model->b[static_cast<size_t>(c)] = b;
  model->blocks = std::max(model->blocks, used);
}

// The rise of one edge profile (samples at unit steps across the edge): positions where it crosses 10 % and 90 %
// of the way from its low plateau to its high one; nullopt when it is no clean step.
std::optional<double> RiseOfProfile(const std::vector<double>& p) {
  const int n = static_cast<int>(p.size());
  const double lo = (p[0] + p[1] + p[2]) / 3, hi = (p[n - 1] + p[n - 2] + p[n - 3]) / 3;
  const double contrast = hi - lo;
  if (contrast < 30) return std::nullopt;
  // Plateaus flat relative to the step: no texture or second edge inside the window.
  for (int k : {0, 1, 2}) {
    if (std::abs(p[k] - lo) > 0.1 * contrast) return std::nullopt;
    if (std::abs(p[n - 1 - k] - hi) > 0.1 * contrast) return std::nullopt;
  }
  auto crossing = [&](double level) -> std::optional<double> {
    for (int k = 0; k + 1 < n; ++k)
      if (p[k] < level && p[k + 1] >= level) return k + (level - p[k]) / (p[k + 1] - p[k]);
    return std::nullopt;
  };
  const auto x10 = crossing(lo + 0.1 * contrast), x90 = crossing(lo + 0.9 * contrast);
  if (!x10 || !x90 || *x90 <= *x10) return std::nullopt;
  return *x90 - *x10;
}

double Bilinear(const std::vector<double>& luma, int w, int h, double x, double y) {
  x = std::clamp(x, 0.0, w - 1.001), y = std::clamp(y, 0.0, h - 1.001);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const double fx = x - x0, fy = y - y0;
  const auto at = [&](int xx, int yy) { return luma[static_cast<size_t>(yy) * w + xx]; };
  return (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) + fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
}

// The residual sigma a flat grey patch with white noise of `sigma` measures after a JPEG round trip at
// `quality` (median over its blocks).
double SigmaAfterJpeg(int quality, double sigma) {
  ImageU8 patch(64, 64, 3);
  std::mt19937_64 rng(12345);
  std::normal_distribution<double> n(0.0, sigma);
  for (size_t i = 0; i < patch.size(); ++i) patch.data()[i] = static_cast<uint8_t>(std::clamp(std::lround(128 + n(rng)), 0L, 255L));
  const ImageU8 back = DecodeImage(EncodeImage(patch, "jpg", quality), "noise patch", 3);
  std::vector<double> after;
  for (int by = 0; by < 8; ++by)
    for (int bx = 0; bx < 8; ++bx) after.push_back(BlockNoiseSigma(back, bx, by, 1));
  return Percentile(after, 0.5);
}

// How much stronger noise must be before a JPEG round trip at `quality` to measure `target` after it. JPEG's
// quantisation is a dead zone: weak noise vanishes entirely and strong noise mostly survives, so the gain is
// found by bisection on the simulated round trip, not by one ratio.
double PreCompressionGain(int quality, double target) {
  if (quality <= 0 || target <= 0.01) return 1.0;
  double lo = target, hi = 16 * target + 4;
  if (SigmaAfterJpeg(quality, hi) < target) return hi / target;
  for (int it = 0; it < 14; ++it) {
    const double mid = std::sqrt(lo * hi);
    (SigmaAfterJpeg(quality, mid) < target ? lo : hi) = mid;
  }
  return std::sqrt(lo * hi) / target;
}

}  // namespace

double NoiseModel::Sigma(int channel, double value) const {
  const size_t c = static_cast<size_t>(channel);
  return std::sqrt(std::max(0.0, a[c] + b[c] * value));
}

double BlockNoiseSigma(const ImageU8& image, int bx, int by, int c) {
  // [1 -2 1; -2 4 -2; 1 -2 1] has sum of squares 36: its response to white noise of sigma s has variance 36 s^2.
  const int x0 = bx * kBlock, y0 = by * kBlock;
  double sum = 0;
  int n = 0;
  for (int y = 1; y < kBlock - 1; ++y)
    for (int x = 1; x < kBlock - 1; ++x) {
      const auto v = [&](int dx, int dy) { return static_cast<double>(image.at(x0 + x + dx, y0 + y + dy, c)); };
      const double r = v(-1, -1) - 2 * v(0, -1) + v(1, -1) - 2 * v(-1, 0) + 4 * v(0, 0) - 2 * v(1, 0) + v(-1, 1) -
                       2 * v(0, 1) + v(1, 1);
      sum += r * r;
      ++n;
    }
  return std::sqrt(sum / (36.0 * n));
}

std::vector<EdgeRise> FindEdgeRises(const ImageU8& image, const std::array<int, 4>* region, const ImageF* mask) {
  const int w = image.width(), h = image.height();
  std::vector<double> luma(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) luma[static_cast<size_t>(y) * w + x] = Luma(image, x, y);
  const int x0 = region ? std::max(2, (*region)[0]) : 2, y0 = region ? std::max(2, (*region)[1]) : 2;
  const int x1 = region ? std::min(w - 2, (*region)[2]) : w - 2, y1 = region ? std::min(h - 2, (*region)[3]) : h - 2;
  constexpr int kHalf = 6;  // profile samples either side of the edge
  std::vector<EdgeRise> edges;
  // Every other pixel: neighbouring edge pixels give the same profile.
  for (int y = y0; y < y1; y += 2)
    for (int x = x0; x < x1; x += 2) {
      if (mask && mask->at(x, y) <= 0.5f) continue;
      const auto L = [&](int xx, int yy) { return luma[static_cast<size_t>(yy) * w + xx]; };
      const double gx = (L(x + 1, y - 1) + 2 * L(x + 1, y) + L(x + 1, y + 1) - L(x - 1, y - 1) - 2 * L(x - 1, y) - L(x - 1, y + 1)) / 8;
      const double gy = (L(x - 1, y + 1) + 2 * L(x, y + 1) + L(x + 1, y + 1) - L(x - 1, y - 1) - 2 * L(x, y - 1) - L(x + 1, y - 1)) / 8;
      const double g = std::hypot(gx, gy);
      if (g < 8) continue;  // no strong edge here
      // A local maximum along the gradient only: the edge's centre.
      const double ux = gx / g, uy = gy / g;
      if (Bilinear(luma, w, h, x + ux, y + uy) - Bilinear(luma, w, h, x - ux, y - uy) < 0) continue;
      const double g_fwd = std::abs(Bilinear(luma, w, h, x + 1.5 * ux, y + 1.5 * uy) - Bilinear(luma, w, h, x + 0.5 * ux, y + 0.5 * uy));
      const double g_back = std::abs(Bilinear(luma, w, h, x - 0.5 * ux, y - 0.5 * uy) - Bilinear(luma, w, h, x - 1.5 * ux, y - 1.5 * uy));
      const double g_here = std::abs(Bilinear(luma, w, h, x + 0.5 * ux, y + 0.5 * uy) - Bilinear(luma, w, h, x - 0.5 * ux, y - 0.5 * uy));
      if (g_here < g_fwd || g_here < g_back) continue;
      std::vector<double> profile;
      for (int s = -kHalf; s <= kHalf; ++s) profile.push_back(Bilinear(luma, w, h, x + s * ux, y + s * uy));
      if (const auto rise = RiseOfProfile(profile)) edges.push_back({*rise, ux, uy});
    }
  return edges;
}

std::vector<double> EdgeRiseWidths(const ImageU8& image, const std::array<int, 4>* region, const ImageF* mask) {
  std::vector<double> widths;
  for (const EdgeRise& e : FindEdgeRises(image, region, mask)) widths.push_back(e.rise_px);
  std::sort(widths.begin(), widths.end());
  return widths;
}

CameraLook EstimateCameraLook(const ImageU8& image, std::optional<int> jpeg_quality, const ImageF* objects) {
  CameraLook look;
  for (int c = 0; c < std::min(3, image.channels()); ++c) FitChannel(image, c, &look.noise);
  const std::vector<double> widths = EdgeRiseWidths(image);
  look.edges = static_cast<int>(widths.size());
  if (widths.size() >= 50) look.edge_width_px = widths[static_cast<size_t>(0.2 * static_cast<double>(widths.size()))];
  if (objects) {
    const std::vector<EdgeRise> found = FindEdgeRises(image, nullptr, objects);
    std::vector<double> on_objects, across_x, across_y;
    const double cos30 = std::cos(30.0 * 3.14159265358979323846 / 180.0);
    for (const EdgeRise& e : found) {
      on_objects.push_back(e.rise_px);
      if (std::abs(e.nx) >= cos30) across_x.push_back(e.rise_px);
      if (std::abs(e.ny) >= cos30) across_y.push_back(e.rise_px);
    }
    const auto median = [](std::vector<double> v) {
      std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
      return v[v.size() / 2];
    };
    look.object_edges = static_cast<int>(on_objects.size());
    if (on_objects.size() >= 30) look.object_edge_rise_px = median(on_objects);
    look.object_edges_across_x = static_cast<int>(across_x.size());
    look.object_edges_across_y = static_cast<int>(across_y.size());
    if (across_x.size() >= 15) look.object_edge_rise_across_x_px = median(across_x);
    if (across_y.size() >= 15) look.object_edge_rise_across_y_px = median(across_y);
  }
  look.jpeg_quality = jpeg_quality.value_or(0);
  return look;
}

nlohmann::json CameraLook::ToJson() const {
  nlohmann::json j;
  j["noise_variance_a"] = noise.a;
  j["noise_variance_b"] = noise.b;
  j["noise_blocks"] = noise.blocks;
  j["noise_sigma_at_128"] = {noise.Sigma(0, 128), noise.Sigma(1, 128), noise.Sigma(2, 128)};
  j["edge_rise_px"] = edge_width_px;
  j["edges"] = edges;
  j["object_edge_rise_px"] = object_edge_rise_px;
  j["object_edges"] = object_edges;
  j["object_edge_rise_across_x_px"] = object_edge_rise_across_x_px;
  j["object_edges_across_x"] = object_edges_across_x;
  j["object_edge_rise_across_y_px"] = object_edge_rise_across_y_px;
  j["object_edges_across_y"] = object_edges_across_y;
  j["jpeg_quality"] = jpeg_quality;
  return j;
}

std::string CameraLook::Summary() const {
  Msg m;
  m << "noise sigma at 128: " << Fixed(noise.Sigma(0, 128), 2) << "/" << Fixed(noise.Sigma(1, 128), 2) << "/"
    << Fixed(noise.Sigma(2, 128), 2) << " (" << noise.blocks << " flat blocks), edge rise "
    << (edge_width_px > 0 ? Fixed(edge_width_px, 2) + " px" : std::string("unknown")) << " (" << edges << " edges), on real objects "
    << (object_edge_rise_px > 0 ? Fixed(object_edge_rise_px, 2) + " px" : std::string("unknown")) << " (" << object_edges << " edges), JPEG "
    << (jpeg_quality > 0 ? "quality " + std::to_string(jpeg_quality) : std::string("none"));
  return m;
}

double ExtraBlurSigma(double from_px, double to_px) {
  if (to_px <= from_px || to_px <= 0) return 0;
  const double s_to = to_px / kRisePerSigma, s_from = from_px / kRisePerSigma;
  return std::sqrt(s_to * s_to - s_from * s_from);
}

int GaussianBlurReach(double sigma) { return sigma < 0.05 ? 0 : std::max(1, static_cast<int>(std::ceil(3 * sigma))); }

void GaussianBlurRegion(ImageF* image, double sigma, int x0, int y0, int x1, int y1) {
  const int r = GaussianBlurReach(sigma);
  if (r == 0) return;
  const int w = image->width(), h = image->height(), ch = image->channels();
  x0 = std::max(0, x0), y0 = std::max(0, y0), x1 = std::min(w, x1), y1 = std::min(h, y1);
  if (x1 <= x0 || y1 <= y0) return;
  std::vector<double> k(static_cast<size_t>(2 * r + 1));
  double sum = 0;
  for (int i = -r; i <= r; ++i) sum += k[static_cast<size_t>(i + r)] = std::exp(-0.5 * i * i / (sigma * sigma));
  for (double& v : k) v /= sum;
  // Horizontal pass over rows y0..y1 (plus r rows either side, which the vertical pass reads), then vertical. Each
  // pass runs its taps in the outer loop over a row of double sums, so the inner loop walks memory in order; every
  // output is still the sum over taps -r..r in that order, as a loop over taps per pixel would give.
  const int ry0 = std::max(0, y0 - r), ry1 = std::min(h, y1 + r);
  const int rw = x1 - x0;
  const size_t row_values = static_cast<size_t>(rw) * static_cast<size_t>(ch);
  ImageF tmp(rw, ry1 - ry0, ch, 0.0f);
  std::vector<double> acc(row_values);
  for (int y = ry0; y < ry1; ++y) {
    std::fill(acc.begin(), acc.end(), 0.0);
    const float* row = image->pixel(0, y);
    for (int i = -r; i <= r; ++i) {
      const double ki = k[static_cast<size_t>(i + r)];
      for (int x = x0; x < x1; ++x) {
        const float* src = row + static_cast<size_t>(std::clamp(x + i, 0, w - 1)) * static_cast<size_t>(ch);
        double* dst = &acc[static_cast<size_t>(x - x0) * static_cast<size_t>(ch)];
        for (int c = 0; c < ch; ++c) dst[c] += ki * src[c];
      }
    }
    float* out = tmp.pixel(0, y - ry0);
    for (size_t v = 0; v < row_values; ++v) out[v] = static_cast<float>(acc[v]);
  }
  // Rows outside [y0, y1) but within reach keep their own values outside [x0, x1): read those from the image.
  for (int y = y0; y < y1; ++y) {
    std::fill(acc.begin(), acc.end(), 0.0);
    for (int i = -r; i <= r; ++i) {
      const double ki = k[static_cast<size_t>(i + r)];
      const int yy = std::clamp(y + i, 0, h - 1);
      const float* src = yy >= ry0 && yy < ry1 ? tmp.pixel(0, yy - ry0) : image->pixel(x0, yy);
      for (size_t v = 0; v < row_values; ++v) acc[v] += ki * src[v];
    }
    float* out = image->pixel(x0, y);
    for (size_t v = 0; v < row_values; ++v) out[v] = static_cast<float>(acc[v]);
  }
}

void ApplySensorToInserts(ImageU8* image, const ImageF& alpha, const ImageF* shadow_noise, int x0, int y0, int x1, int y1,
                          const std::vector<std::array<int, 4>>& parts, const CameraLook& look,
                          const CameraLookOptions& options, uint64_t seed) {
  const int w = image->width(), h = image->height();
  x0 = std::max(0, x0), y0 = std::max(0, y0), x1 = std::min(w, x1), y1 = std::min(h, y1);
  if (x1 <= x0 || y1 <= y0) return;
  std::vector<std::array<int, 4>> rects;
  for (const auto& p : parts)
    if (std::max(x0, p[0]) < std::min(x1, p[2]) && std::max(y0, p[1]) < std::min(y1, p[3]))
      rects.push_back({std::max(x0, p[0]), std::max(y0, p[1]), std::min(x1, p[2]), std::min(y1, p[3])});
  if (parts.empty()) rects.push_back({x0, y0, x1, y1});
  const auto [ry0, ry1] = RowRange(rects, h);
  // The pixels of the parts in scan order, as a scan of the whole rectangle meets them: the noise streams see
  // the same pixels in the same order.
  const auto for_each_pixel = [&](const auto& f) {
    for (int y = ry0; y < ry1; ++y)
      for (const auto& [sx0, sx1] : RowSpans(rects, y, w))
        for (int x = sx0; x < sx1; ++x) f(x, y);
  };
  const ImageU8 before = *image;
  const bool jpeg = options.jpeg && look.jpeg_quality > 0;
  if (options.noise && look.noise.blocks > 0) {
    // Noise added before the compression is partly removed by it, as the camera's was: add what measures as the
    // image's noise after it.
    const double gain = jpeg ? PreCompressionGain(look.jpeg_quality, look.noise.Sigma(1, 128)) : 1.0;
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> unit(0.0, 1.0);
    for_each_pixel([&](int x, int y) {
      const float a = alpha.at(x, y);
      if (a <= 0) return;
      for (int c = 0; c < std::min(3, image->channels()); ++c) {
        const double v = image->at(x, y, c);
        const double n = unit(rng) * look.noise.Sigma(c, v) * gain;
        image->at(x, y, c) = static_cast<uint8_t>(std::clamp(std::lround(v + a * n), 0L, 255L));
      }
    });
  }
  if (jpeg) {
    // On the image's own 8x8 grid (16 x 16 with chroma subsampling), so the blocks fall where the camera's did.
    const int bx0 = (x0 / 16) * 16, by0 = (y0 / 16) * 16;
    const int bx1 = std::min(w, ((x1 + 15) / 16) * 16), by1 = std::min(h, ((y1 + 15) / 16) * 16);
    // One round trip per band of block rows and run of blocks along it that holds pixels of the parts, with one
    // block of context all round (within the grid above): blocks are coded independently, and all a block's
    // decoded pixels read of its neighbours is their chroma (the decoder's upsampling), so each inserted pixel
    // comes back as one round trip of the whole grid gives it. Every crop is taken before any pixel is blended
    // back: one's context may be another's pixels.
    constexpr int kBand = 128;  // rows; the context above and below costs a quarter of it
    struct RoundTrip {
      std::array<int, 4> own, crop;  // the pixels it blends back; the crop it is coded from
      ImageU8 image;
    };
    std::vector<RoundTrip> trips;
    long long coded = 0;
    for (int band = by0; band < by1; band += kBand) {
      const int band_end = std::min(by1, band + kBand);
      std::vector<std::pair<int, int>> runs;
      for (const auto& r : rects)
        if (r[1] < band_end && r[3] > band)
          runs.emplace_back(std::max(bx0, (r[0] / 16 - 1) * 16), std::min(bx1, ((r[2] + 15) / 16 + 1) * 16));
      std::sort(runs.begin(), runs.end());
      std::vector<std::pair<int, int>> merged;
      for (const auto& run : runs) {
        if (merged.empty() || run.first > merged.back().second) merged.push_back(run);
        else merged.back().second = std::max(merged.back().second, run.second);
      }
      for (const auto& [rx0, rx1] : merged) {
        const int cy0 = std::max(by0, band - 16), cy1 = std::min(by1, band_end + 16);
        trips.push_back({{rx0, band, rx1, band_end}, {rx0, cy0, rx1, cy1}, {}});
        coded += static_cast<long long>(rx1 - rx0) * (cy1 - cy0);
      }
    }
    // Parts that fill most of the grid cost more with their context than the grid in one.
    if (coded >= static_cast<long long>(bx1 - bx0) * (by1 - by0)) trips = {{{bx0, by0, bx1, by1}, {bx0, by0, bx1, by1}, {}}};
    // The round trips read the image and write only their own result: they go in parallel.
    ParallelForRethrow(0, trips.size(), [&](size_t i) {
      RoundTrip& t = trips[i];
      ImageU8 crop(t.crop[2] - t.crop[0], t.crop[3] - t.crop[1], 3);
      for (int y = t.crop[1]; y < t.crop[3]; ++y)
        for (int x = t.crop[0]; x < t.crop[2]; ++x)
          for (int c = 0; c < 3; ++c) crop.at(x - t.crop[0], y - t.crop[1], c) = image->at(x, y, c);
      t.image = DecodeImage(EncodeImage(crop, "jpg", look.jpeg_quality), "inserted pixels", 3);
    });
    for (const RoundTrip& t : trips)
      for (int y = t.own[1]; y < t.own[3]; ++y)
        for (const auto& [sx0, sx1] : RowSpans(rects, y, w))
          for (int x = std::max(sx0, t.own[0]); x < std::min(sx1, t.own[2]); ++x) {
            const float a = alpha.at(x, y);
            if (a <= 0) continue;
            for (int c = 0; c < 3; ++c) {
              const double v = a * t.image.at(x - t.crop[0], y - t.crop[1], c) + (1 - a) * before.at(x, y, c);
              image->at(x, y, c) = static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L));
            }
          }
  }
  if (options.noise && shadow_noise && look.noise.blocks > 0) {
    std::mt19937_64 rng(seed ^ 0x5DEECE66Dull);
    std::normal_distribution<double> unit(0.0, 1.0);
    for_each_pixel([&](int x, int y) {
      const float s = shadow_noise->at(x, y);
      if (s <= 0) return;
      for (int c = 0; c < std::min(3, image->channels()); ++c) {
        const double v = image->at(x, y, c);
        const double n = s * unit(rng) * look.noise.Sigma(c, v);
        image->at(x, y, c) = static_cast<uint8_t>(std::clamp(std::lround(v + n), 0L, 255L));
      }
    });
  }
}

double HsvSaturation(double r, double g, double b) {
  const double mx = std::max({r, g, b}), mn = std::min({r, g, b});
  return mx > 0 ? (mx - mn) / mx : 0.0;
}

double ImageSaturationCeiling(const ImageU8& image) {
  std::vector<double> s;
  for (int y = 0; y < image.height(); y += 2)
    for (int x = 0; x < image.width(); x += 2) {
      const uint8_t* p = image.pixel(x, y);
      if (std::max({p[0], p[1], p[2]}) > 40) s.push_back(HsvSaturation(p[0], p[1], p[2]));
    }
  if (s.empty()) return 0;
  const size_t k = static_cast<size_t>(0.995 * static_cast<double>(s.size() - 1));
  std::nth_element(s.begin(), s.begin() + static_cast<long>(k), s.end());
  return s[k];
}

double OutlineSaturation(std::vector<double> pixel_saturations) {
  if (pixel_saturations.empty()) return 0;
  const size_t k = static_cast<size_t>(0.9 * static_cast<double>(pixel_saturations.size() - 1));
  std::nth_element(pixel_saturations.begin(), pixel_saturations.begin() + static_cast<long>(k), pixel_saturations.end());
  return pixel_saturations[k];
}

SaturationCap CapSaturation(ImageF* linear, const ImageF& outline, const ImageF& weight, double ceiling, double min_scale) {
  SD_CHECK(linear->channels() == 3 && outline.width() == linear->width() && outline.height() == linear->height() &&
           weight.width() == linear->width() && weight.height() == linear->height());
  // The outline's pixels, with the insert's share of each; only those change.
  std::vector<OutlinePixel> pixels;
  for (int y = 0; y < linear->height(); ++y)
    for (int x = 0; x < linear->width(); ++x)
      if (outline.at(x, y) > 0.5f) pixels.push_back({x, y, weight.at(x, y)});
  return CapSaturation(linear, pixels, ceiling, min_scale);
}

SaturationCap CapSaturation(ImageF* linear, const std::vector<OutlinePixel>& outline, double ceiling, double min_scale) {
  SD_CHECK(linear->channels() == 3);
  using Pixel = OutlinePixel;
  std::vector<Pixel> pixels;
  pixels.reserve(outline.size());
  for (Pixel p : outline) {
    SD_CHECK(p.x >= 0 && p.y >= 0 && p.x < linear->width() && p.y < linear->height(), << p.x << "," << p.y);
    p.w = std::clamp(p.w, 0.0f, 1.0f);
    pixels.push_back(p);
  }
  SaturationCap cap;
  cap.ceiling = ceiling;
  if (pixels.empty()) return cap;
  const auto saturation = [](const std::array<double, 3>& c) {
    const auto srgb = [](double v) { return LinearToSrgb(static_cast<float>(std::clamp(v, 0.0, 1.0))); };
    return HsvSaturation(srgb(c[0]), srgb(c[1]), srgb(c[2]));
  };
  // The real pixels of the outline measure the same whatever k is: computed once.
  std::vector<double> fixed;
  std::vector<Pixel> inserted;
  for (const Pixel& p : pixels) {
    if (p.w > 0) inserted.push_back(p);
    else fixed.push_back(saturation({linear->at(p.x, p.y, 0), linear->at(p.x, p.y, 1), linear->at(p.x, p.y, 2)}));
  }
  // The bisection below measures the outline some 15 times; each time every inserted pixel's colour is moved
  // towards its luminance and converted to sRGB. The sRGB curve never falls, so the largest and smallest channel
  // in sRGB are those of the largest and smallest linear value: two conversions a pixel instead of three. The
  // pixels go in parallel, each into its own slot.
  std::vector<double> all;
  const auto saturation_at = [&](double k) {
    all.resize(fixed.size() + inserted.size());
    std::copy(fixed.begin(), fixed.end(), all.begin());
    double* out = all.data() + fixed.size();
    ParallelForRange(0, inserted.size(), 1024, [&](size_t begin, size_t end) {
      for (size_t i = begin; i < end; ++i) {
        const Pixel& p = inserted[i];
        std::array<double, 3> c{linear->at(p.x, p.y, 0), linear->at(p.x, p.y, 1), linear->at(p.x, p.y, 2)};
        const double luminance = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        float lo = 1.0f, hi = 0.0f;
        for (double& v : c) {
          v += p.w * (luminance + k * (v - luminance) - v);
          const float clamped = static_cast<float>(std::clamp(v, 0.0, 1.0));
          lo = std::min(lo, clamped), hi = std::max(hi, clamped);
        }
        const double mn = LinearToSrgb(lo);
        out[i] = HsvSaturation(LinearToSrgb(hi), mn, mn);
      }
    });
    return OutlineSaturation(all);
  };
  cap.before = cap.after = saturation_at(1.0);
  if (cap.before <= ceiling) return cap;
  // The outline's saturation falls as k does; bisect for the ceiling.
  double lo = min_scale, hi = 1.0;
  if (saturation_at(lo) < ceiling)
    for (int it = 0; it < 12; ++it) {  // k to 2e-4
      const double mid = 0.5 * (lo + hi);
      (saturation_at(mid) > ceiling ? hi : lo) = mid;
    }
  cap.scale = lo;
  for (const Pixel& p : inserted) {
    float* c = &linear->at(p.x, p.y, 0);
    const float luminance = LinearLuminance(c);
    for (int ch = 0; ch < 3; ++ch) c[ch] += p.w * static_cast<float>(luminance + cap.scale * (c[ch] - luminance) - c[ch]);
  }
  cap.after = saturation_at(1.0);
  return cap;
}

}  // namespace sd
