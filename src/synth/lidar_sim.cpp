#include "synth/lidar_sim.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <random>

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

// Azimuth / elevation bounds of the mesh seen from `origin` (the sensor's position in the mesh's frame).
AngularBounds BoundsOf(const TriangleMesh& mesh_lidar, const Eigen::Vector3f& origin = Eigen::Vector3f::Zero()) {
  AngularBounds b;
  const AlignedBox3f box = mesh_lidar.Bounds();
  const Eigen::Vector3f c = box.Center() - origin;
  b.az_center = std::atan2(c.y(), c.x());
  b.el_min = 1e9;
  b.el_max = -1e9;
  for (const auto& v : mesh_lidar.positions) {
    const Eigen::Vector3f p = v - origin;
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
        const BoxContainment inside(box, 0.05);
        for (size_t i = 0; i < points_ego.size(); ++i)
          if (inside.Contains(points_ego[i])) vals.push_back(sweep.feature(i, fi));
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

std::pair<Rigid3d, Rigid3d> ConstantVelocitySweepPoses(const Eigen::Vector3d& v_ego, double yaw_rate, double period,
                                                       double reference_time) {
  // Pose of the ego at time t relative to the ego at time 0 (constant body velocity and yaw rate).
  auto at = [&](double t) {
    const double yaw = yaw_rate * t;
    Eigen::Vector3d p;
    if (std::abs(yaw_rate) < 1e-9) {
      p = v_ego * t;
    } else {
      // Integral of R(yaw_rate s) v ds over [0, t], rotation about z.
      const double s = std::sin(yaw), c = std::cos(yaw);
      p = Eigen::Vector3d((v_ego.x() * s - v_ego.y() * (1 - c)) / yaw_rate, (v_ego.x() * (1 - c) + v_ego.y() * s) / yaw_rate,
                          v_ego.z() * t);
    }
    return Rigid3d::FromYaw(yaw, p);
  };
  const Rigid3d T_ref_0 = at(reference_time).Inverse();
  return {T_ref_0 * at(0.0), T_ref_0 * at(period)};
}

std::pair<Rigid3d, Rigid3d> SweepPosesFromEgoPoses(const Rigid3d& T_world_ego_ref, const Rigid3d& T_world_ego_a, double t_a,
                                                   const Rigid3d& T_world_ego_b, double t_b, double period,
                                                   double reference_time) {
  SD_CHECK(t_b != t_a, << "two ego poses at the same time");
  const Rigid3d T_ref_a = T_world_ego_ref.Inverse() * T_world_ego_a;
  const Rigid3d T_ref_b = T_world_ego_ref.Inverse() * T_world_ego_b;
  const double dt = t_b - t_a;
  const Eigen::Vector3d v_ego = (T_ref_b.translation - T_ref_a.translation) / dt;
  const double yaw_rate = std::remainder(T_ref_b.Yaw() - T_ref_a.Yaw(), 2 * M_PI) / dt;
  return ConstantVelocitySweepPoses(v_ego, yaw_rate, period, reference_time);
}

namespace {

bool IsIdentity(const Rigid3d& T) {
  return T.rotation.w() == 1.0 && T.rotation.x() == 0.0 && T.rotation.y() == 0.0 && T.rotation.z() == 0.0 &&
         T.translation.isZero(0.0);
}

// One LiDAR ray: direction in the sensor frame at its firing time, and that sensor's pose in the reference
// LiDAR frame.
struct Ray {
  Eigen::Vector3f dir_sensor;
  Rigid3d T_ref_sensor;
  bool static_pose = true;  // T_ref_sensor is exactly the identity
  // Where set, the ray's direction in the reference frame (a real return of a de-skewed sweep: from the
  // sensor's position at firing time through the recorded point); else T_ref_sensor.rotation * dir_sensor.
  bool has_dir_ref = false;
  Eigen::Vector3f dir_ref = Eigen::Vector3f::Zero();
};

struct RayReturn {
  LidarReturn ret;
  Eigen::Vector3f origin = Eigen::Vector3f::Zero(), dir = Eigen::Vector3f::Zero();  // reference LiDAR frame
};

// The rays from their own origins (render/lidar_cast.h), each return kept with its origin and direction.
std::vector<RayReturn> CastRays(const RayScene& scene, const std::vector<Ray>& rays, float max_range) {
  std::vector<Eigen::Vector3f> origins(rays.size()), dirs(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    if (rays[i].static_pose) {
      origins[i] = Eigen::Vector3f::Zero();
      dirs[i] = rays[i].dir_sensor;
    } else {
      origins[i] = rays[i].T_ref_sensor.translation.cast<float>();
      dirs[i] = rays[i].has_dir_ref ? rays[i].dir_ref
                                    : Eigen::Vector3f((rays[i].T_ref_sensor.rotation.cast<float>() * rays[i].dir_sensor).normalized());
    }
  }
  std::vector<LidarReturn> returns = CastLidarRays(scene, origins, dirs, max_range);
  std::vector<RayReturn> out(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) out[i] = {returns[i], origins[i], dirs[i]};
  return out;
}

}  // namespace

LidarSimResult SimulateLidar(const LidarSimInput& input) {
  SD_CHECK(input.sweep != nullptr);
  const PointCloud& sweep = *input.sweep;
  const LidarRealism& re = input.realism;
  SD_CHECK(re.model != nullptr || !(re.noise || re.dropout || re.intensity || re.ego_motion),
           << "LidarRealism switches need a fitted LidarModel");
  LidarSimResult result;
  result.cloud = sweep;
  result.points_on_object.assign(input.objects.size(), 0);
  if (input.objects.empty()) return result;

  // Objects in the LiDAR frame; their angular bounds as each sensor sees them.
  const Rigid3d T_lidar_ego = input.T_ego_lidar.Inverse();
  const bool several_sensors = input.sensor_feature >= 0 && !input.T_lidar_sensors.empty();
  SD_CHECK(!several_sensors || input.sensor_feature < sweep.num_features, << "sensor feature " << input.sensor_feature);
  SD_CHECK(!several_sensors || !re.ego_motion, << "ego motion is modelled for one spinning sensor only");
  std::vector<Eigen::Vector3f> sensor_origins = {Eigen::Vector3f::Zero()};
  if (several_sensors) {
    sensor_origins.clear();
    for (const Rigid3d& T : input.T_lidar_sensors) sensor_origins.push_back(T.translation.cast<float>());
  }
  RayScene scene;
  std::vector<std::vector<AngularBounds>> bounds_by_sensor(sensor_origins.size());
  double nearest_vertex = 1e9;
  for (const PlacedObject* o : input.objects) {
    auto mesh = std::make_shared<TriangleMesh>(o->asset->mesh);
    mesh->Transform(T_lidar_ego * o->T_ego_asset);
    for (size_t s = 0; s < sensor_origins.size(); ++s) bounds_by_sensor[s].push_back(BoundsOf(*mesh, sensor_origins[s]));
    for (const auto& p : mesh->positions) nearest_vertex = std::min(nearest_vertex, static_cast<double>(p.norm()));
    scene.AddMesh(mesh);
  }
  scene.Commit();
  const std::vector<AngularBounds>& bounds = bounds_by_sensor[0];
  // The sensor a real return came from (0 with one sensor); out-of-range indices are the file's problem, read as 0.
  auto sensor_of = [&](size_t i) -> size_t {
    if (!several_sensors) return 0;
    const float f = sweep.feature(i, input.sensor_feature);
    return f >= 0 && f < static_cast<float>(sensor_origins.size()) ? static_cast<size_t>(f) : 0;
  };

  // Sensor pose at a beam's firing time, in the reference LiDAR frame.
  const bool moving = re.ego_motion && !(IsIdentity(re.T_ref_ego_start) && IsIdentity(re.T_ref_ego_end));
  auto make_ray = [&](const Eigen::Vector3f& dir_sensor) {
    Ray ray;
    ray.dir_sensor = dir_sensor;
    if (!moving) return ray;
    const double s = std::clamp(re.model->FiringTime(std::atan2(dir_sensor.y(), dir_sensor.x())) / re.model->SweepPeriod(), 0.0, 1.0);
    ray.T_ref_sensor = T_lidar_ego * Interpolate(re.T_ref_ego_start, re.T_ref_ego_end, s) * input.T_ego_lidar;
    ray.static_pose = false;
    return ray;
  };

  const int fi = sweep.num_features > 3 ? 3 : -1;
  float max_intensity = 0;
  if (fi >= 0)
    for (size_t i = 0; i < sweep.size(); ++i) max_intensity = std::max(max_intensity, sweep.feature(i, fi));
  auto intensity = [&](int object, float cos_incidence) {
    if (re.intensity) return re.model->Intensity(input.objects[object]->asset->info.category, cos_incidence);
    const float v = input.reference_intensity.empty() ? 0.0f : input.reference_intensity[object] * cos_incidence / 0.7f;
    return std::clamp(v, 0.0f, max_intensity > 0 ? max_intensity : v);
  };
  // Noise, dropout and the stored point of a return (see the header: raw sensor frame or reference frame).
  std::mt19937_64 rng(re.seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  auto dropped = [&](const LidarReturn& h) { return re.dropout && uniform(rng) < re.model->DropoutProbability(h.range); };
  auto stored_point = [&](const Ray& ray, const RayReturn& rr) -> Eigen::Vector3f {
    if (!re.noise && ray.static_pose) return rr.ret.point;
    float range = rr.ret.range;
    if (re.noise) range = std::max(0.0f, range + static_cast<float>(re.model->RangeSigma(range) * gauss(rng)));
    if (re.motion_compensated_output || several_sensors) return rr.origin + range * rr.dir;
    return range * ray.dir_sensor;
  };

  double pad = 0.01;  // radians around each object's angular bounds
  if (moving) {
    const double shift = std::max(re.T_ref_ego_start.translation.norm(), re.T_ref_ego_end.translation.norm());
    const double turn = std::max(re.T_ref_ego_start.rotation.angularDistance(Eigen::Quaterniond::Identity()),
                                 re.T_ref_ego_end.rotation.angularDistance(Eigen::Quaterniond::Identity()));
    pad += shift / std::max(0.5, nearest_vertex) + turn;
  }
  auto near_any_object = [&](double az, double el, size_t sensor) {
    for (const auto& b : bounds_by_sensor[sensor])
      if (b.Contains(az, el, pad)) return true;
    return false;
  };

  // 1. Real returns.
  std::vector<int> candidates;
  std::vector<Ray> rays;
  for (size_t i = 0; i < sweep.size(); ++i) {
    const size_t sensor = sensor_of(i);
    const Eigen::Vector3f p = sweep.xyz(i), q = p - sensor_origins[sensor];  // q: from the point's own sensor
    const double r = q.norm();
    if (r < 0.5) continue;
    if (!near_any_object(std::atan2(q.y(), q.x()), std::atan2(q.z(), std::hypot(q.x(), q.y())), sensor)) continue;
    candidates.push_back(static_cast<int>(i));
    if (several_sensors) {
      // Static sensors away from the sweep's origin: the ray runs from the point's sensor through the point, and
      // the moved point is stored where the ray meets the object, in the sweep's frame.
      Ray ray;
      ray.T_ref_sensor = input.T_lidar_sensors[sensor];
      ray.static_pose = false;
      ray.has_dir_ref = true;
      ray.dir_ref = q / static_cast<float>(r);
      ray.dir_sensor = (ray.T_ref_sensor.rotation.inverse().cast<float>() * ray.dir_ref).normalized();
      rays.push_back(ray);
      continue;
    }
    Ray ray = make_ray(p / static_cast<float>(r));
    if (!ray.static_pose && re.motion_compensated_output) {
      // The recorded point is in the reference frame; the beam came from the sensor at its firing time.
      const Eigen::Vector3f o = ray.T_ref_sensor.translation.cast<float>();
      ray.dir_ref = (p - o).normalized();
      ray.has_dir_ref = true;
      ray.dir_sensor = (ray.T_ref_sensor.rotation.inverse().cast<float>() * ray.dir_ref).normalized();
    }
    rays.push_back(ray);
  }
  const auto hits = CastRays(scene, rays, input.max_range);
  std::vector<char> remove(sweep.size(), 0);
  for (size_t k = 0; k < candidates.size(); ++k) {
    const int i = candidates[k];
    const auto& h = hits[k].ret;
    const float recorded = rays[k].has_dir_ref ? (sweep.xyz(i) - hits[k].origin).norm() : sweep.xyz(i).norm();
    if (!h.hit || h.range >= recorded - 0.02f) continue;
    if (dropped(h)) {
      remove[i] = 1;
      ++result.dropped;
      continue;
    }
    result.cloud.xyz(i) = stored_point(rays[k], hits[k]);
    if (fi >= 0) result.cloud.feature(i, fi) = intensity(h.mesh, h.cos_incidence);
    ++result.moved;
    ++result.points_on_object[h.mesh];
    result.object_points.push_back({i, h.mesh});
  }

  // 2. Beams with no return, recovered from the ring pattern.
  const int ring_f = sweep.FeatureIndex("ring");
  if (ring_f >= 0 && !several_sensors) {
    std::map<int, std::vector<std::pair<double, double>>> rings;  // ring -> (azimuth, elevation)
    for (size_t i = 0; i < sweep.size(); ++i) {
      const Eigen::Vector3f p = sweep.xyz(i);
      rings[static_cast<int>(sweep.feature(i, ring_f))].push_back(
          {std::atan2(p.y(), p.x()), std::atan2(p.z(), std::hypot(p.x(), p.y()))});
    }
    std::vector<Ray> new_rays;
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
          new_rays.push_back(make_ray(Eigen::Vector3f(static_cast<float>(std::cos(el) * std::cos(a)),
                                                      static_cast<float>(std::cos(el) * std::sin(a)), static_cast<float>(std::sin(el)))));
          new_ring.push_back(ring);
        }
      }
    }
    const auto new_hits = CastRays(scene, new_rays, input.max_range);
    std::vector<float> record(sweep.num_features, 0.0f);
    for (size_t k = 0; k < new_rays.size(); ++k) {
      const auto& h = new_hits[k].ret;
      if (!h.hit) continue;
      if (dropped(h)) {
        ++result.dropped;
        continue;
      }
      const Eigen::Vector3f q = stored_point(new_rays[k], new_hits[k]);
      record[0] = q.x();
      record[1] = q.y();
      record[2] = q.z();
      if (fi >= 0) record[fi] = intensity(h.mesh, h.cos_incidence);
      record[ring_f] = static_cast<float>(new_ring[k]);
      result.object_points.push_back({static_cast<int>(result.cloud.size()), h.mesh});
      result.cloud.Append(record.data());
      ++result.added;
      ++result.points_on_object[h.mesh];
    }
  }

  // Real returns whose simulated return dropped out leave the cloud; indices shift.
  if (std::find(remove.begin(), remove.end(), 1) != remove.end()) {
    const int nf = sweep.num_features;
    std::vector<int> new_index(result.cloud.size(), -1);
    std::vector<float> data;
    data.reserve(result.cloud.data.size());
    int next = 0;
    for (size_t i = 0; i < result.cloud.size(); ++i) {
      if (i < remove.size() && remove[i]) continue;
      new_index[i] = next++;
      data.insert(data.end(), result.cloud.data.begin() + static_cast<long>(i * nf),
                  result.cloud.data.begin() + static_cast<long>((i + 1) * nf));
    }
    result.cloud.data = std::move(data);
    for (auto& [i, k] : result.object_points) i = new_index[i];
  }
  SD_LOG(Debug, "lidar: moved " << result.moved << " returns onto objects, added " << result.added
                                << " from empty beams, dropped " << result.dropped);
  return result;
}

}  // namespace sd
