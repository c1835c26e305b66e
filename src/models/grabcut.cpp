#include "models/grabcut.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include <Eigen/Dense>

#include "core/error.h"
#include "core/parallel.h"

namespace sd::models {

// ---------------------------------------------------------------------------------------------------------------
// Max-flow (Boykov–Kolmogorov).

MaxFlow::MaxFlow(int nodes, int edges_hint) : nodes_(static_cast<size_t>(std::max(0, nodes))) {
  arcs_.reserve(2 * static_cast<size_t>(std::max(0, edges_hint)));
}

void MaxFlow::AddTerminal(int node, double source_cap, double sink_cap) {
  SD_CHECK(node >= 0 && node < nodes() && source_cap >= 0 && sink_cap >= 0, << node << " " << source_cap << " "
                                                                             << sink_cap);
  double& tr = nodes_[static_cast<size_t>(node)].tr_cap;
  const double from_source = std::max(tr, 0.0) + source_cap, to_sink = std::max(-tr, 0.0) + sink_cap;
  // source→node→sink carries min(...) at once; only the difference remains a terminal capacity.
  flow_ += std::min(from_source, to_sink);
  tr = from_source - to_sink;
}

void MaxFlow::AddEdge(int a, int b, double cap_ab, double cap_ba) {
  SD_CHECK(a >= 0 && a < nodes() && b >= 0 && b < nodes() && a != b && cap_ab >= 0 && cap_ba >= 0,
           << a << " " << b << " " << cap_ab << " " << cap_ba);
  const int index = static_cast<int>(arcs_.size());  // even: the reverse arc is index ^ 1
  arcs_.push_back({b, nodes_[static_cast<size_t>(a)].first, cap_ab});
  nodes_[static_cast<size_t>(a)].first = index;
  arcs_.push_back({a, nodes_[static_cast<size_t>(b)].first, cap_ba});
  nodes_[static_cast<size_t>(b)].first = index + 1;
}

void MaxFlow::Activate(int node) {
  Node& n = nodes_[static_cast<size_t>(node)];
  if (n.active) return;
  n.active = true;
  active_.push_back(node);
}

// Pushes the path's bottleneck from the source tree's root through s_node →(arc)→ t_node to the sink tree's
// root; nodes whose parent arc (or terminal capacity) saturates become orphans.
double MaxFlow::Augment(int s_node, int t_node, int arc) {
  double bottleneck = arcs_[static_cast<size_t>(arc)].cap;
  for (int k = s_node;;) {
    const Node& n = nodes_[static_cast<size_t>(k)];
    if (n.parent == kTerminal) {
      bottleneck = std::min(bottleneck, n.tr_cap);
      break;
    }
    bottleneck = std::min(bottleneck, arcs_[static_cast<size_t>(n.parent ^ 1)].cap);
    k = arcs_[static_cast<size_t>(n.parent)].head;
  }
  for (int k = t_node;;) {
    const Node& n = nodes_[static_cast<size_t>(k)];
    if (n.parent == kTerminal) {
      bottleneck = std::min(bottleneck, -n.tr_cap);
      break;
    }
    bottleneck = std::min(bottleneck, arcs_[static_cast<size_t>(n.parent)].cap);
    k = arcs_[static_cast<size_t>(n.parent)].head;
  }
  arcs_[static_cast<size_t>(arc)].cap -= bottleneck;
  arcs_[static_cast<size_t>(arc ^ 1)].cap += bottleneck;
  auto orphan = [&](int k) {
    nodes_[static_cast<size_t>(k)].parent = kOrphan;
    orphans_.push_back(k);
  };
  for (int k = s_node;;) {
    Node& n = nodes_[static_cast<size_t>(k)];
    if (n.parent == kTerminal) {
      n.tr_cap -= bottleneck;
      if (n.tr_cap == 0) orphan(k);
      break;
    }
    const int a = n.parent;
    arcs_[static_cast<size_t>(a)].cap += bottleneck;
    arcs_[static_cast<size_t>(a ^ 1)].cap -= bottleneck;
    const int up = arcs_[static_cast<size_t>(a)].head;
    if (arcs_[static_cast<size_t>(a ^ 1)].cap == 0) orphan(k);
    k = up;
  }
  for (int k = t_node;;) {
    Node& n = nodes_[static_cast<size_t>(k)];
    if (n.parent == kTerminal) {
      n.tr_cap += bottleneck;
      if (n.tr_cap == 0) orphan(k);
      break;
    }
    const int a = n.parent;
    arcs_[static_cast<size_t>(a)].cap -= bottleneck;
    arcs_[static_cast<size_t>(a ^ 1)].cap += bottleneck;
    const int up = arcs_[static_cast<size_t>(a)].head;
    if (arcs_[static_cast<size_t>(a)].cap == 0) orphan(k);
    k = up;
  }
  return bottleneck;
}

// An orphan looks for a new parent in its own tree whose path reaches the terminal (the shortest such, by the
// distances stamped this round); without one it leaves the tree, its children become orphans and the tree
// nodes that could grow into it again become active.
void MaxFlow::Adopt(int node) {
  Node& n = nodes_[static_cast<size_t>(node)];
  int best = -1, best_dist = std::numeric_limits<int>::max();
  // Residual capacity from the neighbour towards the node (source tree) or from the node towards it (sink tree).
  auto usable = [&](int a) { return n.sink ? arcs_[static_cast<size_t>(a)].cap > 0 : arcs_[static_cast<size_t>(a ^ 1)].cap > 0; };
  for (int a = n.first; a >= 0; a = arcs_[static_cast<size_t>(a)].next) {
    if (!usable(a)) continue;
    const int j = arcs_[static_cast<size_t>(a)].head;
    const Node& m = nodes_[static_cast<size_t>(j)];
    if (m.parent == kFree || m.sink != n.sink) continue;
    int d = 0;
    bool rooted = true;
    for (int k = j;;) {
      Node& q = nodes_[static_cast<size_t>(k)];
      if (q.stamp == time_) {
        d += q.dist;
        break;
      }
      ++d;
      if (q.parent == kTerminal) {
        q.stamp = time_;
        q.dist = 1;
        break;
      }
      if (q.parent == kOrphan) {
        rooted = false;
        break;
      }
      k = arcs_[static_cast<size_t>(q.parent)].head;
    }
    if (!rooted) continue;
    if (d < best_dist) {
      best_dist = d;
      best = a;
    }
    for (int k = j, dk = d; nodes_[static_cast<size_t>(k)].stamp != time_;
         k = arcs_[static_cast<size_t>(nodes_[static_cast<size_t>(k)].parent)].head, --dk) {
      nodes_[static_cast<size_t>(k)].stamp = time_;
      nodes_[static_cast<size_t>(k)].dist = dk;
    }
  }
  if (best >= 0) {
    n.parent = best;
    n.stamp = time_;
    n.dist = best_dist + 1;
    return;
  }
  n.parent = kFree;
  for (int a = n.first; a >= 0; a = arcs_[static_cast<size_t>(a)].next) {
    const int j = arcs_[static_cast<size_t>(a)].head;
    Node& m = nodes_[static_cast<size_t>(j)];
    if (m.parent == kFree || m.sink != n.sink) continue;
    if (usable(a)) Activate(j);
    if (m.parent >= 0 && arcs_[static_cast<size_t>(m.parent)].head == node) {
      m.parent = kOrphan;
      orphans_.push_back(j);
    }
  }
}

double MaxFlow::Solve() {
  for (int i = 0; i < nodes(); ++i) {
    Node& n = nodes_[static_cast<size_t>(i)];
    if (n.tr_cap == 0) continue;
    n.sink = n.tr_cap < 0;
    n.parent = kTerminal;
    n.dist = 1;
    n.stamp = 0;
    Activate(i);
  }
  int current = -1;
  for (;;) {
    int i = current;
    if (i < 0 || nodes_[static_cast<size_t>(i)].parent == kFree) {
      i = -1;
      while (active_head_ < active_.size()) {
        const int k = active_[active_head_++];
        nodes_[static_cast<size_t>(k)].active = false;
        if (nodes_[static_cast<size_t>(k)].parent != kFree) {
          i = k;
          break;
        }
      }
      if (active_head_ > 4096 && 2 * active_head_ > active_.size()) {
        active_.erase(active_.begin(), active_.begin() + static_cast<std::ptrdiff_t>(active_head_));
        active_head_ = 0;
      }
      if (i < 0) break;
    }
    current = -1;
    // Growth: the node's tree takes its free neighbours until it touches the other tree.
    int s_node = -1, t_node = -1, mid = -1;
    Node& n = nodes_[static_cast<size_t>(i)];
    for (int a = n.first; a >= 0; a = arcs_[static_cast<size_t>(a)].next) {
      const bool open = n.sink ? arcs_[static_cast<size_t>(a ^ 1)].cap > 0 : arcs_[static_cast<size_t>(a)].cap > 0;
      if (!open) continue;
      const int j = arcs_[static_cast<size_t>(a)].head;
      Node& m = nodes_[static_cast<size_t>(j)];
      if (m.parent == kFree) {
        m.sink = n.sink;
        m.parent = a ^ 1;
        m.stamp = n.stamp;
        m.dist = n.dist + 1;
        Activate(j);
      } else if (m.sink != n.sink) {
        s_node = n.sink ? j : i;
        t_node = n.sink ? i : j;
        mid = n.sink ? (a ^ 1) : a;
        break;
      }
    }
    if (mid < 0) continue;
    current = i;  // it may have more neighbours to grow into
    ++time_;
    flow_ += Augment(s_node, t_node, mid);
    while (!orphans_.empty()) {
      const int o = orphans_.back();
      orphans_.pop_back();
      Adopt(o);
    }
  }
  return flow_;
}

bool MaxFlow::SourceSide(int node) const {
  const Node& n = nodes_[static_cast<size_t>(node)];
  return n.parent != kFree && !n.sink;
}

// ---------------------------------------------------------------------------------------------------------------
// Colour models.

namespace {

using Vec3 = Eigen::Vector3d;

struct Gaussian {
  Vec3 mean = Vec3::Zero();
  Eigen::Matrix3d inverse = Eigen::Matrix3d::Identity();
  double log_weight_norm = 0;  // log(weight) − ½ log det Σ − (3/2) log 2π
};

// Colour variance added to every covariance (0..255 units): keeps flat synthetic regions and tiny components
// from producing singular matrices and unbounded likelihoods.
constexpr double kCovarianceRidge = 4.0;

struct Gmm {
  std::vector<Gaussian> parts;

