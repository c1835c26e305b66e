#include "perception/tracker.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

#include <Eigen/Dense>

#include "core/error.h"

namespace sd::perception {
namespace {

using Vec4 = Eigen::Vector4d;
using Mat4 = Eigen::Matrix4d;

struct Hit {
  size_t frame;
  int detection;
  Eigen::Vector2d velocity_world;  // posterior velocity after this hit's update
  double velocity_sigma;           // its standard deviation (per axis, RMS of the two)
};

struct Track {
  int id = 0;
  Vec4 x = Vec4::Zero();  // world x, y, vx, vy
  Mat4 P = Mat4::Identity();
  double last_time = 0;   // time of the state
  double last_hit_time = 0;
  int misses = 0;
  bool alive = true;
  std::vector<Hit> hits;
  std::map<ObjectClass, int> classes;
  ObjectClass last_class = ObjectClass::kOther;
};

// The discrete white-noise-acceleration model (Bar-Shalom et al. 2001, eq. 6.3.2-4).
void Predict(Track* t, double time, double accel_sigma) {
  const double dt = time - t->last_time;
  if (dt <= 0) return;
  Mat4 F = Mat4::Identity();
  F(0, 2) = F(1, 3) = dt;
  const double q = accel_sigma * accel_sigma, dt2 = dt * dt, dt3 = dt2 * dt, dt4 = dt3 * dt;
  Mat4 Q = Mat4::Zero();
  Q(0, 0) = Q(1, 1) = dt4 / 4 * q;
  Q(0, 2) = Q(2, 0) = Q(1, 3) = Q(3, 1) = dt3 / 2 * q;
  Q(2, 2) = Q(3, 3) = dt2 * q;
  t->x = F * t->x;
  t->P = F * t->P * F.transpose() + Q;
  t->last_time = time;
}

void Update(Track* t, const Eigen::Vector2d& z, double position_sigma) {
  Eigen::Matrix<double, 2, 4> H = Eigen::Matrix<double, 2, 4>::Zero();
  H(0, 0) = H(1, 1) = 1;
  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity() * position_sigma * position_sigma;
  const Eigen::Matrix2d S = H * t->P * H.transpose() + R;
  const Eigen::Matrix<double, 4, 2> K = t->P * H.transpose() * S.inverse();
  t->x += K * (z - H * t->x);
  // Joseph form: stays symmetric positive definite.
  const Mat4 IKH = Mat4::Identity() - K * H;
  t->P = IKH * t->P * IKH.transpose() + K * R * K.transpose();
}

// Vehicles match vehicles through the whole gate; a pedestrian or small object reaches a vehicle track only
// nearby (a cone beside a parked car must not take the car's track through the speed allowance when the car's
// own detection is missing). `other` matches anything: the class of an odd partial view is unreliable.
bool Compatible(ObjectClass track, ObjectClass det) {
  if (track == ObjectClass::kOther || det == ObjectClass::kOther) return true;
  const bool tv = track == ObjectClass::kVehicle, dv = det == ObjectClass::kVehicle;
  return tv == dv;
}

double WrapPi(double a) {
  while (a > M_PI) a -= 2 * M_PI;
  while (a <= -M_PI) a += 2 * M_PI;
  return a;
}

}  // namespace

std::vector<std::vector<TrackedObject>> TrackObjects(const std::vector<TrackFrameInput>& frames, const TrackOptions& o,
                                                     TrackStats* stats) {
  for (size_t k = 0; k < frames.size(); ++k) {
    const TrackFrameInput& f = frames[k];
    if (!std::isfinite(f.timestamp) || !f.T_world_ego.translation.allFinite() || !f.T_world_ego.rotation.coeffs().allFinite())
      throw InputError("", Msg() << "tracking: frame " << k << " has a non-finite timestamp or ego pose");
    if (k > 0 && !(f.timestamp > frames[k - 1].timestamp))
      throw InputError("", Msg() << "tracking: frame " << k << " timestamp " << Fixed(f.timestamp, 6) << " s does not follow frame "
                                 << k - 1 << "'s " << Fixed(frames[k - 1].timestamp, 6) << " s");
  }
  std::vector<Track> tracks;
  TrackStats st;
  for (size_t k = 0; k < frames.size(); ++k) {
    const TrackFrameInput& f = frames[k];
    const double t = f.timestamp;
    st.detections += static_cast<int>(f.detections.size());
    std::vector<Eigen::Vector2d> z(f.detections.size());
    // The seen centre: a vehicle's completed box jumps when its view turns from end-on to flank; its returns do not.
    for (size_t d = 0; d < f.detections.size(); ++d) z[d] = (f.T_world_ego * f.detections[d].seen_center).head<2>();
    // Deaths by age, then prediction of the living.
    std::vector<int> live;
    for (size_t i = 0; i < tracks.size(); ++i) {
      Track& tr = tracks[i];
      if (!tr.alive) continue;
      if (t - tr.last_hit_time > o.max_coast_s) { tr.alive = false; continue; }
      Predict(&tr, t, o.accel_sigma);
      live.push_back(static_cast<int>(i));
    }
    // Greedy association: all gated pairs, shortest first; ties by track then detection index.
    std::vector<std::tuple<double, int, int>> pairs;
    for (int i : live) {
      const Track& tr = tracks[i];
      const bool small = tr.last_class == ObjectClass::kPedestrian || tr.last_class == ObjectClass::kSmallObject;
      const double gate = o.gate_m + (small ? o.max_speed_small : o.max_speed) * (t - tr.last_hit_time);
      for (size_t d = 0; d < z.size(); ++d) {
        const double dist = (tr.x.head<2>() - z[d]).norm();
        // A detection of an incompatible class joins only where it stands within gate_m of the prediction (a car
        // whose partial view reads as a pedestrian-sized box this sweep), never through the speed allowance.
        const bool ok = Compatible(tr.last_class, f.detections[d].object_class) ? dist <= gate : dist <= o.gate_m;
        if (ok) pairs.emplace_back(dist, i, static_cast<int>(d));
      }
    }
    std::sort(pairs.begin(), pairs.end());
    std::vector<char> track_used(tracks.size(), 0), det_used(z.size(), 0);
    for (const auto& [dist, i, d] : pairs) {
      if (track_used[i] || det_used[d]) continue;
      track_used[i] = det_used[d] = 1;
      Track& tr = tracks[i];
      Update(&tr, z[d], o.position_sigma);
      tr.last_hit_time = t;
      tr.misses = 0;
      tr.hits.push_back({k, d, tr.x.tail<2>(), std::sqrt(0.5 * (tr.P(2, 2) + tr.P(3, 3)))});
      ++tr.classes[f.detections[d].object_class];
      // The class that gates the next association: the track's most frequent one (a single odd view does not
      // turn a car track into a pedestrian one).
      int best = -1;
      for (const auto& [c, n] : tr.classes)
        if (n > best) best = n, tr.last_class = c;
    }
    for (int i : live)
      if (!track_used[i] && ++tracks[i].misses > o.max_misses) tracks[i].alive = false;
    // Births.
    for (size_t d = 0; d < z.size(); ++d) {
      if (det_used[d]) continue;
      Track tr;
      tr.id = static_cast<int>(tracks.size()) + 1;
      tr.x << z[d].x(), z[d].y(), 0, 0;
      tr.P.setZero();
      tr.P(0, 0) = tr.P(1, 1) = o.position_sigma * o.position_sigma;
      tr.P(2, 2) = tr.P(3, 3) = o.initial_speed_sigma * o.initial_speed_sigma;
      tr.last_time = tr.last_hit_time = t;
      tr.hits.push_back({k, static_cast<int>(d), Eigen::Vector2d::Zero(), o.initial_speed_sigma});
      tr.classes[f.detections[d].object_class] = 1;
      tr.last_class = f.detections[d].object_class;
      tracks.push_back(std::move(tr));
    }
  }
  // Output: tracks with enough hits, at every frame they were matched in.
  std::vector<std::vector<TrackedObject>> out(frames.size());
  st.tracks = static_cast<int>(tracks.size());
  for (const Track& tr : tracks) {
    if (static_cast<int>(tr.hits.size()) < o.min_hits) continue;
    ++st.output_tracks;
    ObjectClass cls = ObjectClass::kOther;
    int best = -1;
    for (const auto& [c, n] : tr.classes)  // map order: ties go to the first class in enum order
      if (n > best) best = n, cls = c;
    for (size_t h = 0; h < tr.hits.size(); ++h) {
      const Hit& hit = tr.hits[h];
      const TrackFrameInput& f = frames[hit.frame];
      const DetectedObject& det = f.detections[hit.detection];
      // The birth hit has no velocity of its own: it takes the next hit's (zero for a track seen once).
      const Hit& v_hit = h == 0 && tr.hits.size() > 1 ? tr.hits[1] : hit;
      const Eigen::Vector2d v_world = v_hit.velocity_world;
      TrackedObject obj;
      obj.track_id = tr.id;
      obj.object_class = cls;
      obj.num_points = det.num_points;
      obj.detection = hit.detection;
      obj.velocity_world = v_world;
      const Eigen::Matrix3d R_ego_world = f.T_world_ego.Rotation().transpose();
      obj.velocity_ego = (R_ego_world * Eigen::Vector3d(v_world.x(), v_world.y(), 0)).head<2>();
      obj.box = det.box;
      // Moving: faster than moving_speed and than twice the velocity's own uncertainty (two sweeps 0.1 s apart
      // with 10 cm of centre jitter make 1 m/s of "speed" for a parked car).
      if (v_world.norm() > std::max(o.moving_speed, 2.0 * v_hit.velocity_sigma)) {
        // Heading from the motion; the box's side nearer to the motion becomes its length.
        const double motion_yaw = std::atan2(obj.velocity_ego.y(), obj.velocity_ego.x());
        const double diff = std::abs(WrapPi(motion_yaw - det.box.Yaw()));
        const bool along_width = diff > M_PI / 4 && diff < 3 * M_PI / 4;
        if (along_width) std::swap(obj.box.size.x(), obj.box.size.y());
        obj.box.T_frame_box = Rigid3d::FromYaw(motion_yaw, det.box.center());
      }
      out[hit.frame].push_back(obj);
      ++st.output_boxes;
    }
  }
  for (auto& frame : out)
    std::sort(frame.begin(), frame.end(), [](const TrackedObject& a, const TrackedObject& b) { return a.track_id < b.track_id; });
  if (stats) *stats = st;
  return out;
}

}  // namespace sd::perception
