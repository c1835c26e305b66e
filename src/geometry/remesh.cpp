#include "geometry/remesh.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/parallel.h"
#include "geometry/edge_adjacency.h"
#include "geometry/topology.h"

namespace sd::geometry {
namespace {

// Face quality floor for the results of collapses and flips: |cross| / (longest edge)^2 of a new face must
// stay above this (equilateral: 0.87; 0.05 is a smallest angle of about 3 degrees). Keeps slivers out.
constexpr float kMinQuality = 0.05f;
// A face's normal may turn by at most ~45 degrees (cos 0.7) in one collapse / flip / relaxation move:
// anything more is treated as a fold-over in the making. (Looser bounds let a face on a steep wrinkle be
// turned past vertical in a few moves; the ring-normal test in each operation backs this up.)
constexpr float kMinNormalCos = 0.7f;
// The first steps ramp the learning rate up over 1 / (1 - beta1) steps, while the moment estimates are
// still dominated by single gradients.
constexpr float kRampSteps = 1.0f;
constexpr float kEps = 1e-20f;

inline int Next(int h) { return h % 3 == 2 ? h - 2 : h + 1; }
inline int Prev(int h) { return h % 3 == 0 ? h + 2 : h - 1; }

// Per-vertex data that follows vertices through remeshing.
struct VertexData {
  std::vector<Eigen::Vector3f>* positions;
  std::vector<Eigen::Vector3f>* m1;
  std::vector<float>* m2;
  std::vector<Eigen::Vector3f>* velocity;
  std::vector<float>* target;

  int AddMidpoint(int a, int b) {
    const int v = static_cast<int>(positions->size());
    positions->push_back(0.5f * ((*positions)[a] + (*positions)[b]));
    m1->push_back(0.5f * ((*m1)[a] + (*m1)[b]));
    m2->push_back(0.5f * ((*m2)[a] + (*m2)[b]));
    velocity->push_back(0.5f * ((*velocity)[a] + (*velocity)[b]));
    target->push_back(0.5f * ((*target)[a] + (*target)[b]));
    return v;
  }
  // b merges into a; a moves to p (the midpoint, or stays put on the boundary) and takes the average state.
  void Merge(int a, int b, const Eigen::Vector3f& p) {
    (*positions)[a] = p;
    (*m1)[a] = 0.5f * ((*m1)[a] + (*m1)[b]);
    (*m2)[a] = 0.5f * ((*m2)[a] + (*m2)[b]);
    (*velocity)[a] = 0.5f * ((*velocity)[a] + (*velocity)[b]);
    (*target)[a] = 0.5f * ((*target)[a] + (*target)[b]);
  }
};

float Quality(const Eigen::Vector3f& a, const Eigen::Vector3f& b, const Eigen::Vector3f& c, Eigen::Vector3f* n) {
  *n = (b - a).cross(c - a);
  const float longest = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  return longest > 0 ? n->norm() / longest : 0.0f;
}

// cos(before, after) > kMinNormalCos, without square roots (this runs for every face of every relaxed vertex).
bool NormalKept(const Eigen::Vector3f& before, const Eigen::Vector3f& after) {
  const float dot = before.dot(after);
  return dot > 0 && dot * dot > kMinNormalCos * kMinNormalCos * before.squaredNorm() * after.squaredNorm();
}

// Half-edge view of an oriented manifold triangle mesh: half-edge h = 3 f + k runs from corner k to
// corner k+1 of face f; opp[h] is its twin (-1 on the boundary). The boundary keeps its shape: boundary
// edges are only split (at their midpoints), never collapsed or flipped, and boundary vertices never move or
// vanish, so every boundary vertex keeps one outgoing boundary half-edge, which `out` points to (ring walks
// start there).
class HalfEdgeMesh {
 public:
  HalfEdgeMesh(std::vector<Eigen::Vector3i>* faces, VertexData data, const RemeshOptions& options)
      : F_(*faces), data_(data), P_(*data.positions), T_(*data.target), options_(options) {
    const int nv = static_cast<int>(P_.size());
    const int nf = static_cast<int>(F_.size());
    out_.assign(nv, -1);
    boundary_.assign(nv, 0);
    valence_.assign(nv, 0);
    face_dead_.assign(nf, 0);
    vert_dead_.assign(nv, 0);
    // The constructor admits only manifold, consistently wound meshes and every pass keeps them so: each
    // edge has one half-edge, or two running opposite ways, and those are twins.
    opp_ = BuildEdgeAdjacency(nv, F_, DegenerateFaces::kSkip).twin;
    for (int h = 0; h < 3 * nf; ++h) {
      const int v = From(h);
      ++valence_[v];  // faces around v for now
      if (opp_[h] < 0) {
        boundary_[v] = 1;
        out_[v] = h;
      } else if (out_[v] < 0) {
        out_[v] = h;
      }
    }
    for (int v = 0; v < nv; ++v) valence_[v] += boundary_[v];  // neighbours = faces (+1 on a boundary)
  }