  double LogComponent(size_t k, const float* c) const {
    const Gaussian& g = parts[k];
    const Vec3 d(c[0] - g.mean[0], c[1] - g.mean[1], c[2] - g.mean[2]);
    return g.log_weight_norm - 0.5 * d.dot(g.inverse * d);
  }
  double NegLogLikelihood(const float* c) const {
    double best = -std::numeric_limits<double>::infinity();
    std::array<double, 16> logs{};
    const size_t n = std::min(parts.size(), logs.size());
    for (size_t k = 0; k < n; ++k) best = std::max(best, logs[k] = LogComponent(k, c));
    double sum = 0;
    for (size_t k = 0; k < n; ++k) sum += std::exp(logs[k] - best);
    return -(best + std::log(sum));
  }
  int MostLikely(const float* c) const {
    int best = 0;
    double best_log = -std::numeric_limits<double>::infinity();
    for (size_t k = 0; k < parts.size(); ++k) {
      const double l = LogComponent(k, c);
      if (l > best_log) best_log = l, best = static_cast<int>(k);
    }
    return best;
  }
};

// Fits one Gaussian per label from samples (3 floats each) and their component labels; empty labels are dropped.
Gmm Fit(const std::vector<float>& samples, const std::vector<int>& label, int components) {
  const size_t n = label.size();
  std::vector<Vec3> sum(static_cast<size_t>(components), Vec3::Zero());
  std::vector<Eigen::Matrix3d> outer(static_cast<size_t>(components), Eigen::Matrix3d::Zero());
  std::vector<double> count(static_cast<size_t>(components), 0);
  for (size_t i = 0; i < n; ++i) {
    const Vec3 c(samples[3 * i], samples[3 * i + 1], samples[3 * i + 2]);
    const auto k = static_cast<size_t>(label[i]);
    sum[k] += c;
    outer[k] += c * c.transpose();
    count[k] += 1;
  }
  Gmm gmm;
  for (size_t k = 0; k < static_cast<size_t>(components); ++k) {
    if (count[k] < 1) continue;
    Gaussian g;
    g.mean = sum[k] / count[k];
    Eigen::Matrix3d cov = outer[k] / count[k] - g.mean * g.mean.transpose();
    cov += kCovarianceRidge * Eigen::Matrix3d::Identity();
    g.inverse = cov.inverse();
    g.log_weight_norm = std::log(count[k] / static_cast<double>(n)) - 0.5 * std::log(cov.determinant()) -
                        1.5 * std::log(2 * std::numbers::pi);
    gmm.parts.push_back(g);
  }
  return gmm;
}

// k-means++ seeding (fixed seed: deterministic results) and a few Lloyd rounds on at most ~20k of the samples;
// returns every sample's nearest centre.
std::vector<int> KMeansLabels(const std::vector<float>& samples, int k) {
  const size_t n = samples.size() / 3;
  const size_t stride = std::max<size_t>(1, n / 20000);
  std::vector<size_t> pick;
  for (size_t i = 0; i < n; i += stride) pick.push_back(i);
  auto dist2 = [&](size_t i, const Vec3& c) {
    const double a = samples[3 * i] - c[0], b = samples[3 * i + 1] - c[1], d = samples[3 * i + 2] - c[2];
    return a * a + b * b + d * d;
  };
  auto at = [&](size_t i) { return Vec3(samples[3 * i], samples[3 * i + 1], samples[3 * i + 2]); };
  std::mt19937 rng(12345);
  std::vector<Vec3> centres{at(pick[rng() % pick.size()])};
  std::vector<double> d2(pick.size(), std::numeric_limits<double>::infinity());
  while (static_cast<int>(centres.size()) < k) {
    double total = 0;
    for (size_t p = 0; p < pick.size(); ++p) total += d2[p] = std::min(d2[p], dist2(pick[p], centres.back()));
    if (total <= 0) break;  // fewer distinct colours than components
    double r = std::uniform_real_distribution<double>(0, total)(rng);
    size_t chosen = pick.size() - 1;
    for (size_t p = 0; p < pick.size(); ++p)
      if ((r -= d2[p]) <= 0) {
        chosen = p;
        break;
      }
    centres.push_back(at(pick[chosen]));
  }
  auto nearest = [&](size_t i) {
    int best = 0;
    double best_d = std::numeric_limits<double>::infinity();
    for (size_t c = 0; c < centres.size(); ++c) {
      const double d = dist2(i, centres[c]);
      if (d < best_d) best_d = d, best = static_cast<int>(c);
    }
    return best;
  };
  for (int round = 0; round < 8; ++round) {
    std::vector<Vec3> sum(centres.size(), Vec3::Zero());
    std::vector<double> count(centres.size(), 0);
    for (size_t i : pick) {
      const int c = nearest(i);
      sum[static_cast<size_t>(c)] += at(i);
      count[static_cast<size_t>(c)] += 1;
    }
    for (size_t c = 0; c < centres.size(); ++c)
      if (count[c] > 0) centres[c] = sum[c] / count[c];
  }
  std::vector<int> label(n);
  for (size_t i = 0; i < n; ++i) label[i] = nearest(i);
  return label;
}

// One GrabCut colour model: k-means the first time, then (the paper's step 1) each sample to its most likely
// component of the previous model and refit.
Gmm LearnGmm(const std::vector<float>& samples, const Gmm* previous, int components) {
  const size_t n = samples.size() / 3;
  std::vector<int> label;
  if (previous == nullptr || previous->parts.empty()) {
    label = KMeansLabels(samples, components);
  } else {
    label.resize(n);
    ParallelFor(0, n, [&](size_t i) { label[i] = previous->MostLikely(&samples[3 * i]); }, 4096);
  }
  return Fit(samples, label, components);
}

enum Label : uint8_t { kHardBackground = 0, kHardForeground = 1, kForeground = 2, kBackground = 3 };

}  // namespace

PixelRect PixelsOf(const Box2& box, int width, int height) {
  PixelRect r;
  if (!(std::isfinite(box.x1) && std::isfinite(box.y1) && std::isfinite(box.x2) && std::isfinite(box.y2))) return r;
  // Pixel x's centre x + 0.5 lies in [x1, x2) ⇔ ceil(x1 − 0.5) ≤ x < ceil(x2 − 0.5).
  auto lo = [](double v, int n) { return static_cast<int>(std::clamp(std::ceil(v - 0.5), 0.0, static_cast<double>(n))); };
  r.x0 = lo(box.x1, width);
  r.x1 = lo(box.x2, width);
  r.y0 = lo(box.y1, height);
  r.y1 = lo(box.y2, height);
  return r;
}

void CheckSegmentationInput(const ImageU8& image, const Box2& box, const ImageF* prior) {
  const int w = image.width(), h = image.height(), ch = image.channels();
  if (image.empty()) throw InputError({}, "segmentation: empty image");
  if (ch != 1 && ch != 3 && ch != 4) throw InputError({}, Msg() << "segmentation: " << ch << "-channel image");
  if (PixelsOf(box, w, h).Empty())
    throw InputError({}, Msg() << "segmentation: the box (" << box.x1 << ", " << box.y1 << ") - (" << box.x2 << ", "
                               << box.y2 << ") holds no pixel of the " << w << "x" << h << " image");
  if (prior != nullptr && (prior->width() != w || prior->height() != h || prior->channels() != 1))
    throw InputError({}, Msg() << "segmentation: the prior mask is " << prior->width() << "x" << prior->height() << "x"
                               << prior->channels() << ", the image " << w << "x" << h << " (1 channel expected)");
}

ImageF GrabCut(const ImageU8& image, const Box2& box, const ImageF* prior, const GrabCutOptions& options,
               const ImageF* background) {
  CheckSegmentationInput(image, box, prior);
  CheckSegmentationInput(image, box, background);
  const int w = image.width(), h = image.height(), ch = image.channels();
  const PixelRect r = PixelsOf(box, w, h);
  SD_CHECK(options.components >= 1 && options.components <= 16 && options.iterations >= 1, << options.components);
  const size_t n = static_cast<size_t>(w) * static_cast<size_t>(h);
  // Colours as floats 0..255.
  std::vector<float> rgb(3 * n);
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) rgb[3 * i + static_cast<size_t>(c)] = image.vector()[i * static_cast<size_t>(ch) + static_cast<size_t>(ch >= 3 ? c : 0)];
  auto index = [w](int x, int y) { return static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(x); };

