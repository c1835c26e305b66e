#include "synth/realism.h"

#include <algorithm>
#include <cmath>

#include "geometry/box_projection.h"
#include "geometry/polygon.h"

namespace sd {
namespace {

constexpr double kNearM = 0.5;

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

double Saturation(const uint8_t* p) {
  const double mx = std::max({p[0], p[1], p[2]}), mn = std::min({p[0], p[1], p[2]});
  return mx > 0 ? (mx - mn) / mx : 0.0;
}

}  // namespace

ObjectLook MeasureObjectLook(const ImageU8& image, const CameraSensor& camera, const Box3& box_ego, const CameraLook& look) {
  ObjectLook out;
  const auto in_image = geometry::ProjectBoxToImage(camera.intrinsics, camera.T_ego_cam.Inverse(), box_ego, kNearM);
  if (!in_image || in_image->clipped.Empty()) return out;
  const Box2& r = in_image->clipped;
  const int x0 = static_cast<int>(std::floor(r.x1)), y0 = static_cast<int>(std::floor(r.y1));
  const int x1 = std::min(image.width(), static_cast<int>(std::ceil(r.x2)));
  const int y1 = std::min(image.height(), static_cast<int>(std::ceil(r.y2)));
  ImageF mask(image.width(), image.height(), 1, 0.0f);
  double saturation = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x)
      if (geometry::InsideConvexPolygon(in_image->outline, {x + 0.5, y + 0.5})) {
        mask.at(x, y) = 1;
        saturation += Saturation(image.pixel(x, y));
        ++out.pixels;
      }
  if (out.pixels == 0) return out;
  out.saturation = saturation / out.pixels;

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
  const int w = camera.intrinsics.width, h = camera.intrinsics.height;
  ImageF mask(w, h, 1, 0.0f);
  for (const Box3& box : boxes_ego) {
    const auto in_image = geometry::ProjectBoxToImage(camera.intrinsics, camera.T_ego_cam.Inverse(), box, kNearM);
    if (!in_image || in_image->clipped.Area() < min_pixels) continue;
    const Box2& r = in_image->clipped;
    for (int y = static_cast<int>(r.y1); y < std::min(h, static_cast<int>(std::ceil(r.y2))); ++y)
      for (int x = static_cast<int>(r.x1); x < std::min(w, static_cast<int>(std::ceil(r.x2))); ++x)
        if (geometry::InsideConvexPolygon(in_image->outline, {x + 0.5, y + 0.5})) mask.at(x, y) = 1;
  }
  return mask;
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

}  // namespace sd