  int From(int h) const { return F_[h / 3][h % 3]; }
  int To(int h) const { return F_[h / 3][(h % 3 + 1) % 3]; }

  // Calls fn(h) for each outgoing half-edge of v, in rotation order.
  template <typename Fn>
  void ForEachOutgoing(int v, Fn&& fn) const {
    const int h0 = out_[v];
    if (h0 < 0) return;
    int h = h0;
    do {
      fn(h);
      h = opp_[Prev(h)];
    } while (h >= 0 && h != h0);
  }
  // Neighbour vertices of v (the extra last one on a boundary).
  void Neighbours(int v, std::vector<int>* out) const {
    out->clear();
    int last = -1;
    ForEachOutgoing(v, [&](int h) {
      out->push_back(To(h));
      last = h;
    });
    if (boundary_[v] && last >= 0) out->push_back(From(Prev(last)));
  }

  // Area-weighted normal of the faces around v (unnormalised).
  Eigen::Vector3f RingNormal(int v) const {
    Eigen::Vector3f n = Eigen::Vector3f::Zero();
    ForEachOutgoing(v, [&](int e) { n += (P_[To(e)] - P_[v]).cross(P_[From(Prev(e))] - P_[v]); });
    return n;
  }

  const RemeshStats& stats() const { return stats_; }

  float EdgeTarget(int a, int b) const { return 0.5f * (T_[a] + T_[b]); }
  float Length(int h) const { return (P_[To(h)] - P_[From(h)]).norm(); }
  bool InteriorEdge(int h) const { return opp_[h] >= 0; }

  // --- Collapse -------------------------------------------------------------------------------------------
  void CollapseShortEdges() {
    const float tol = options_.edge_length_tolerance;
    std::vector<std::pair<float, int>> candidates;
    for (int h = 0; h < static_cast<int>(opp_.size()); ++h) {
      if (!InteriorEdge(h) || opp_[h] < h) continue;
      const int a = From(h), b = To(h);
      if (boundary_[a] && boundary_[b]) continue;
      const float len = Length(h);
      if (len < (1 - tol) * EdgeTarget(a, b)) candidates.emplace_back(len, h);
    }
    std::sort(candidates.begin(), candidates.end());
    for (const auto& [len, h] : candidates) {
      if (face_dead_[h / 3] || !InteriorEdge(h)) continue;
      const int a = From(h), b = To(h);
      if (boundary_[a] && boundary_[b]) continue;
      // Earlier collapses may have moved the ends: re-test against the current lengths.
      if (Length(h) >= (1 - tol) * EdgeTarget(a, b)) continue;
      // An interior vertex next to the boundary merges into the boundary vertex (which stays put), else
      // interior vertices pile up along a frozen boundary as slivers.
      if (TryCollapse(boundary_[b] ? opp_[h] : h)) ++stats_.collapses;
    }
  }