  std::vector<uint8_t> label(n, kHardBackground);
  for (int y = r.y0; y < r.y1; ++y)
    for (int x = r.x0; x < r.x1; ++x) {
      const size_t i = index(x, y);
      label[i] = prior != nullptr && prior->vector()[i] >= 0.5f             ? kHardForeground
                 : background != nullptr && background->vector()[i] >= 0.5f ? kHardBackground
                                                                              : kForeground;
    }

  // Pairwise weights to the right, down, down-right and down-left neighbours: γ exp(−β‖Δ‖²) / distance.
  constexpr std::array<std::array<int, 2>, 4> kOffsets{{{1, 0}, {0, 1}, {1, 1}, {-1, 1}}};
  auto diff2 = [&](size_t a, size_t b) {
    double s = 0;
    for (int c = 0; c < 3; ++c) {
      const double d = rgb[3 * a + static_cast<size_t>(c)] - rgb[3 * b + static_cast<size_t>(c)];
      s += d * d;
    }
    return s;
  };
  std::vector<double> row_sum(static_cast<size_t>(h), 0.0), row_count(static_cast<size_t>(h), 0.0);
  ParallelRows(0, h, [&](int y) {
    for (int x = 0; x < w; ++x)
      for (const auto& o : kOffsets) {
        const int qx = x + o[0], qy = y + o[1];
        if (qx < 0 || qx >= w || qy >= h) continue;
        row_sum[static_cast<size_t>(y)] += diff2(index(x, y), index(qx, qy));
        row_count[static_cast<size_t>(y)] += 1;
      }
  });
  double sum = 0, count = 0;
  for (int y = 0; y < h; ++y) sum += row_sum[static_cast<size_t>(y)], count += row_count[static_cast<size_t>(y)];
  const double beta = sum > 0 ? count / (2 * sum) : 0.0;
  std::vector<std::array<double, 4>> pair(n);
  ParallelRows(0, h, [&](int y) {
    for (int x = 0; x < w; ++x)
      for (size_t k = 0; k < kOffsets.size(); ++k) {
        const int qx = x + kOffsets[k][0], qy = y + kOffsets[k][1];
        const double dist = k < 2 ? 1.0 : std::numbers::sqrt2;
        pair[index(x, y)][k] = qx < 0 || qx >= w || qy >= h
                                   ? 0.0
                                   : options.gamma * std::exp(-beta * diff2(index(x, y), index(qx, qy))) / dist;
      }
  });

