#include "synth/camera_road.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <optional>
#include <unordered_map>

#include "core/error.h"
#include "core/parallel.h"
#include "io/image_io.h"

namespace sd {
namespace {

namespace fs = std::filesystem;

// One camera image as matching sees it: grey (0..255), shrunk, on the ideal pinhole of its calibration.
struct GreyView {
  int width = 0, height = 0;
  std::vector<float> px;  // row-major
  PinholeCamera camera;   // of the working image, no distortion
  Rigid3d T_world_cam;

  // Bilinear sample at continuous coordinates (pixel centres at +0.5); false outside the image.
  bool Sample(double u, double v, float* out) const {
    const double x = u - 0.5, y = v - 0.5;
    if (!(x >= 0 && y >= 0 && x < width - 1 && y < height - 1)) return false;
    const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
    const float ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
    const float* p = px.data() + static_cast<size_t>(y0) * width + x0;
    const float top = p[0] + ax * (p[1] - p[0]);
    const float bottom = p[width] + ax * (p[width + 1] - p[width]);
    *out = top + ay * (bottom - top);
    return true;
  }
};

// Reads, greys and shrinks one camera's image; resamples it onto the ideal pinhole where the calibration has
// distortion, so that a plane maps between views by a homography. nullopt (with the reason) when the file is
// missing; InputError when it exists but cannot be decoded or disagrees with its calibration.
std::optional<GreyView> LoadView(const Frame& frame, const CameraSensor& cam, int downsample, std::string* why) {
  if (cam.image_path.empty() || !fs::is_regular_file(cam.image_path)) {
    *why = Msg() << "frame " << frame.token << " " << cam.channel << ": image missing ("
                 << cam.image_path.string() << ")";
    return std::nullopt;
  }
  const ImageU8 rgb = ReadImage(cam.image_path, 3);
  const PinholeCamera& K = cam.intrinsics;
  if ((K.width > 0 && rgb.width() != K.width) || (K.height > 0 && rgb.height() != K.height))
    throw InputError(cam.image_path, Msg() << "image is " << rgb.width() << "x" << rgb.height() << " but camera "
                                           << cam.channel << " is calibrated for " << K.width << "x" << K.height);
  const int ds = std::max(1, downsample);
  GreyView view;
  view.width = rgb.width() / ds;
  view.height = rgb.height() / ds;
  if (view.width < 8 || view.height < 8)
    throw InputError(cam.image_path, Msg() << "image of " << rgb.width() << "x" << rgb.height() << " is too small to match");
  // Box filter: each working pixel averages ds x ds image pixels, so pixel j covers [j ds, (j+1) ds) and the
  // intrinsics scale by 1/ds exactly under the +0.5 pixel-centre convention.
  std::vector<float> grey(static_cast<size_t>(view.width) * view.height, 0.f);
  const float norm = 1.f / static_cast<float>(ds * ds);
  for (int y = 0; y < view.height * ds; ++y) {
    float* row = grey.data() + static_cast<size_t>(y / ds) * view.width;
    for (int x = 0; x < view.width * ds; ++x) {
      const uint8_t* p = rgb.pixel(x, y);
      row[x / ds] += norm * (0.299f * p[0] + 0.587f * p[1] + 0.114f * p[2]);
    }
  }
  view.camera = K;
  view.camera.width = view.width;
  view.camera.height = view.height;
  view.camera.fx /= ds;
  view.camera.fy /= ds;
  view.camera.cx /= ds;
  view.camera.cy /= ds;
  view.camera.distortion = Distortion{};
  view.T_world_cam = frame.T_world_ego * cam.T_ego_cam;
  if (K.distortion.IsZero()) {
    view.px = std::move(grey);
    return view;
  }
  // Undistort once: each ideal pixel takes the distorted image's value where its ray lands (clamped at the border;
  // the few border pixels this smears lie outside any patch that could match anyway).
  GreyView distorted = view;
  distorted.px = std::move(grey);
  distorted.camera.distortion = K.distortion;
  view.px.assign(distorted.px.size(), 0.f);
  const PinholeCamera& c = view.camera;
  for (int y = 0; y < view.height; ++y)
    for (int x = 0; x < view.width; ++x) {
      const Eigen::Vector2d xy((x + 0.5 - c.cx) / c.fx, (y + 0.5 - c.cy) / c.fy);
      const Eigen::Vector2d d = K.Distort(xy);
      const double u = std::clamp(c.fx * d.x() + c.cx, 0.5, view.width - 1.5);
      const double v = std::clamp(c.fy * d.y() + c.cy, 0.5, view.height - 1.5);
      float value = 0;
      distorted.Sample(u, v, &value);
      view.px[static_cast<size_t>(y) * view.width + x] = value;
    }
  return view;
}

// A source view and the homography pencil from the reference: H(h) = A + B / d(h).
// For any plane n^T X_c = d of the reference camera, H = A + (K_s t_sc) (K_r^-T n / d)^T.
struct Source {
  const GreyView* view = nullptr;
  Eigen::Matrix3d A, B;
  Eigen::Vector3d Kt;  // K_s t_sc
};

// The sweep at one reference pixel (u, v) whose patch lies inside the reference image. `inv_dist[j]` is
// 1 / d(h_j), the reference camera's signed distance to plane j along its normal.
//
// Coarse to fine, for speed (about 5x fewer samples than the full sweep): every second height with every second
// patch sample in each direction gives the cost curve the acceptance tests read; the full patch is then scored at
// the heights next to the coarse best, and its best, refined by a parabola, is the answer.
//
// Two families of planes: the road's (horizontal, `kRoad`: h is a height, the vertical-plane check applies) and
// the camera's fronto-parallel planes (`kDepth`: h is an inverse depth, for whatever stands above the road).
enum class Planes { kRoad, kDepth };
class Sweeper {
 public:
  Sweeper(const GreyView& ref, const std::vector<Source>& sources, const std::vector<double>& inv_dist,
          const Eigen::Matrix3d& R_ego_cam, const CameraRoadOptions& o, Planes planes = Planes::kRoad)
      : ref_(ref), sources_(sources), inv_dist_(inv_dist), R_ego_cam_(R_ego_cam), o_(o), planes_(planes) {
    K_inv_ = ref.camera.K().inverse();
    const int P = o.patch;
    for (int dy = -P, k = 0; dy <= P; ++dy)
      for (int dx = -P; dx <= P; ++dx, ++k) {
        offsets_.emplace_back(dx, dy);
        full_.push_back(k);
        if ((dx + P) % 2 == 0 && (dy + P) % 2 == 0) sparse_.push_back(k);
      }
    centre_ = static_cast<int>(offsets_.size()) / 2;
    const int N = static_cast<int>(inv_dist.size());
    for (int j = 0; j < N; j += 2) coarse_heights_.push_back(j);
    if (coarse_heights_.back() != N - 1) coarse_heights_.push_back(N - 1);
  }

