#include "synth/lidar_model.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <tuple>

#include <Eigen/Dense>

#include "core/error.h"
#include "core/stats.h"
#include "datasets/categories.h"

namespace sd {
namespace {

constexpr double kTwoPi = 2 * M_PI;

double RobustSigma(const std::vector<double>& v) {
  const double m = Median(v);
  std::vector<double> dev;
  dev.reserve(v.size());
  for (double x : v) dev.push_back(std::abs(x - m));
  return 1.4826 * Median(dev);
}

// Angle in [0, 2 pi).
double Wrap2Pi(double a) {
  a = std::fmod(a, kTwoPi);
  return a < 0 ? a + kTwoPi : a;
}

// z = a * h + b, least squares with two rounds of outlier rejection (3 robust sigmas, at least 2 cm).
std::pair<double, double> RobustLine(const std::vector<double>& h, const std::vector<double>& z) {
  std::vector<char> use(h.size(), 1);
  double a = 0, b = 0;
  for (int round = 0; round < 3; ++round) {
    double sh = 0, sz = 0, shh = 0, shz = 0, n = 0;
    for (size_t i = 0; i < h.size(); ++i) {
      if (!use[i]) continue;
      sh += h[i], sz += z[i], shh += h[i] * h[i], shz += h[i] * z[i], n += 1;
    }
    const double det = n * shh - sh * sh;
    if (n < 2 || std::abs(det) < 1e-12) break;
    a = (n * shz - sh * sz) / det;
    b = (sz - a * sh) / n;
    std::vector<double> res(h.size());
    for (size_t i = 0; i < h.size(); ++i) res[i] = z[i] - a * h[i] - b;
    const double tol = std::max(0.02, 3.0 * RobustSigma(res));
    for (size_t i = 0; i < h.size(); ++i) use[i] = std::abs(res[i]) <= tol;
  }
  return {a, b};
}

// Least-squares plane n . p = d through points (n unit, n.z >= 0).
bool FitPlane(const std::vector<Eigen::Vector3d>& pts, Eigen::Vector3d* n, double* d) {
  if (pts.size() < 3) return false;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : pts) c += p;
  c /= static_cast<double>(pts.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : pts) cov += (p - c) * (p - c).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  *n = es.eigenvectors().col(0);
  if (n->z() < 0) *n = -*n;
  *d = n->dot(c);
  return true;
}

int TimeFeature(const PointCloud& sweep) {
  for (const char* name : {"time", "timestamp", "offset_ns", "t"}) {
    const int f = sweep.FeatureIndex(name);
    if (f >= 3) return f;
  }
  return -1;
}

int IntensityFeature(const PointCloud& sweep) {
  for (const char* name : {"intensity", "reflectance"}) {
    const int f = sweep.FeatureIndex(name);
    if (f >= 3) return f;
  }
  return -1;
}

}  // namespace

double LidarModel::FiringTime(double azimuth) const {
  const double frac = Wrap2Pi(spin_direction * (azimuth - start_azimuth)) / kTwoPi;
  return frac * SweepPeriod();
}

double LidarModel::DropoutProbability(double range) const {
  if (dropout_probability.empty()) return 0;
  for (size_t k = 0; k < dropout_probability.size(); ++k)
    if (range < dropout_range_edges[k + 1]) return dropout_probability[k];
  return dropout_probability.back();
}

float LidarModel::Intensity(const std::string& category, double cos_incidence) const {
  double refl = ground_reflectivity;
  auto it = category_reflectivity.find(category);
  if (it == category_reflectivity.end()) it = category_reflectivity.find(CanonicalCategory(category));
  if (it != category_reflectivity.end()) {
    refl = it->second;
  } else {
    const auto info = FindCategory(category);
    refl = ground_reflectivity * (info ? info->lidar_reflectivity : 1.0);
  }
  const double v = refl * std::pow(std::clamp(cos_incidence, 0.0, 1.0), intensity_exponent);
  return static_cast<float>(std::clamp(v, 0.0, intensity_max > 0 ? static_cast<double>(intensity_max) : v));
}