  // When too little of the image lies outside the box, its outer ring stands in as background colour samples.
  const int64_t outside = static_cast<int64_t>(n) - r.Area();
  const int ring = std::max(2, std::min(r.x1 - r.x0, r.y1 - r.y0) / 20);
  auto in_ring = [&](int x, int y) { return x < r.x0 + ring || x >= r.x1 - ring || y < r.y0 + ring || y >= r.y1 - ring; };

  const int bw = r.x1 - r.x0, bh = r.y1 - r.y0;
  const size_t nodes = static_cast<size_t>(bw) * static_cast<size_t>(bh);
  // The graph's pairwise edges are the same every round: built once, copied per round.
  MaxFlow edges(static_cast<int>(nodes), static_cast<int>(4 * nodes));
  std::vector<double> to_fixed_bg(nodes, 0.0);  // pairwise terms with hard background neighbours outside the box
  auto in_box = [&](int x, int y) { return x >= r.x0 && x < r.x1 && y >= r.y0 && y < r.y1; };
  for (int y = 0; y < bh; ++y)
    for (int x = 0; x < bw; ++x) {
      const int node = y * bw + x;
      const size_t i = index(r.x0 + x, r.y0 + y);
      for (size_t k = 0; k < kOffsets.size(); ++k) {
        // Forward neighbour (x + o): an edge inside the box, or a fixed background pixel outside it.
        const int fx = r.x0 + x + kOffsets[k][0], fy = r.y0 + y + kOffsets[k][1];
        if (fx >= 0 && fx < w && fy < h) {
          if (in_box(fx, fy))
            edges.AddEdge(node, (fy - r.y0) * bw + (fx - r.x0), pair[i][k], pair[i][k]);
          else
            to_fixed_bg[static_cast<size_t>(node)] += pair[i][k];
        }
        // Backward neighbour (x − o) outside the box: its weight is stored at that neighbour.
        const int bx = r.x0 + x - kOffsets[k][0], by = r.y0 + y - kOffsets[k][1];
        if (bx >= 0 && bx < w && by >= 0 && !in_box(bx, by)) to_fixed_bg[static_cast<size_t>(node)] += pair[index(bx, by)][k];
      }
    }
  std::vector<double> cost_fg(nodes), cost_bg(nodes);
  Gmm fg_model, bg_model;
  const double hard = 1e9;
  MaxFlow graph(0);
  size_t hard_fg = 0;
  for (uint8_t l : label) hard_fg += l == kHardForeground;
  const bool seeded_start = options.foreground_from_prior && hard_fg >= 64;
  for (int iteration = 0; iteration < options.iterations; ++iteration) {
    std::vector<float> fg_samples, bg_samples;
    fg_samples.reserve(3 * static_cast<size_t>(r.Area()));
    bg_samples.reserve(3 * n);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const size_t i = index(x, y);
        const bool is_fg = label[i] == kForeground || label[i] == kHardForeground;
        // A seeded start learns the object from the seeds; the box's other pixels then count for neither model.
        if (seeded_start && iteration == 0 && label[i] == kForeground) continue;
        std::vector<float>& dst = is_fg ? fg_samples : bg_samples;
        dst.insert(dst.end(), &rgb[3 * i], &rgb[3 * i] + 3);
        if (outside < 64 && iteration == 0 && label[i] != kHardBackground && in_ring(x, y))
          bg_samples.insert(bg_samples.end(), &rgb[3 * i], &rgb[3 * i] + 3);
      }
    if (fg_samples.size() < 3 * 8 || bg_samples.size() < 3 * 8) break;
    fg_model = LearnGmm(fg_samples, iteration == 0 ? nullptr : &fg_model, options.components);
    bg_model = LearnGmm(bg_samples, iteration == 0 ? nullptr : &bg_model, options.components);