  // Collapses half-edge h = a -> b (b merges into a, at the midpoint, or at a if a is a boundary vertex)
  // when that keeps the mesh manifold, free of fold-overs and slivers, and does not create edges that would
  // immediately be split again. b must be interior.
  bool TryCollapse(int h) {
    const int g = opp_[h];
    const int a = From(h), b = To(h);
    const int c = From(Prev(h)), d = From(Prev(g));  // apexes of the two faces of edge a-b
    SD_CHECK(!boundary_[b]);
    // Edges a-c and a-d must be interior too (only possible otherwise when a is on the boundary): the
    // stitching below pairs twins on both sides, and the boundary stays exactly as it is.
    RemeshStats::Rejections& rejected = stats_.collapse_rejected;
    if (opp_[Prev(h)] < 0 || opp_[Next(g)] < 0) return Refuse(&rejected.boundary);
    // Link condition: a and b may share exactly the neighbours c and d, else the collapse pinches the
    // surface into a non-manifold edge or vertex. c and d lose one neighbour and must keep three, else
    // two faces end up on the same three vertices (e.g. a tetrahedron collapsing into a double triangle).
    if (c == d) return Refuse(&rejected.link);
    if (valence_[c] <= 3 || valence_[d] <= 3) return Refuse(&rejected.valence);
    Neighbours(a, &ring_a_);
    Neighbours(b, &ring_b_);
    int shared = 0;
    for (int x : ring_a_) {
      if (std::find(ring_b_.begin(), ring_b_.end(), x) != ring_b_.end()) ++shared;
    }
    if (shared != 2) return Refuse(&rejected.link);
    // Very high valences make needle triangles that no flip can repair in one pass.
    if (valence_[a] + valence_[b] - 4 > 12) return Refuse(&rejected.valence);

    const Eigen::Vector3f p = boundary_[a] ? P_[a] : Eigen::Vector3f(0.5f * (P_[a] + P_[b]));
    const float t_new = 0.5f * (T_[a] + T_[b]);
    const float max_len = 1 + options_.edge_length_tolerance;
    const int fa = h / 3, fb = g / 3;
    // Every face around a or b other than the two removed ones gets p for a or b. Each must keep its own
    // orientation and also face the same way as the surrounding surface (one-rings of a and b): the second
    // test catches a face that is already steep on a wrinkle and would be turned just past vertical.
    const Eigen::Vector3f ring_normal = RingNormal(a) + RingNormal(b);
    int* failed = nullptr;  // the first test a face failed
    auto check_faces_of = [&](int v) {
      ForEachOutgoing(v, [&](int e) {
        const int f = e / 3;
        if (failed != nullptr || f == fa || f == fb) return;
        const Eigen::Vector3f& q1 = P_[To(e)];
        const Eigen::Vector3f& q2 = P_[From(Prev(e))];
        const Eigen::Vector3f before = (q1 - P_[v]).cross(q2 - P_[v]);
        Eigen::Vector3f after;
        if (Quality(p, q1, q2, &after) < kMinQuality) {
          failed = &rejected.sliver;
        } else if (!NormalKept(before, after) || after.dot(ring_normal) <= 0) {
          failed = &rejected.fold_over;
        } else if ((q1 - p).norm() > max_len * 0.5f * (t_new + T_[To(e)])) {
          failed = &rejected.too_long;
        }
      });
    };
    check_faces_of(a);
    check_faces_of(b);
    if (failed != nullptr) return Refuse(failed);

    // Faces around b (except the two removed) now use a.
    ForEachOutgoing(b, [&](int e) {
      const int f = e / 3;
      if (f != fa && f != fb) F_[f][e % 3] = a;
    });
    // Stitch the twins across each removed face: in face (a, b, c), c -> b's twin (now c -> a) pairs with
    // a -> c's twin; likewise in (b, a, d).
    const int hb_c = Next(h), hc_a = Prev(h);   // b->c, c->a in face fa
    const int ha_d = Next(g), hd_b = Prev(g);   // a->d, d->b in face fb
    const int o_cb = opp_[hb_c], o_ac = opp_[hc_a], o_da = opp_[ha_d], o_bd = opp_[hd_b];
    Link(o_cb, o_ac);
    Link(o_da, o_bd);
    for (int e = 3 * fa; e < 3 * fa + 3; ++e) opp_[e] = -1;
    for (int e = 3 * fb; e < 3 * fb + 3; ++e) opp_[e] = -1;
    face_dead_[fa] = face_dead_[fb] = 1;
    vert_dead_[b] = 1;
    out_[b] = -1;
    SetOut(a, o_ac);  // a -> c (a boundary a keeps its boundary half-edge, not in fa or fb)
    if (!boundary_[c]) out_[c] = o_cb;  // c -> a; a boundary c keeps its boundary half-edge (not in fa)
    if (!boundary_[d]) out_[d] = o_da;
    valence_[a] += valence_[b] - 4;
    --valence_[c];
    --valence_[d];
    data_.Merge(a, b, p);
    return true;
  }