  // The refined (fractional) index of the road height, or nullopt when rejected.
  std::optional<double> Run(double u, double v) {
    const int S = static_cast<int>(sources_.size()), N = static_cast<int>(inv_dist_.size());
    const int n = static_cast<int>(offsets_.size());
    ref_vals_.resize(n);
    for (int k = 0; k < n; ++k) ref_.Sample(u + offsets_[k].first, v + offsets_[k].second, &ref_vals_[k]);
    // Texture-less patches have no answer (their NCC is noise over a flat curve).
    if (!Normalise(full_, &ref_full_, &norm_full_) || !Normalise(sparse_, &ref_sparse_, &norm_sparse_))
      return std::nullopt;
    // Per source and patch sample, the homogeneous source point is a_k + b_k / d(h): A x_k and B x_k once.
    a_.resize(static_cast<size_t>(S) * n);
    b_.resize(static_cast<size_t>(S) * n);
    for (int s = 0; s < S; ++s)
      for (int k = 0; k < n; ++k) {
        const Eigen::Vector3d x(u + offsets_[k].first, v + offsets_[k].second, 1.0);
        a_[s * n + k] = sources_[s].A * x;
        b_[s * n + k] = sources_[s].B * x;
      }
    // Coarse curve: every second height (and the last), sparse patch. NaN where no source sees the patch.
    coarse_.assign(N, std::numeric_limits<double>::quiet_NaN());
    int best = -1;
    for (int j : coarse_heights_) {
      coarse_[j] = Score(j, sparse_, ref_sparse_, norm_sparse_);
      if (!std::isnan(coarse_[j]) && (best < 0 || coarse_[j] > coarse_[best])) best = j;
    }
    if (best < 0) return std::nullopt;
    // The source with the most parallax over the sweep judges what "away from the peak" means.
    int par = -1;
    double span = 0;
    for (int s = 0; s < S; ++s) {
      const auto c0 = Centre(s, 0), c1 = Centre(s, N - 1);
      if (!c0 || !c1) continue;
      const double d = (*c1 - *c0).norm();
      if (d > span) span = d, par = s;
    }
    if (par < 0) return std::nullopt;
    // No resolution: one pixel of parallax covers too many metres of height, or too large a share of the depth.
    if (planes_ == Planes::kRoad && (2 * o_.search) / span > o_.max_height_per_px) return std::nullopt;
    if (planes_ == Planes::kDepth &&
        std::abs(inv_dist_.front() - inv_dist_.back()) / span / inv_dist_[best] > o_.max_depth_share_per_px)
      return std::nullopt;
    const auto cb = Centre(par, best);
    if (!cb) return std::nullopt;
    auto away = [&](int j) {
      const auto c = Centre(par, j);
      return c && (*c - *cb).norm() > o_.peak_px;
    };
    // Peak resolved inside the range: both ends away from it (else the height sits at the edge of the search).
    if (!away(0) || !away(N - 1)) return std::nullopt;
    // Distinct minimum: nothing away from the peak scores nearly as well (flat or multi-modal curves fail).
    double rival = -1;
    for (int j = 0; j < N; ++j)
      if (!std::isnan(coarse_[j]) && away(j)) rival = std::max(rival, coarse_[j]);
    if (coarse_[best] - rival < o_.min_margin) return std::nullopt;
    // Fine: the full patch at every height next to the coarse best; its best must clear min_ncc.
    const int lo = std::max(0, best - 2), hi = std::min(N - 1, best + 2);
    fine_.assign(N, std::numeric_limits<double>::quiet_NaN());
    int fine_best = -1;
    for (int j = lo; j <= hi; ++j) {
      fine_[j] = Score(j, full_, ref_full_, norm_full_);
      if (!std::isnan(fine_[j]) && (fine_best < 0 || fine_[j] > fine_[fine_best])) fine_best = j;
    }
    if (fine_best < 0 || fine_[fine_best] < o_.min_ncc) return std::nullopt;
    if (fine_best == 0 || fine_best == N - 1) return std::nullopt;  // at the edge of the search range
    if (planes_ == Planes::kDepth) return Refined(fine_best);
    // Not road: a vertical plane facing the camera through the same point explains the patch at least as well (a
    // car's back, a kerb's face, a wall's foot at road height). Where the two warps hardly differ (far away) this
    // decides nothing and the point stays.
    const Eigen::Vector3d ray_c = K_inv_ * Eigen::Vector3d(u, v, 1.0);
    const Eigen::Vector3d ray_e = R_ego_cam_ * ray_c;
    const Eigen::Vector3d n_ground_c = R_ego_cam_.transpose() * Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d X_c = ray_c * ((1.0 / inv_dist_[fine_best]) / n_ground_c.dot(ray_c));
    const Eigen::Vector3d n_wall_c = R_ego_cam_.transpose() * Eigen::Vector3d(ray_e.x(), ray_e.y(), 0).normalized();
    const double wall = ScorePlane(K_inv_.transpose() * n_wall_c / n_wall_c.dot(X_c), u, v);
    if (!std::isnan(wall) && wall >= fine_[fine_best]) return std::nullopt;
    return Refined(fine_best);
  }