    ParallelFor(0, static_cast<size_t>(bh), [&](size_t yy) {
      for (int x = 0; x < bw; ++x) {
        const size_t node = yy * static_cast<size_t>(bw) + static_cast<size_t>(x);
        const float* c = &rgb[3 * index(r.x0 + x, r.y0 + static_cast<int>(yy))];
        cost_fg[node] = fg_model.NegLogLikelihood(c);
        cost_bg[node] = bg_model.NegLogLikelihood(c);
      }
    });
    // Source side = foreground: the source edge carries the cost of calling the pixel background, the sink edge
    // the cost of calling it foreground; costs are shifted to be ≥ 0 per pixel (only differences matter).
    graph = edges;  // reuses the previous round's buffers
    for (int node = 0; node < static_cast<int>(nodes); ++node) {
      const auto k = static_cast<size_t>(node);
      const uint8_t fixed = label[index(r.x0 + node % bw, r.y0 + node / bw)];
      if (fixed == kHardForeground) {
        graph.AddTerminal(node, hard, 0);
      } else if (fixed == kHardBackground) {
        graph.AddTerminal(node, 0, hard);
      } else {
        const double lo = std::min(cost_fg[k], cost_bg[k]);
        graph.AddTerminal(node, cost_bg[k] - lo, cost_fg[k] - lo + to_fixed_bg[k]);
      }
    }
    graph.Solve();
    size_t changed = 0;
    for (int y = 0; y < bh; ++y)
      for (int x = 0; x < bw; ++x) {
        const size_t i = index(r.x0 + x, r.y0 + y);
        if (label[i] == kHardForeground || label[i] == kHardBackground) continue;
        const uint8_t now = graph.SourceSide(y * bw + x) ? kForeground : kBackground;
        changed += now != label[i];
        label[i] = now;
      }
    if (changed == 0 && iteration > 0) break;
  }
  ImageF mask(w, h, 1, 0.0f);
  for (size_t i = 0; i < n; ++i)
    mask.vector()[i] = label[i] == kForeground || label[i] == kHardForeground ? 1.0f : 0.0f;
  return LargestComponentFilled(mask);
}