  // --- Split ----------------------------------------------------------------------------------------------
  void SplitLongEdges() {
    const float tol = options_.edge_length_tolerance;
    std::vector<std::pair<float, int>> candidates;
    for (int h = 0; h < static_cast<int>(opp_.size()); ++h) {
      if (face_dead_[h / 3] || (InteriorEdge(h) && opp_[h] < h)) continue;
      const float len = Length(h);
      if (len > (1 + tol) * EdgeTarget(From(h), To(h))) candidates.emplace_back(-len, h);
    }
    std::sort(candidates.begin(), candidates.end());  // longest first
    // One split per face and pass: the candidates' half-edge ids stay valid, and the next Remesh() call
    // continues where this one stopped.
    // Faces created by this pass (index >= num_faces) count as touched.
    const int num_faces = static_cast<int>(F_.size());
    std::vector<char> touched(num_faces, 0);
    auto is_touched = [&](int f) { return f >= num_faces || touched[f]; };
    for (const auto& [neg_len, h] : candidates) {
      if (static_cast<int64_t>(P_.size()) >= options_.max_vertices) break;
      const int g = opp_[h];
      if (is_touched(h / 3) || (g >= 0 && is_touched(g / 3))) continue;
      touched[h / 3] = 1;
      if (g >= 0) {
        touched[g / 3] = 1;
        Split(h);
      } else {
        SplitBoundary(h);
      }
      ++stats_.splits;
    }
  }

  // Splits boundary half-edge h = a -> b of face (a, b, c) at its midpoint m into (a, m, c), (m, b, c).
  // The boundary keeps its shape (m lies on it) and gains one edge.
  void SplitBoundary(int h) {
    const int a = From(h), b = To(h), c = From(Prev(h));
    const int o_bc = opp_[Next(h)], o_ca = opp_[Prev(h)];
    const int m = data_.AddMidpoint(a, b);
    out_.push_back(-1);
    boundary_.push_back(1);
    valence_.push_back(3);
    vert_dead_.push_back(0);
    const int f0 = h / 3, f2 = AddFace();
    F_[f0] = Eigen::Vector3i(a, m, c);
    F_[f2] = Eigen::Vector3i(m, b, c);
    Link(3 * f0 + 0, -1);          // a->m: boundary, a's boundary half-edge now
    Link(3 * f0 + 1, 3 * f2 + 2);  // m->c | c->m
    Link(3 * f0 + 2, o_ca);        // c->a
    Link(3 * f2 + 0, -1);          // m->b: boundary, m's boundary half-edge
    Link(3 * f2 + 1, o_bc);        // b->c
    SetOut(b, 3 * f2 + 1);
    SetOut(c, 3 * f0 + 2);
    ++valence_[c];
  }

  // Splits interior half-edge h = a -> b at its midpoint m: faces (a, b, c), (b, a, d) become (a, m, c),
  // (m, b, c), (b, m, d), (m, a, d). The pieces are coplanar with the faces they replace: no fold-over.
  void Split(int h) {
    const int g = opp_[h];
    const int a = From(h), b = To(h), c = From(Prev(h)), d = From(Prev(g));
    const int o_bc = opp_[Next(h)], o_ca = opp_[Prev(h)], o_ad = opp_[Next(g)], o_db = opp_[Prev(g)];
    const int m = data_.AddMidpoint(a, b);
    out_.push_back(-1);
    boundary_.push_back(0);
    valence_.push_back(4);
    vert_dead_.push_back(0);
    const int f0 = h / 3, f1 = g / 3;
    const int f2 = AddFace(), f3 = AddFace();
    F_[f0] = Eigen::Vector3i(a, m, c);
    F_[f2] = Eigen::Vector3i(m, b, c);
    F_[f1] = Eigen::Vector3i(b, m, d);
    F_[f3] = Eigen::Vector3i(m, a, d);
    Link(3 * f0 + 0, 3 * f3 + 0);  // a->m | m->a
    Link(3 * f0 + 1, 3 * f2 + 2);  // m->c | c->m
    Link(3 * f0 + 2, o_ca);        // c->a
    Link(3 * f2 + 0, 3 * f1 + 0);  // m->b | b->m
    Link(3 * f2 + 1, o_bc);        // b->c
    Link(3 * f1 + 1, 3 * f3 + 2);  // m->d | d->m
    Link(3 * f1 + 2, o_db);        // d->b
    Link(3 * f3 + 1, o_ad);        // a->d
    SetOut(a, 3 * f0 + 0);
    SetOut(b, 3 * f2 + 1);
    SetOut(c, 3 * f0 + 2);
    SetOut(d, 3 * f1 + 2);
    out_[m] = 3 * f0 + 1;
    ++valence_[c];
    ++valence_[d];
  }