 private:
  // The best index refined by a parabola through its score and its neighbours' (sub-step).
  double Refined(int fine_best) {
    for (int j : {fine_best - 1, fine_best + 1})
      if (std::isnan(fine_[j])) fine_[j] = Score(j, full_, ref_full_, norm_full_);
    double offset = 0;
    const double l = fine_[fine_best - 1], c = fine_[fine_best], r = fine_[fine_best + 1];
    if (!std::isnan(l) && !std::isnan(r) && l - 2 * c + r < 0) offset = std::clamp(0.5 * (l - r) / (l - 2 * c + r), -0.5, 0.5);
    return fine_best + offset;
  }

  // Zero-mean reference values over `idx` and their norm; false when the patch has too little texture.
  bool Normalise(const std::vector<int>& idx, std::vector<float>* out, double* norm) const {
    double sum = 0, sum2 = 0;
    for (int k : idx) sum += ref_vals_[k], sum2 += double(ref_vals_[k]) * ref_vals_[k];
    const double m = static_cast<double>(idx.size());
    const double mean = sum / m, var = std::max(0.0, sum2 / m - mean * mean);
    if (std::sqrt(var) < o_.min_texture) return false;
    out->resize(idx.size());
    for (size_t q = 0; q < idx.size(); ++q) (*out)[q] = static_cast<float>(ref_vals_[idx[q]] - mean);
    *norm = std::sqrt(var * m);
    return true;
  }

