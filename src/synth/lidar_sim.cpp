#include "synth/lidar_sim.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>

#include "core/log.h"
#include "datasets/categories.h"
#include "render/lidar_cast.h"
#include "render/ray_scene.h"

namespace sd {
namespace {

float Median(std::vector<float> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

struct AngularBounds {
  double az_center = 0, az_half = 0;  // radians
  double el_min = 0, el_max = 0;
  bool Contains(double az, double el, double pad) const {
    const double daz = std::remainder(az - az_center, 2 * M_PI);
    return std::abs(daz) <= az_half + pad && el >= el_min - pad && el <= el_max + pad;
  }
};

AngularBounds BoundsOf(const TriangleMesh& mesh_lidar) {
  AngularBounds b;
  const AlignedBox3f box = mesh_lidar.Bounds();
  const Eigen::Vector3f c = box.Center();
  b.az_center = std::atan2(c.y(), c.x());
  b.el_min = 1e9;
  b.el_max = -1e9;
  for (const auto& p : mesh_lidar.positions) {
    const double az = std::atan2(p.y(), p.x());
    b.az_half = std::max(b.az_half, std::abs(std::remainder(az - b.az_center, 2 * M_PI)));
    const double el = std::atan2(p.z(), std::hypot(p.x(), p.y()));
    b.el_min = std::min(b.el_min, el);
    b.el_max = std::max(b.el_max, el);
  }
  return b;
}

}  // namespace

std::vector<float> ReferenceIntensities(const PointCloud& sweep, const std::vector<Eigen::Vector3d>& points_ego,
                                        const std::vector<int>& ground_indices,
                                        const std::vector<std::pair<std::string, Box3>>& annotated,
                                        const std::vector<const PlacedObject*>& objects) {
  const int fi = sweep.num_features > 3 ? 3 : -1;
  std::vector<float> out(objects.size(), 0.0f);
  if (fi < 0) return out;
  std::vector<float> ground;
  for (int i : ground_indices) ground.push_back(sweep.feature(i, fi));
  const float ground_ref = ground.empty() ? 10.0f : Median(ground);
  std::map<std::string, float> by_category;
  for (size_t k = 0; k < objects.size(); ++k) {
    const std::string& cat = objects[k]->asset->info.category;
    if (!by_category.count(cat)) {
      std::vector<float> vals;
      for (const auto& [name, box] : annotated) {
        const auto info = FindCategory(name);
        if (!info || info->name != cat) continue;
        for (size_t i = 0; i < points_ego.size(); ++i)
          if (box.Contains(points_ego[i], 0.05)) vals.push_back(sweep.feature(i, fi));
      }
      if (vals.size() >= 10) {
        by_category[cat] = Median(vals);
      } else {
        const auto info = FindCategory(cat);
        by_category[cat] = ground_ref * static_cast<float>(info ? info->lidar_reflectivity : 1.0);
      }
    }
    out[k] = by_category[cat];
  }
  return out;
}

LidarSimResult SimulateLidar(const LidarSimInput& input) {
  SD_CHECK(input.sweep != nullptr);
  const PointCloud& sweep = *input.sweep;
  LidarSimResult result;
  result.cloud = sweep;
  result.points_on_object.assign(input.objects.size(), 0);
  if (input.objects.empty()) return result;

  // Objects in the LiDAR frame.
  const Rigid3d T_lidar_ego = input.T_ego_lidar.Inverse();
  RayScene scene;
  std::vector<AngularBounds> bounds;
  for (const PlacedObject* o : input.objects) {
    auto mesh = std::make_shared<TriangleMesh>(o->asset->mesh);
    mesh->Transform(T_lidar_ego * o->T_ego_asset);
    bounds.push_back(BoundsOf(*mesh));
    scene.AddMesh(mesh);
  }
  scene.Commit();

  const int fi = sweep.num_features > 3 ? 3 : -1;
  float max_intensity = 0;
  if (fi >= 0)
    for (size_t i = 0; i < sweep.size(); ++i) max_intensity = std::max(max_intensity, sweep.feature(i, fi));
  auto intensity = [&](int object, float cos_incidence) {
    const float v = input.reference_intensity.empty() ? 0.0f : input.reference_intensity[object] * cos_incidence / 0.7f;
    return std::clamp(v, 0.0f, max_intensity > 0 ? max_intensity : v);
  };
  const double pad = 0.01;  // radians around each object's angular bounds
  auto near_any_object = [&](double az, double el) {
    for (const auto& b : bounds)
      if (b.Contains(az, el, pad)) return true;
    return false;
  };

  // 1. Real returns.
  std::vector<int> candidates;
  std::vector<Eigen::Vector3f> dirs;
  for (size_t i = 0; i < sweep.size(); ++i) {
    const Eigen::Vector3f p = sweep.xyz(i);
    const double r = p.norm();
    if (r < 0.5) continue;
    if (!near_any_object(std::atan2(p.y(), p.x()), std::atan2(p.z(), std::hypot(p.x(), p.y())))) continue;
    candidates.push_back(static_cast<int>(i));
    dirs.push_back(p / static_cast<float>(r));
  }
  const auto hits = CastLidarRays(scene, Eigen::Vector3f::Zero(), dirs, input.max_range);
  for (size_t k = 0; k < candidates.size(); ++k) {
    const int i = candidates[k];
    const auto& h = hits[k];
    if (!h.hit || h.range >= sweep.xyz(i).norm() - 0.02f) continue;
    result.cloud.xyz(i) = h.point;
    if (fi >= 0) result.cloud.feature(i, fi) = intensity(h.mesh, h.cos_incidence);
    ++result.moved;
    ++result.points_on_object[h.mesh];
    result.object_points.push_back({i, h.mesh});
  }

  // 2. Beams with no return, recovered from the ring pattern.
  const int ring_f = sweep.FeatureIndex("ring");
  if (ring_f >= 0) {
    std::map<int, std::vector<std::pair<double, double>>> rings;  // ring -> (azimuth, elevation)
    for (size_t i = 0; i < sweep.size(); ++i) {
      const Eigen::Vector3f p = sweep.xyz(i);
      rings[static_cast<int>(sweep.feature(i, ring_f))].push_back(
          {std::atan2(p.y(), p.x()), std::atan2(p.z(), std::hypot(p.x(), p.y()))});
    }
    std::vector<Eigen::Vector3f> new_dirs;
    std::vector<int> new_ring;
    for (auto& [ring, pts] : rings) {
      if (pts.size() < 100) continue;
      std::vector<double> els;
      for (const auto& p : pts) els.push_back(p.second);
      std::nth_element(els.begin(), els.begin() + els.size() / 2, els.end());
      const double el = els[els.size() / 2];
      std::sort(pts.begin(), pts.end());
      std::vector<double> gaps;
      for (size_t i = 1; i < pts.size(); ++i) {
        const double g = pts[i].first - pts[i - 1].first;
        if (g > 1e-5) gaps.push_back(g);
      }
      if (gaps.empty()) continue;
      std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
      const double step = gaps[gaps.size() / 2];
      for (const auto& b : bounds) {
        if (el < b.el_min - pad || el > b.el_max + pad) continue;
        for (double az = b.az_center - b.az_half - pad; az <= b.az_center + b.az_half + pad; az += step) {
          const double a = std::remainder(az, 2 * M_PI);
          // Skip slots that hold a real return (cast above).
          auto it = std::lower_bound(pts.begin(), pts.end(), std::make_pair(a - 0.5 * step, -1e9));
          if (it != pts.end() && it->first <= a + 0.5 * step) continue;
          new_dirs.emplace_back(static_cast<float>(std::cos(el) * std::cos(a)), static_cast<float>(std::cos(el) * std::sin(a)),
                                static_cast<float>(std::sin(el)));
          new_ring.push_back(ring);
        }
      }
    }
    const auto new_hits = CastLidarRays(scene, Eigen::Vector3f::Zero(), new_dirs, input.max_range);
    std::vector<float> record(sweep.num_features, 0.0f);
    for (size_t k = 0; k < new_dirs.size(); ++k) {
      const auto& h = new_hits[k];
      if (!h.hit) continue;
      record[0] = h.point.x();
      record[1] = h.point.y();
      record[2] = h.point.z();
      if (fi >= 0) record[fi] = intensity(h.mesh, h.cos_incidence);
      record[ring_f] = static_cast<float>(new_ring[k]);
      result.object_points.push_back({static_cast<int>(result.cloud.size()), h.mesh});
      result.cloud.Append(record.data());
      ++result.added;
      ++result.points_on_object[h.mesh];
    }
  }
  SD_LOG(Debug, "lidar: moved " << result.moved << " returns onto objects, added " << result.added << " from empty beams");
  return result;
}

}  // namespace sd