  // --- Flip -----------------------------------------------------------------------------------------------
  // Flips interior edges when that brings the four vertices' valences closer to 6 (4 on the boundary).
  void FlipEdges() {
    const int num_half_edges = static_cast<int>(opp_.size());
    for (int h = 0; h < num_half_edges; ++h) {
      if (face_dead_[h / 3] || !InteriorEdge(h) || opp_[h] < h) continue;
      if (TryFlip(h)) ++stats_.flips;
    }
  }

  bool TryFlip(int h) {
    const int g = opp_[h];
    const int a = From(h), b = To(h), c = From(Prev(h)), d = From(Prev(g));
    auto ideal = [&](int v) { return boundary_[v] ? 4 : 6; };
    auto dev = [&](int v, int delta) { return std::abs(valence_[v] + delta - ideal(v)); };
    const int before = dev(a, 0) + dev(b, 0) + dev(c, 0) + dev(d, 0);
    const int after = dev(a, -1) + dev(b, -1) + dev(c, 1) + dev(d, 1);
    if (after >= before) return false;
    RemeshStats::Rejections& rejected = stats_.flip_rejected;
    if (c == d) return Refuse(&rejected.link);
    // a and b lose a neighbour: an interior vertex needs 3, a boundary one 2.
    if (valence_[a] - 1 < 3 - boundary_[a] || valence_[b] - 1 < 3 - boundary_[b]) return Refuse(&rejected.valence);
    // The new edge c-d must not exist yet (else the flip duplicates an edge: non-manifold).
    bool exists = false;
    ForEachOutgoing(c, [&](int e) { exists = exists || To(e) == d; });
    if (!exists && boundary_[c]) {
      int last = -1;
      ForEachOutgoing(c, [&](int e) { last = e; });
      exists = last >= 0 && From(Prev(last)) == d;
    }
    if (exists) return Refuse(&rejected.link);
    // New faces (c, a, d), (d, b, c): non-degenerate, and neither folds over against the old pair.
    const Eigen::Vector3f n_old = (P_[b] - P_[a]).cross(P_[c] - P_[a]) + (P_[a] - P_[b]).cross(P_[d] - P_[b]);
    Eigen::Vector3f n0, n1;
    if (Quality(P_[c], P_[a], P_[d], &n0) < kMinQuality || Quality(P_[d], P_[b], P_[c], &n1) < kMinQuality) {
      return Refuse(&rejected.sliver);
    }
    if (!NormalKept(n_old, n0) || !NormalKept(n_old, n1) || n0.dot(n1) <= 0) return Refuse(&rejected.fold_over);
    const Eigen::Vector3f ring_normal = RingNormal(a) + RingNormal(b) + RingNormal(c) + RingNormal(d);
    if (n0.dot(ring_normal) <= 0 || n1.dot(ring_normal) <= 0) return Refuse(&rejected.fold_over);

    const int o_bc = opp_[Next(h)], o_ca = opp_[Prev(h)], o_ad = opp_[Next(g)], o_db = opp_[Prev(g)];
    const int f0 = h / 3, f1 = g / 3;
    F_[f0] = Eigen::Vector3i(c, a, d);
    F_[f1] = Eigen::Vector3i(d, b, c);
    Link(3 * f0 + 0, o_ca);
    Link(3 * f0 + 1, o_ad);
    Link(3 * f1 + 0, o_db);
    Link(3 * f1 + 1, o_bc);
    Link(3 * f0 + 2, 3 * f1 + 2);  // d->c | c->d
    SetOut(a, 3 * f0 + 1);
    SetOut(b, 3 * f1 + 1);
    SetOut(c, 3 * f0 + 0);
    SetOut(d, 3 * f1 + 0);
    --valence_[a];
    --valence_[b];
    ++valence_[c];
    ++valence_[d];
    return true;
  }