  // Where the patch centre lands in source `s` under hypothesis `j`.
  std::optional<Eigen::Vector2d> Centre(int s, int j) const {
    const size_t k = static_cast<size_t>(s) * offsets_.size() + centre_;
    const Eigen::Vector3d p = a_[k] + b_[k] * inv_dist_[j];
    if (p.z() <= 1e-6) return std::nullopt;
    return Eigen::Vector2d(p.x() / p.z(), p.y() / p.z());
  }

  // Mean full-patch NCC under the plane whose homographies are A + Kt m^T (m = K_r^-T n / d); NaN when unseen.
  double ScorePlane(const Eigen::Vector3d& m, double u, double v) const {
    const size_t n = offsets_.size();
    return MeanNcc(full_, ref_full_, norm_full_, [&](int s, int k) {
      const Eigen::Vector3d x(u + offsets_[k].first, v + offsets_[k].second, 1.0);
      return Eigen::Vector3d(a_[s * n + k] + sources_[s].Kt * m.dot(x));
    });
  }

  // Mean NCC over the sources that see the whole warped patch (samples `idx`) under sweep plane `j`; NaN when none does.
  double Score(int j, const std::vector<int>& idx, const std::vector<float>& ref, double ref_norm) const {
    const size_t n = offsets_.size();
    const double w = inv_dist_[j];
    return MeanNcc(idx, ref, ref_norm, [&](int s, int k) { return Eigen::Vector3d(a_[s * n + k] + b_[s * n + k] * w); });
  }

  // The NCC of the reference samples `idx` (zero-mean values `ref`, norm `ref_norm`) against each source where
  // `point(s, k)` (homogeneous source pixel of patch sample k) lands, averaged over the sources that see them all.
  template <typename PointOf>
  double MeanNcc(const std::vector<int>& idx, const std::vector<float>& ref, double ref_norm, const PointOf& point) const {
    const double m = static_cast<double>(idx.size());
    double total = 0;
    int seen = 0;
    for (int s = 0; s < static_cast<int>(sources_.size()); ++s) {
      double s1 = 0, s2 = 0, sr = 0;
      bool inside = true;
      for (size_t q = 0; q < idx.size() && inside; ++q) {
        const Eigen::Vector3d p = point(s, idx[q]);
        float val = 0;
        inside = p.z() > 1e-6 && sources_[s].view->Sample(p.x() / p.z(), p.y() / p.z(), &val);
        s1 += val;
        s2 += double(val) * val;
        sr += double(val) * ref[q];
      }
      if (!inside) continue;
      const double src_var = s2 - s1 * s1 / m;
      total += src_var > 1e-6 ? sr / (ref_norm * std::sqrt(src_var)) : 0.0;
      ++seen;
    }
    return seen > 0 ? total / seen : std::numeric_limits<double>::quiet_NaN();
  }