namespace {

// 4-connected flood fill from `seed` over pixels with member(i), writing `id` into `comp`; returns the size.
template <typename Member>
size_t Flood(int w, int h, size_t seed, int id, std::vector<int>* comp, const Member& member) {
  std::vector<size_t> stack{seed};
  (*comp)[seed] = id;
  size_t size = 0;
  while (!stack.empty()) {
    const size_t p = stack.back();
    stack.pop_back();
    ++size;
    const int x = static_cast<int>(p % static_cast<size_t>(w)), y = static_cast<int>(p / static_cast<size_t>(w));
    const std::array<std::array<int, 2>, 4> nb{{{x - 1, y}, {x + 1, y}, {x, y - 1}, {x, y + 1}}};
    for (const auto& q : nb) {
      if (q[0] < 0 || q[1] < 0 || q[0] >= w || q[1] >= h) continue;
      const size_t qi = static_cast<size_t>(q[1]) * static_cast<size_t>(w) + static_cast<size_t>(q[0]);
      if ((*comp)[qi] == -1 && member(qi)) {
        (*comp)[qi] = id;
        stack.push_back(qi);
      }
    }
  }
  return size;
}

}  // namespace

ImageF LargestComponentFilled(const ImageF& mask) {
  const int w = mask.width(), h = mask.height();
  const size_t n = static_cast<size_t>(w) * static_cast<size_t>(h);
  std::vector<int> comp(n, -1);
  auto fg = [&](size_t i) { return mask.vector()[i] >= 0.5f; };
  int best = -1, next = 0;
  size_t best_size = 0;
  for (size_t i = 0; i < n; ++i) {
    if (comp[i] != -1 || !fg(i)) continue;
    const size_t size = Flood(w, h, i, next, &comp, fg);
    if (size > best_size) best_size = size, best = next;
    ++next;
  }
  ImageF out(w, h, 1, 0.0f);
  if (best < 0) return out;
  // Background = what the image border reaches without crossing the kept component; the rest is the object.
  std::vector<int> reach(n, -1);
  auto open = [&](size_t i) { return comp[i] != best; };
  auto seed = [&](int x, int y) {
    const size_t i = static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(x);
    if (reach[i] == -1 && open(i)) Flood(w, h, i, 0, &reach, open);
  };
  for (int x = 0; x < w; ++x) seed(x, 0), seed(x, h - 1);
  for (int y = 0; y < h; ++y) seed(0, y), seed(w - 1, y);
  for (size_t i = 0; i < n; ++i) out.vector()[i] = reach[i] == 0 ? 0.0f : 1.0f;
  return out;
}

}  // namespace sd::models