std::string LidarModel::Summary() const {
  std::ostringstream os;
  os.precision(4);
  os << beams.size() << " lasers" << (rings_from_feature ? " (ring feature)" : " (inferred)");
  if (!beams.empty())
    os << ", elevation " << beams.front().elevation * 180 / M_PI << ".." << beams.back().elevation * 180 / M_PI << " deg";
  os << ", azimuth step " << azimuth_step * 180 / M_PI << " deg (" << firings_per_revolution << " firings/rev), "
     << spin_hz << " Hz " << (spin_direction > 0 ? "ccw" : "cw") << (timing_from_data ? " (measured)" : "")
     << "; range sigma " << noise_sigma0 << " + " << noise_sigma_slope << " r m (" << noise_samples << " samples); dropout";
  for (size_t k = 0; k < dropout_probability.size(); ++k)
    os << " [" << dropout_range_edges[k] << "," << dropout_range_edges[k + 1] << "):" << dropout_probability[k];
  os << "; intensity cos^" << intensity_exponent << " (rms log " << intensity_rms_log << ", Lambertian "
     << intensity_rms_log_lambertian << "), ground " << ground_reflectivity;
  for (const auto& [c, r] : category_reflectivity) os << ", " << c << " " << r;
  return os.str();
}

LidarModel FitLidarModel(const PointCloud& sweep, const LidarFitOptions& options) {
  const size_t n = sweep.size();
  if (n < 1000) throw InputError({}, Msg() << "LiDAR model fit: the sweep has " << n << " points; at least 1000 are needed");
  LidarModel model;

  std::vector<char> valid(n, 0);
  std::vector<double> az(n, 0), range(n, 0), horiz(n, 0);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d p = sweep.xyz(i).cast<double>();
    range[i] = p.norm();
    horiz[i] = std::hypot(p.x(), p.y());
    az[i] = std::atan2(p.y(), p.x());
    valid[i] = std::isfinite(range[i]) && range[i] >= options.min_range;
  }

  // 1. Laser of every record.
  std::vector<int> laser(n, -1);
  int ring_f = sweep.FeatureIndex("ring");
  if (ring_f < 3) ring_f = sweep.FeatureIndex("laser_number");
  if (ring_f >= 3) {
    model.rings_from_feature = true;
    for (size_t i = 0; i < n; ++i) laser[i] = static_cast<int>(std::lround(sweep.feature(i, ring_f)));
  } else {
    // Scan lines stored one after another: count full turns of the unwrapped azimuth along the records.
    double cum = 0, prev = NAN;
    std::vector<double> cums(n, NAN);
    for (size_t i = 0; i < n; ++i) {
      if (!valid[i]) continue;
      if (!std::isnan(prev)) cum += std::remainder(az[i] - prev, kTwoPi);
      prev = az[i];
      cums[i] = cum;
    }
    const double sign = cum < 0 ? -1.0 : 1.0;
    const double margin = 1.0 * M_PI / 180;  // scan lines start within a degree of each other
    for (size_t i = 0; i < n; ++i)
      if (valid[i]) laser[i] = static_cast<int>(std::floor((sign * cums[i] + margin) / kTwoPi));
  }

  // 2. Per laser: cone fit, azimuth step, firing position.
  std::map<int, std::vector<size_t>> by_laser;
  std::map<int, size_t> first_record;
  for (size_t i = 0; i < n; ++i) {
    if (laser[i] < 0) continue;
    if (!first_record.count(laser[i])) first_record[laser[i]] = i;
    if (valid[i]) by_laser[laser[i]].push_back(i);
  }
  std::vector<std::pair<size_t, int>> firsts;
  for (const auto& [l, i] : first_record) firsts.push_back({i, l});
  std::sort(firsts.begin(), firsts.end());
  std::map<int, int> firing_rank;
  for (size_t k = 0; k < firsts.size(); ++k) firing_rank[firsts[k].second] = static_cast<int>(k);

  // Two models per laser: a cone with its apex at the origin (elevation = median angle), or a cone with its
  // own apex on the axis (line fit z = tan(el) h + z0). Raw (not de-skewed) sweeps lie on offset cones
  // exactly (KITTI: residual ~0, apexes 0.12-0.2 m); motion-compensated ones (nuScenes, AV2) do not, and a
  // free apex fitted over a narrow distance band (steep lasers that see only the ground) is badly biased.
  // So: when most lasers that see a wide distance band (>= 2 m) lie on an offset cone (robust residual < 5 mm
  // and 3x below the origin model), those keep their fit and the others take the apex of the exact laser
  // nearest in elevation; otherwise every laser uses the origin model.
  struct Fit {
    LidarBeam beam;
    double raw = 0, a = 0, b = 0;
    bool wide = false, exact = false;
    std::vector<double> h, z;
  };
  std::vector<Fit> fits;
  std::map<int, double> laser_step;
  for (auto& [l, idx] : by_laser) {
    if (idx.size() < 100) continue;
    Fit f;
    std::vector<double> raw;
    for (size_t i : idx)
      if (horiz[i] >= 2.0) f.h.push_back(horiz[i]), f.z.push_back(sweep.xyz(i).z()), raw.push_back(std::atan2(f.z.back(), f.h.back()));
    if (f.h.size() < 50) continue;
    f.raw = Median(raw);
    std::vector<double> hs = f.h;
    std::sort(hs.begin(), hs.end());
    f.wide = hs[hs.size() * 9 / 10] - hs[hs.size() / 10] >= 2.0;
    std::tie(f.a, f.b) = RobustLine(f.h, f.z);
    std::vector<double> res_origin(f.h.size()), res_free(f.h.size());
    for (size_t k = 0; k < f.h.size(); ++k) {
      res_origin[k] = f.z[k] - std::tan(f.raw) * f.h[k];
      res_free[k] = f.z[k] - f.a * f.h[k] - f.b;
    }
    const double sigma_free = RobustSigma(res_free);
    f.exact = f.wide && sigma_free < 0.005 && sigma_free < 0.3 * RobustSigma(res_origin);
    LidarBeam& beam = f.beam;
    beam.laser = l;
    beam.elevation = f.raw;
    beam.firing_position = model.rings_from_feature ? firing_rank[l] : -1;
    beam.returns = static_cast<int>(idx.size());
    std::vector<double> azs;
    for (size_t i : idx) azs.push_back(az[i]);
    std::sort(azs.begin(), azs.end());
    std::vector<double> gaps;
    for (size_t k = 1; k < azs.size(); ++k)
      if (azs[k] - azs[k - 1] > 1e-5) gaps.push_back(azs[k] - azs[k - 1]);
    beam.azimuth_step = Median(gaps);
    laser_step[l] = beam.azimuth_step;
    fits.push_back(std::move(f));
  }
  int wide = 0, exact = 0;
  for (const Fit& f : fits) wide += f.wide, exact += f.exact;
  if (exact > 0 && 2 * exact >= wide) {
    for (Fit& f : fits) {
      if (f.exact) {
        f.beam.elevation = std::atan(f.a);
        f.beam.z_offset = f.b;
        continue;
      }
      double z0 = 0, best = 1e9;
      for (const Fit& g : fits)
        if (g.exact && std::abs(g.raw - f.raw) < best) best = std::abs(g.raw - f.raw), z0 = g.b;
      std::vector<double> el;
      for (size_t k = 0; k < f.h.size(); ++k) el.push_back(std::atan2(f.z[k] - z0, f.h[k]));
      f.beam.elevation = Median(el);
      f.beam.z_offset = z0;
    }
  }
  for (const Fit& f : fits) model.beams.push_back(f.beam);
  if (model.beams.empty()) throw InputError({}, "LiDAR model fit: no laser has 100 returns (is this a spinning LiDAR sweep?)");
  std::sort(model.beams.begin(), model.beams.end(), [](const LidarBeam& x, const LidarBeam& y) { return x.elevation < y.elevation; });
  {
    std::vector<double> steps;
    for (const auto& b : model.beams) steps.push_back(b.azimuth_step);
    model.azimuth_step = Median(steps);
    model.firings_per_revolution = model.azimuth_step > 0 ? static_cast<int>(std::lround(kTwoPi / model.azimuth_step)) : 0;
  }

  // 3. Timing.
  const int time_f = TimeFeature(sweep);
  if (time_f >= 0) {
    std::vector<std::pair<double, double>> ta;  // time, azimuth
    for (size_t i = 0; i < n; ++i)
      if (valid[i]) ta.push_back({sweep.feature(i, time_f), az[i]});
    std::sort(ta.begin(), ta.end());
    double cum = 0, st = 0, sa = 0, stt = 0, sta = 0;
    const double t0 = ta.front().first;
    for (size_t k = 0; k < ta.size(); ++k) {
      if (k > 0) cum += std::remainder(ta[k].second - ta[k - 1].second, kTwoPi);
      const double t = ta[k].first - t0;
      st += t, sa += cum, stt += t * t, sta += t * cum;
    }
    const double m = static_cast<double>(ta.size());
    const double slope = (m * sta - st * sa) / std::max(1e-30, m * stt - st * st);  // rad per time unit
    const double span = ta.back().first - t0;
    // The feature's unit: seconds, or nanoseconds when a sweep spans more than 1000 units.
    const double unit = span > 1000 ? 1e-9 : 1.0;
    if (std::abs(slope) > 0) {
      model.spin_hz = std::abs(slope) / unit / kTwoPi;
      model.spin_direction = slope > 0 ? 1 : -1;
      model.start_azimuth = ta.front().second;
      model.timing_from_data = true;
    }
  }
  if (!model.timing_from_data) {
    // Direction from the record order of one laser's consecutive returns.
    std::vector<double> d;
    for (const auto& [l, idx] : by_laser)
      for (size_t k = 1; k < idx.size(); ++k) {
        const double s = std::remainder(az[idx[k]] - az[idx[k - 1]], kTwoPi);
        if (std::abs(s) < 0.1) d.push_back(s);
      }
    model.spin_direction = Median(d) > 0 ? 1 : -1;
    // A complete firing grid (every laser has one record per firing, returns or not, as nuScenes stores it)
    // gives the firing count; 32 lasers on such a grid are an HDL-32E, whose firing cycle is 46.08 us.
    std::map<int, size_t> counts;
    if (model.rings_from_feature)
      for (size_t i = 0; i < n; ++i) ++counts[laser[i]];
    bool grid = !counts.empty() && n % counts.size() == 0;
    for (const auto& [l, c] : counts) grid = grid && c == n / counts.size();
    if (grid) model.firings_per_revolution = static_cast<int>(n / counts.size());
    model.spin_hz = grid && counts.size() == 32 ? 1.0 / (static_cast<double>(n / 32) * 46.08e-6) : 10.0;
    size_t first_valid = 0;
    while (first_valid < n && !valid[first_valid]) ++first_valid;
    model.start_azimuth = model.rings_from_feature && first_valid < n ? az[first_valid] : M_PI;
  }
  if (options.spin_hz > 0) model.spin_hz = options.spin_hz;
  if (options.spin_direction != 0) model.spin_direction = options.spin_direction > 0 ? 1 : -1;
  if (!std::isnan(options.start_azimuth)) model.start_azimuth = options.start_azimuth;

  // 4. Ground plane (RANSAC over 2..40 m, near-horizontal planes), then ground returns.
  std::vector<size_t> cand;
  for (size_t i = 0; i < n; ++i)
    if (valid[i] && horiz[i] >= 2.0 && horiz[i] <= 40.0) cand.push_back(i);
  Eigen::Vector3d gn(0, 0, 1);
  double gd = -1e9;
  {
    std::mt19937 rng(1);
    std::uniform_int_distribution<size_t> pick(0, cand.size() - 1);
    size_t best = 0;
    for (int it = 0; it < 300 && cand.size() >= 3; ++it) {
      const Eigen::Vector3d a = sweep.xyz(cand[pick(rng)]).cast<double>();
      const Eigen::Vector3d b = sweep.xyz(cand[pick(rng)]).cast<double>();
      const Eigen::Vector3d c = sweep.xyz(cand[pick(rng)]).cast<double>();
      Eigen::Vector3d nn = (b - a).cross(c - a);
      if (nn.norm() < 1e-6) continue;
      nn.normalize();
      if (nn.z() < 0) nn = -nn;
      if (nn.z() < 0.95) continue;
      const double d = nn.dot(a);
      size_t inl = 0;
      for (size_t i : cand) inl += std::abs(nn.dot(sweep.xyz(i).cast<double>()) - d) < 0.1;
      if (inl > best) best = inl, gn = nn, gd = d;
    }
    std::vector<Eigen::Vector3d> inliers;
    for (size_t i : cand)
      if (std::abs(gn.dot(sweep.xyz(i).cast<double>()) - gd) < 0.1) inliers.push_back(sweep.xyz(i).cast<double>());
    FitPlane(inliers, &gn, &gd);
  }
  std::vector<char> ground(n, 0);
  for (size_t i = 0; i < n; ++i)
    ground[i] = valid[i] && horiz[i] >= 2.0 && std::abs(gn.dot(sweep.xyz(i).cast<double>()) - gd) < 0.12;
  auto cos_ground = [&](size_t i) { return std::abs(gn.dot(sweep.xyz(i).cast<double>())) / std::max(1e-9, range[i]); };

  // 5. Range noise: residuals to local planes of 1.5 m cells.
  {
    std::map<std::pair<int, int>, std::vector<size_t>> cells;
    for (size_t i = 0; i < n; ++i)
      if (ground[i])
        cells[{static_cast<int>(std::floor(sweep.xyz(i).x() / 1.5)), static_cast<int>(std::floor(sweep.xyz(i).y() / 1.5))}].push_back(i);
    const std::vector<double> edges = {0, 4, 6, 8, 10, 12, 15, 20, 30, 200};
    std::vector<std::vector<double>> err(edges.size() - 1);
    for (const auto& [key, idx] : cells) {
      if (idx.size() < 10) continue;
      std::vector<Eigen::Vector3d> pts;
      for (size_t i : idx) pts.push_back(sweep.xyz(i).cast<double>());
      Eigen::Vector3d cn;
      double cd;
      if (!FitPlane(pts, &cn, &cd)) continue;
      const double dof = std::sqrt(static_cast<double>(idx.size()) / static_cast<double>(idx.size() - 3));
      for (size_t k = 0; k < idx.size(); ++k) {
        const double c = std::abs(cn.dot(pts[k])) / range[idx[k]];
        if (c < 0.2) continue;
        const double e = (cn.dot(pts[k]) - cd) / c * dof;
        const size_t b = std::upper_bound(edges.begin(), edges.end(), range[idx[k]]) - edges.begin() - 1;
        if (b < err.size()) err[b].push_back(e);
      }
    }
    double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (size_t b = 0; b < err.size(); ++b) {
      if (err[b].size() < 30) continue;
      const double w = static_cast<double>(err[b].size());
      double mean_r = 0.5 * (edges[b] + std::min(edges[b + 1], 40.0));
      const double s = RobustSigma(err[b]);
      sw += w, sx += w * mean_r, sy += w * s, sxx += w * mean_r * mean_r, sxy += w * mean_r * s;
      model.noise_samples += static_cast<int>(err[b].size());
    }
    if (sw > 0) {
      const double det = sw * sxx - sx * sx;
      model.noise_sigma_slope = det > 1e-9 ? (sw * sxy - sx * sy) / det : 0.0;
      if (model.noise_sigma_slope < 0) model.noise_sigma_slope = 0;
      model.noise_sigma0 = (sy - model.noise_sigma_slope * sx) / sw;
      if (model.noise_sigma0 < 0) {
        model.noise_sigma0 = 0;
        model.noise_sigma_slope = sxy / std::max(1e-12, sxx);
      }
    }
  }

  // 6. Dropout: missing slots between consecutive ground returns of one laser.
  {
    model.dropout_range_edges = {0, 5, 10, 15, 20, 30, 40, 60, 120};
    const size_t nb = model.dropout_range_edges.size() - 1;
    std::vector<double> slots(nb, 0), misses(nb, 0);
    for (const auto& [l, idx] : by_laser) {
      const auto st = laser_step.find(l);
      if (st == laser_step.end() || st->second <= 0) continue;
      std::vector<std::pair<double, size_t>> ring;
      for (size_t i : idx) ring.push_back({az[i], i});
      std::sort(ring.begin(), ring.end());
      for (size_t k = 1; k < ring.size(); ++k) {
        const size_t a = ring[k - 1].second, b = ring[k].second;
        if (!ground[a] || !ground[b]) continue;
        const long steps = std::lround((ring[k].first - ring[k - 1].first) / st->second);
        if (steps < 1 || steps > 8) continue;
        if (std::abs(range[a] - range[b]) > 0.15 * std::max(range[a], range[b])) continue;
        const double r = 0.5 * (range[a] + range[b]);
        const size_t bin = std::upper_bound(model.dropout_range_edges.begin(), model.dropout_range_edges.end(), r) -
                           model.dropout_range_edges.begin() - 1;
        if (bin >= nb) continue;
        slots[bin] += static_cast<double>(steps);
        misses[bin] += static_cast<double>(steps - 1);
      }
    }
    model.dropout_probability.assign(nb, -1);
    model.dropout_slots.assign(nb, 0);
    for (size_t b = 0; b < nb; ++b) {
      model.dropout_slots[b] = static_cast<int>(slots[b]);
      if (slots[b] >= 20) model.dropout_probability[b] = misses[b] / slots[b];
    }
    // Bins without support take the nearest supported bin's value (0 when none has any).
    for (size_t b = 0; b < nb; ++b) {
      if (model.dropout_probability[b] >= 0) continue;
      double v = 0;
      for (size_t d = 1; d < nb; ++d) {
        if (b >= d && model.dropout_probability[b - d] >= 0 && model.dropout_slots[b - d] >= 20) { v = model.dropout_probability[b - d]; break; }
        if (b + d < nb && model.dropout_probability[b + d] >= 0 && model.dropout_slots[b + d] >= 20) { v = model.dropout_probability[b + d]; break; }
      }
      model.dropout_probability[b] = v;
    }
  }

  // 7. Intensity.
  model.intensity_feature = IntensityFeature(sweep);
  if (model.intensity_feature < 0 && sweep.num_features > 3) model.intensity_feature = 3;
  const int fi = model.intensity_feature;
  if (fi >= 0) {
    for (size_t i = 0; i < n; ++i) model.intensity_max = std::max(model.intensity_max, sweep.feature(i, fi));
    std::vector<double> lx, ly;
    for (size_t i = 0; i < n; ++i) {
      if (!ground[i]) continue;
      const double I = sweep.feature(i, fi);
      const double c = cos_ground(i);
      if (I <= 0 || c < 0.05) continue;
      lx.push_back(std::log(c));
      ly.push_back(std::log(I));
    }
    if (lx.size() >= 50) {
      double sx = 0, sy = 0, sxx = 0, sxy = 0;
      const double m = static_cast<double>(lx.size());
      for (size_t k = 0; k < lx.size(); ++k) sx += lx[k], sy += ly[k], sxx += lx[k] * lx[k], sxy += lx[k] * ly[k];
      const double det = m * sxx - sx * sx;
      model.intensity_exponent = det > 1e-9 ? (m * sxy - sx * sy) / det : 1.0;
      const double b = (sy - model.intensity_exponent * sx) / m;
      double ss = 0, ss1 = 0, b1 = 0;
      for (size_t k = 0; k < lx.size(); ++k) b1 += ly[k] - lx[k];
      b1 /= m;
      for (size_t k = 0; k < lx.size(); ++k) {
        ss += std::pow(ly[k] - b - model.intensity_exponent * lx[k], 2);
        ss1 += std::pow(ly[k] - b1 - lx[k], 2);
      }
      model.intensity_rms_log = std::sqrt(ss / m);
      model.intensity_rms_log_lambertian = std::sqrt(ss1 / m);
    }
    const double ne = model.intensity_exponent;
    std::vector<double> g;
    for (size_t i = 0; i < n; ++i) {
      const double c = cos_ground(i);
      if (ground[i] && c >= 0.05) g.push_back(sweep.feature(i, fi) / std::pow(c, ne));
    }
    model.ground_reflectivity = Median(g);
    std::map<std::string, std::vector<double>> per_cat;
    for (const auto& [name, box] : options.annotated) {
      const BoxContainment inside(box, 0.05);
      const Eigen::Matrix3d R = box.T_frame_box.Rotation();
      const std::string cat = CanonicalCategory(name);
      for (size_t i = 0; i < n; ++i) {
        if (!valid[i]) continue;
        const Eigen::Vector3d p = sweep.xyz(i).cast<double>();
        const Eigen::Vector3d q = inside.Local(p);
        if (!inside.ContainsLocal(q)) continue;
        // Nearest face of the box: smallest normalised distance to a face.
        int axis = 0;
        double best = 1e9;
        for (int k = 0; k < 3; ++k) {
          const double d = 0.5 * box.size[k] - std::abs(q[k]);
          if (d < best) best = d, axis = k;
        }
        const double c = std::abs(R.col(axis).dot(p)) / range[i];
        if (c < 0.1) continue;
        per_cat[cat].push_back(sweep.feature(i, fi) / std::pow(c, ne));
      }
    }
    for (const auto& [cat, v] : per_cat)
      if (v.size() >= 10) model.category_reflectivity[cat] = Median(v);
  }
  return model;
}

}  // namespace sd