  const GreyView& ref_;
  const std::vector<Source>& sources_;
  const std::vector<double>& inv_dist_;
  Eigen::Matrix3d R_ego_cam_, K_inv_;
  const CameraRoadOptions& o_;
  Planes planes_;
  std::vector<std::pair<int, int>> offsets_;  // patch samples (dx, dy), row-major
  std::vector<int> full_, sparse_;            // indices into offsets_: all, every second in x and y
  int centre_ = 0;
  std::vector<int> coarse_heights_;           // every second height index, and the last
  std::vector<float> ref_vals_, ref_full_, ref_sparse_;
  double norm_full_ = 0, norm_sparse_ = 0;
  std::vector<Eigen::Vector3d> a_, b_;
  std::vector<double> coarse_, fine_;
};

// The source frames of `frame_index`: up to `neighbours` on each side within `max_gap` seconds.
std::vector<size_t> NeighbourFrames(const Log& log, size_t frame_index, const CameraRoadOptions& o) {
  std::vector<size_t> out;
  if (!log.sequential) return out;
  const double t = log.frames[frame_index].timestamp;
  for (int k = 1; k <= o.neighbours; ++k) {
    if (frame_index >= static_cast<size_t>(k) && std::abs(log.frames[frame_index - k].timestamp - t) <= o.max_gap)
      out.push_back(frame_index - k);
    if (frame_index + k < log.frames.size() && std::abs(log.frames[frame_index + k].timestamp - t) <= o.max_gap)
      out.push_back(frame_index + k);
  }
  return out;
}

// A road point whose height departs from the median of its neighbours' (all cameras, within `outlier_radius`) by
// more than `outlier_tolerance` is a mismatch: the road is smooth at that scale, the stereo's noise is a few
// centimetres, and the lowest points of a noisy set would otherwise pull the road's seed plane down (its RANSAC
// takes each cell's lowest point, as a LiDAR's lowest returns are its road). Points with fewer than three
// neighbours have no verdict and are dropped too: a lone patch of texture is as likely a mismatch.
void RejectHeightOutliers(const CameraRoadOptions& o, CameraRoadResult* r) {
  const double cell = o.outlier_radius;
  std::unordered_map<int64_t, std::vector<int>> grid;
  const auto key = [&](int64_t ix, int64_t iy) { return (ix << 32) ^ (iy & 0xffffffff); };
  for (size_t i = 0; i < r->points_ego.size(); ++i) {
    const Eigen::Vector3d& p = r->points_ego[i];
    grid[key(static_cast<int64_t>(std::floor(p.x() / cell)), static_cast<int64_t>(std::floor(p.y() / cell)))].push_back(static_cast<int>(i));
  }
  std::vector<uint8_t> keep(r->points_ego.size(), 0);
  ParallelFor(0, r->points_ego.size(), [&](size_t i) {
    const Eigen::Vector3d& p = r->points_ego[i];
    const int64_t ix = static_cast<int64_t>(std::floor(p.x() / cell)), iy = static_cast<int64_t>(std::floor(p.y() / cell));
    std::vector<double> z;
    for (int64_t dy = -1; dy <= 1; ++dy)
      for (int64_t dx = -1; dx <= 1; ++dx) {
        const auto it = grid.find(key(ix + dx, iy + dy));
        if (it == grid.end()) continue;
        for (int j : it->second)
          if (static_cast<size_t>(j) != i && (r->points_ego[j] - p).head<2>().squaredNorm() <= cell * cell)
            z.push_back(r->points_ego[j].z());
      }
    if (z.size() < 3) return;
    std::nth_element(z.begin(), z.begin() + static_cast<long>(z.size() / 2), z.end());
    keep[i] = std::abs(p.z() - z[z.size() / 2]) <= o.outlier_tolerance;
  });
  size_t n = 0;
  for (size_t i = 0; i < keep.size(); ++i)
    if (keep[i]) {
      r->points_ego[n] = r->points_ego[i];
      r->camera_of[n] = r->camera_of[i];
      ++n;
    }
  r->outliers = static_cast<int>(r->points_ego.size() - n);
  r->points_ego.resize(n);
  r->camera_of.resize(n);
}

}  // namespace

CameraRoadResult EstimateRoadFromCameras(const Log& log, size_t frame_index, double prior_ground_z,
                                         const CameraRoadOptions& o) {
  SD_CHECK(frame_index < log.frames.size(), << "frame " << frame_index << " of " << log.frames.size());
  SD_CHECK(o.step > 0 && o.search > 0 && o.stride > 0 && o.patch > 0 && o.downsample > 0 && o.peak_px > 0,
           << "bad CameraRoadOptions");
  CameraRoadResult result;
  const Frame& frame = log.frames[frame_index];
  const std::vector<size_t> neighbours = NeighbourFrames(log, frame_index, o);
  if (neighbours.empty()) {
    result.summary = log.sequential ? std::string(Msg() << "no neighbouring frame within " << Fixed(o.max_gap, 1) << " s: none")
                                    : std::string("frames are not a sequence (no neighbouring frame): none");
    return result;
  }
  const int N = static_cast<int>(std::lround(2 * o.search / o.step)) + 1;
  const double step = 2 * o.search / (N - 1);
  std::vector<double> heights(N);
  for (int j = 0; j < N; ++j) heights[j] = prior_ground_z - o.search + j * step;

  for (size_t ci = 0; ci < frame.cameras.size(); ++ci) {
    const CameraSensor& cam = frame.cameras[ci];
    // Sources first: their poses decide whether reading the reference image is worth it.
    std::vector<GreyView> source_views;
    source_views.reserve(neighbours.size());
    const Rigid3d T_world_ref = frame.T_world_ego * cam.T_ego_cam;
    for (size_t fi : neighbours) {
      const Frame& other = log.frames[fi];
      const CameraSensor* sc = other.FindCamera(cam.channel);
      if (!sc) continue;
      const Rigid3d T_world_src = other.T_world_ego * sc->T_ego_cam;
      if ((T_world_src.translation - T_world_ref.translation).norm() < o.min_baseline) {
        result.skipped.push_back(Msg() << "frame " << other.token << " " << cam.channel << ": camera moved less than "
                                       << Fixed(o.min_baseline, 2) << " m (no parallax)");
        continue;
      }
      std::string why;
      std::optional<GreyView> v = LoadView(other, *sc, o.downsample, &why);
      if (!v) {
        result.skipped.push_back(why);
        continue;
      }
      source_views.push_back(std::move(*v));
    }
    if (source_views.empty()) continue;
    std::string why;
    const std::optional<GreyView> ref = LoadView(frame, cam, o.downsample, &why);
    if (!ref) {
      result.skipped.push_back(why);
      continue;
    }
    ++result.cameras_used;
    result.source_views += static_cast<int>(source_views.size());

    // Homography pencil per source: X_s = R_sc X_c + t_sc, plane n_c^T X_c = d(h) in the reference camera.
    const Eigen::Matrix3d R_ego_cam = cam.T_ego_cam.Rotation();
    const Eigen::Vector3d n_c = R_ego_cam.transpose() * Eigen::Vector3d::UnitZ();
    const Eigen::Matrix3d K_r_inv = ref->camera.K().inverse();
    std::vector<Source> sources, depth_sources;
    for (const GreyView& sv : source_views) {
      const Rigid3d T_src_ref = sv.T_world_cam.Inverse() * ref->T_world_cam;
      Source s;
      s.view = &sv;
      s.A = sv.camera.K() * T_src_ref.Rotation() * K_r_inv;
      s.B = sv.camera.K() * T_src_ref.translation * n_c.transpose() * K_r_inv;
      s.Kt = sv.camera.K() * T_src_ref.translation;
      sources.push_back(s);
      s.B = s.Kt * Eigen::Vector3d::UnitZ().transpose() * K_r_inv;  // fronto-parallel: n = optical axis, d = depth
      depth_sources.push_back(s);
    }
    std::vector<double> inv_depth(std::max(3, o.depth_steps));
    for (size_t j = 0; j < inv_depth.size(); ++j)
      inv_depth[j] = 1.0 / o.min_depth + (1.0 / o.max_depth - 1.0 / o.min_depth) * j / (inv_depth.size() - 1.0);
    // n_c^T X_c = z - z_cam for a point at ego height z (the reference camera's origin sits at ego height z_cam).
    const double z_cam = cam.T_ego_cam.translation.z();
    std::vector<double> inv_dist(N);
    bool all_below = true;
    for (int j = 0; j < N; ++j) {
      const double d = heights[j] - z_cam;
      all_below = all_below && d < -1e-3;
      inv_dist[j] = 1.0 / d;
    }
    if (!all_below) {  // a camera at road height (or below) sees no road plane to sweep
      result.skipped.push_back(Msg() << "frame " << frame.token << " " << cam.channel << ": camera within the swept heights");
      continue;
    }

    // Reference grid: rows in parallel, each row's results kept in its own slot (deterministic order).
    const int P = o.patch;
    const int x_begin = P + 1, y_begin = P + 1;
    // The last grid pixel's patch still has a right/bottom neighbour for bilinear sampling.
    const int cols = (ref->width - 2 * P - 3) / o.stride + 1;
    const int rows = (ref->height - 2 * P - 3) / o.stride + 1;
    if (cols <= 0 || rows <= 0) continue;
    std::vector<std::vector<Eigen::Vector3d>> row_points(rows), row_scene(rows);
    std::vector<int> row_tried(rows, 0);
    ParallelFor(0, static_cast<size_t>(rows), [&](size_t r) {
      Sweeper sweeper(*ref, sources, inv_dist, R_ego_cam, o);
      Sweeper depth_sweeper(*ref, depth_sources, inv_depth, R_ego_cam, o, Planes::kDepth);
      const double v = y_begin + static_cast<double>(r) * o.stride + 0.5;
      const Eigen::Vector3d& origin = cam.T_ego_cam.translation;
      for (int c = 0; c < cols; ++c) {
        const double u = x_begin + static_cast<double>(c) * o.stride + 0.5;
        const Eigen::Vector3d ray_c = K_r_inv * Eigen::Vector3d(u, v, 1.0);
        const Eigen::Vector3d ray_ego = R_ego_cam * ray_c;
        // The road: below the prior plane's horizon, hitting it within range (at the prior height).
        bool road = false;
        if (ray_ego.z() < -1e-6 &&
            (origin + ray_ego * ((prior_ground_z - origin.z()) / ray_ego.z())).head<2>().norm() <= o.max_range) {
          ++row_tried[r];
          if (const std::optional<double> j = sweeper.Run(u, v)) {
            const double z = prior_ground_z - o.search + *j * step;
            row_points[r].push_back(origin + ray_ego * ((z - origin.z()) / ray_ego.z()));
            road = true;
          }
        }
        if (road || !o.scene_points) continue;
        if (const std::optional<double> j = depth_sweeper.Run(u, v)) {
          const double inv = inv_depth.front() + (inv_depth.back() - inv_depth.front()) * *j / (inv_depth.size() - 1.0);
          const Eigen::Vector3d p = cam.T_ego_cam * (ray_c * (1.0 / inv / ray_c.z()));
          if (p.head<2>().norm() <= o.max_range) row_scene[r].push_back(p);
        }
      }
    });
    for (int r = 0; r < rows; ++r) {
      result.pixels_tried += row_tried[r];
      for (const Eigen::Vector3d& p : row_points[r]) {
        result.points_ego.push_back(p);
        result.camera_of.push_back(static_cast<int>(ci));
      }
      result.scene_points_ego.insert(result.scene_points_ego.end(), row_scene[r].begin(), row_scene[r].end());
    }
  }
  RejectHeightOutliers(o, &result);
  result.pixels_accepted = static_cast<int>(result.points_ego.size());
  if (result.cameras_used == 0)
    result.summary = Msg() << "no camera with a usable neighbouring view: none";
  else
    result.summary = Msg() << "stereo over " << result.source_views << " source views of " << result.cameras_used
                           << " cameras: " << result.pixels_accepted << " of " << result.pixels_tried << " pixels accepted ("
                           << result.outliers << " more dropped, off their neighbours' height)";
  if (o.scene_points && result.cameras_used > 0) result.summary += Msg() << ", " << result.scene_points_ego.size() << " scene points";
  if (!result.skipped.empty()) result.summary += Msg() << " (" << result.skipped.size() << " views left out)";
  return result;
}

}  // namespace sd