  // --- Tangential smoothing -------------------------------------------------------------------------------
  // Moves each interior vertex a fraction `gain` towards its neighbours' centroid, within its tangent plane
  // (the normal part would shrink the surface). A move that would turn an incident face by too much is
  // dropped.
  void SmoothTangentially(float gain) {
    if (gain <= 0) return;
    const size_t nv = P_.size();
    std::vector<Eigen::Vector3f> moved(P_);
    ParallelForRange(0, nv, 256, [&](size_t begin, size_t end) {
      for (size_t vi = begin; vi < end; ++vi) {
        const int v = static_cast<int>(vi);
        if (vert_dead_[v] || boundary_[v] || out_[v] < 0) continue;
        Eigen::Vector3f centroid = Eigen::Vector3f::Zero(), normal = Eigen::Vector3f::Zero();
        int count = 0;
        ForEachOutgoing(v, [&](int e) {
          const Eigen::Vector3f& q1 = P_[To(e)];
          centroid += q1;
          normal += (q1 - P_[v]).cross(P_[From(Prev(e))] - P_[v]);
          ++count;
        });
        if (count == 0 || normal.squaredNorm() <= 0) continue;
        normal.normalize();
        Eigen::Vector3f delta = centroid / static_cast<float>(count) - P_[v];
        delta -= normal * normal.dot(delta);
        const Eigen::Vector3f p = P_[v] + gain * delta;
        bool ok = true;
        ForEachOutgoing(v, [&](int e) {
          const Eigen::Vector3f& q1 = P_[To(e)];
          const Eigen::Vector3f& q2 = P_[From(Prev(e))];
          const Eigen::Vector3f before = (q1 - P_[v]).cross(q2 - P_[v]);
          const Eigen::Vector3f after = (q1 - p).cross(q2 - p);
          if (!NormalKept(before, after) || after.dot(normal) <= 0) ok = false;
        });
        if (ok) moved[v] = p;
      }
    });
    P_ = std::move(moved);
  }

  // Drops dead faces and dead or unreferenced vertices; vertex data arrays are compacted alike.
  void Compact() {
    const int nv = static_cast<int>(P_.size());
    std::vector<int> remap(nv, -1);
    std::vector<char> used(nv, 0);
    for (size_t f = 0; f < F_.size(); ++f) {
      if (!face_dead_[f]) used[F_[f][0]] = used[F_[f][1]] = used[F_[f][2]] = 1;
    }
    int n = 0;
    for (int v = 0; v < nv; ++v) {
      if (!used[v]) continue;
      remap[v] = n;
      P_[n] = P_[v];
      (*data_.m1)[n] = (*data_.m1)[v];
      (*data_.m2)[n] = (*data_.m2)[v];
      (*data_.velocity)[n] = (*data_.velocity)[v];
      T_[n] = T_[v];
      ++n;
    }
    P_.resize(n);
    data_.m1->resize(n);
    data_.m2->resize(n);
    data_.velocity->resize(n);
    T_.resize(n);
    size_t nf = 0;
    for (size_t f = 0; f < F_.size(); ++f) {
      if (face_dead_[f]) continue;
      F_[nf++] = Eigen::Vector3i(remap[F_[f][0]], remap[F_[f][1]], remap[F_[f][2]]);
    }
    F_.resize(nf);
  }

 private:
  static bool Refuse(int* reason) {
    ++*reason;
    return false;
  }
  void Link(int x, int y) {
    if (x >= 0) opp_[x] = y;
    if (y >= 0) opp_[y] = x;
    // A half-edge without twin is its start vertex's boundary half-edge: the ring walk must start there.
    if (x >= 0 && y < 0) out_[From(x)] = x;
  }
  // Interior vertices may start their ring anywhere; boundary ones keep their boundary half-edge.
  void SetOut(int v, int h) {
    if (!boundary_[v]) out_[v] = h;
  }
  int AddFace() {
    F_.emplace_back(0, 0, 0);
    face_dead_.push_back(0);
    opp_.insert(opp_.end(), 3, -1);
    return static_cast<int>(F_.size()) - 1;
  }

  std::vector<Eigen::Vector3i>& F_;
  VertexData data_;
  std::vector<Eigen::Vector3f>& P_;
  std::vector<float>& T_;
  const RemeshOptions& options_;
  std::vector<int> opp_, out_, valence_;
  std::vector<char> boundary_, face_dead_, vert_dead_;
  std::vector<int> ring_a_, ring_b_;
  RemeshStats stats_;
};

// The constructor's option checks, repeated by Step() and Remesh() for options changed since.
void CheckOptions(const RemeshOptions& options) {
  if (!(options.edge_length_min > 0) || !(options.edge_length_max >= options.edge_length_min)) {
    throw InputError("", Msg() << "ContinuousRemesher: bad edge length limits [" << options.edge_length_min << ", "
                               << options.edge_length_max << "]");
  }
  if (!(options.edge_length_tolerance > 0 && options.edge_length_tolerance < 1)) {
    throw InputError("", Msg() << "ContinuousRemesher: edge_length_tolerance must lie in (0, 1), got "
                               << options.edge_length_tolerance);
  }
}

}  // namespace

RemeshStats::Rejections& RemeshStats::Rejections::operator+=(const Rejections& other) {
  boundary += other.boundary;
  link += other.link;
  valence += other.valence;
  sliver += other.sliver;
  fold_over += other.fold_over;
  too_long += other.too_long;
  return *this;
}

RemeshStats& RemeshStats::operator+=(const RemeshStats& other) {
  splits += other.splits;
  collapses += other.collapses;
  flips += other.flips;
  collapse_rejected += other.collapse_rejected;
  flip_rejected += other.flip_rejected;
  return *this;
}

ContinuousRemesher::ContinuousRemesher(std::vector<Eigen::Vector3f> positions, std::vector<Eigen::Vector3i> faces,
                                       const RemeshOptions& options)
    : options_(options), positions_(std::move(positions)), faces_(std::move(faces)) {
  if (positions_.empty() || faces_.empty()) throw InputError("", "ContinuousRemesher: empty mesh");
  for (const Eigen::Vector3f& p : positions_) {
    if (!p.allFinite()) throw InputError("", "ContinuousRemesher: non-finite vertex position");
  }
  const TopologyReport topology = AnalyzeTopology(static_cast<int>(positions_.size()), faces_);
  if (!topology.IsManifold() || topology.inconsistent_edges > 0) {
    throw InputError("", "ContinuousRemesher: the mesh must be manifold and consistently oriented (" +
                             topology.Describe() + ")");
  }
  CheckOptions(options_);
  const size_t n = positions_.size();
  m1_.assign(n, Eigen::Vector3f::Zero());
  m2_.assign(n, 0.0f);
  velocity_.assign(n, Eigen::Vector3f::Zero());
  // Start from the mesh's own resolution (mean incident edge length): the first Remesh() then keeps the
  // input as it is instead of jumping to a limit; the controller takes it from there.
  std::vector<float> sum(n, 0.0f);
  std::vector<int> count(n, 0);
  for (const Eigen::Vector3i& f : faces_) {
    for (int k = 0; k < 3; ++k) {
      const float len = (positions_[f[(k + 1) % 3]] - positions_[f[k]]).norm();
      sum[f[k]] += len;
      sum[f[(k + 1) % 3]] += len;
      count[f[k]] += 1;
      count[f[(k + 1) % 3]] += 1;
    }
  }
  target_length_.resize(n);
  for (size_t v = 0; v < n; ++v) {
    const float mean = count[v] > 0 ? sum[v] / static_cast<float>(count[v]) : options_.edge_length_max;
    target_length_[v] = std::clamp(mean, options_.edge_length_min, options_.edge_length_max);
  }
}

void ContinuousRemesher::Step(const std::vector<Eigen::Vector3f>& grad) {
  CheckOptions(options_);
  SD_CHECK(grad.size() == positions_.size(),
           << "Step: " << grad.size() << " gradients for " << positions_.size() << " vertices");
  ++step_count_;
  const size_t n = positions_.size();
  const RemeshOptions& o = options_;

  // Neighbour centroids for the smoothing of the update (each interior neighbour is counted once per face,
  // i.e. twice: uniform weights). In an oriented manifold, v's outgoing half-edges end at n_1 .. n_k-1 and
  // its incoming ones start at n_2 .. n_k, so XOR-ing all those neighbour ids leaves n_1 ^ n_k: zero exactly
  // when the fan closes, i.e. v is interior. Boundary vertices are smoothed along the rim instead (towards
  // the mean of their two boundary neighbours): smoothing them over the fan would shrink an open surface
  // from its rim, not smoothing them at all lets a noisy rim wander and lengthen without bound.
  std::vector<Eigen::Vector3f> neighbour_sum(n, Eigen::Vector3f::Zero());
  std::vector<float> neighbour_count(n, 0.0f);
  std::vector<int> fan_xor(n, 0);
  if (o.smooth_gain > 0) {
    for (const Eigen::Vector3i& f : faces_) {
      for (int k = 0; k < 3; ++k) {
        const int a = f[k], b = f[(k + 1) % 3];
        neighbour_sum[a] += positions_[b];
        neighbour_sum[b] += positions_[a];
        neighbour_count[a] += 1;
        neighbour_count[b] += 1;
        fan_xor[a] ^= b;
        fan_xor[b] ^= a;
      }
    }
    if (std::any_of(fan_xor.begin(), fan_xor.end(), [](int x) { return x != 0; })) {
      // Open mesh: boundary edges are those with one face.
      const EdgeAdjacency adjacency = BuildEdgeAdjacency(static_cast<int>(n), faces_, DegenerateFaces::kSkip);
      for (int v = 0; v < static_cast<int>(n); ++v) {
        if (fan_xor[v] != 0) {
          neighbour_sum[v] = Eigen::Vector3f::Zero();
          neighbour_count[v] = 0;
        }
      }
      for (int e = 0; e < adjacency.NumEdges(); ++e) {
        if (adjacency.NumFacesOn(e) != 1) continue;
        const int a = adjacency.edges[e][0], b = adjacency.edges[e][1];
        neighbour_sum[a] += positions_[b];
        neighbour_sum[b] += positions_[a];
        neighbour_count[a] += 1;
        neighbour_count[b] += 1;
      }
    }
  }
  const float c1 = 1.0f - std::pow(o.beta1, static_cast<float>(step_count_));
  const float c2 = 1.0f - std::pow(o.beta2, static_cast<float>(step_count_));
  const float lr = o.learning_rate * std::min(1.0f, static_cast<float>(step_count_) * (1 - o.beta1) / kRampSteps);

  ParallelForRange(0, n, 1024, [&](size_t begin, size_t end) {
    for (size_t v = begin; v < end; ++v) {
      const Eigen::Vector3f& g = grad[v];
      m1_[v] = o.beta1 * m1_[v] + (1 - o.beta1) * g;
      m2_[v] = o.beta2 * m2_[v] + (1 - o.beta2) * g.squaredNorm();
      // Adam with one second moment per vertex (not per coordinate), so the step direction is the
      // gradient's; |velocity| is ~1 while the gradient is consistent, ~sqrt((1-b1)/(1+b1)) for noise.
      velocity_[v] = (m1_[v] / c1) / (std::sqrt(m2_[v] / c2) + kEps);
      const float speed = velocity_[v].norm();
      const Eigen::Vector3f p = positions_[v];
      positions_[v] -= lr * target_length_[v] * velocity_[v];
      // Laplacian smoothing of the update (the paper's regulariser): move a fraction smooth_gain * speed
      // towards the neighbours' centroid. Adam gives every vertex a step of ~lr * target length even when its
      // gradient is pure noise, so without this a settled surface turns jagged; scaling by the speed (not by
      // the gradient, whose units are the caller's) keeps it scale-free, and settled vertices keep detail.
      if (o.smooth_gain > 0 && neighbour_count[v] > 0) {
        const Eigen::Vector3f umbrella = p - neighbour_sum[v] / neighbour_count[v];
        positions_[v] -= std::min(1.0f, o.smooth_gain * speed) * umbrella;
      }
      // Edge length controller (paper, Sec. 4): grow the target where the vertex still moves faster than
      // velocity_target, shrink it where it has settled.
      target_length_[v] = std::clamp(target_length_[v] * (1 + o.gain * (speed - o.velocity_target)),
                                     o.edge_length_min, o.edge_length_max);
    }
  });
}

RemeshStats ContinuousRemesher::Remesh() {
  CheckOptions(options_);
  if (!options_.remesh) return {};
  for (float& t : target_length_) t = std::clamp(t, options_.edge_length_min, options_.edge_length_max);
  HalfEdgeMesh mesh(&faces_, VertexData{&positions_, &m1_, &m2_, &velocity_, &target_length_}, options_);
  // Collapse before split (a split right next to a short edge would otherwise be undone at once), flip for
  // valence, then relax tangentially so the next pass sees well-shaped triangles.
  mesh.CollapseShortEdges();
  mesh.SplitLongEdges();
  mesh.FlipEdges();
  mesh.SmoothTangentially(options_.smooth_gain);
  mesh.Compact();
  return mesh.stats();
}

float ContinuousRemesher::MeanTargetEdgeLength() const {
  if (target_length_.empty()) return 0.0f;
  double sum = 0;
  for (float t : target_length_) sum += t;
  return static_cast<float>(sum / static_cast<double>(target_length_.size()));
}

}  // namespace sd::geometry
