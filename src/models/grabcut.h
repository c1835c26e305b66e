#pragma once
// The classical segmentation path: GrabCut (Rother, Kolmogorov & Blake 2004) from a pixel box.
//
// Pixels outside the box are background (hard); pixels inside are labelled by alternating
//   1. colour models: a Gaussian mixture (full covariance, `components` each) for the background (outside the
//      box and what was last labelled background inside) and one for the foreground, each pixel assigned to its
//      most likely component and the mixtures refitted;
//   2. a minimum s-t cut of the energy  Σ −log p(colour | label)  +  γ Σ_{8-neighbours} [labels differ]
//      · exp(−β‖Δcolour‖²) / distance,  β = 1 / (2 ⟨‖Δcolour‖²⟩) over the image (contrast-sensitive: cutting
//      is cheap across strong edges), solved exactly by MaxFlow below;
// for `iterations` rounds (or until no label changes), then the largest 4-connected foreground component is
// kept and its holes (background not 4-connected to the box border) filled. Colours are sRGB 0..255, as in the
// paper. A prior mask (e.g. LiDAR points projected into the crop) makes its pixels ≥ 0.5 hard foreground,
// which both seeds the foreground model and pins those pixels through the cut.
//
// Only the box's pixels are graph nodes: an edge to a fixed background pixel outside is folded into the
// inside pixel's terminal weight, so the graph is as small as the box.
#include <cstdint>
#include <vector>

#include "core/box3.h"
#include "core/image.h"

namespace sd::models {

struct GrabCutOptions {
  int components = 5;     // Gaussians per colour model
  int iterations = 5;     // model-fit / cut rounds (stops early when no label changes)
  double gamma = 50.0;    // pairwise weight (the paper's value, for 0..255 colours)
  // The first round's object colour model from the sure-foreground pixels alone (when there are at least 64)
  // rather than from every pixel of the box: for a thin object in a wide box (a cone in its projected 3D box)
  // the box is mostly background, and a model learnt from it calls background object.
  bool foreground_from_prior = false;
};

// Min-cut / max-flow on a directed graph with source and sink terminal edges (Boykov & Kolmogorov 2004:
// two search trees grown from the terminals, augmented along found paths, orphans re-adopted; fast on the
// short paths of image grids). Capacities must be ≥ 0; exact on integer capacities.
class MaxFlow {
 public:
  // `edges_hint`: how many AddEdge calls to reserve room for.
  explicit MaxFlow(int nodes, int edges_hint = 0);
  // Adds capacity source→node and node→sink (both may be non-zero; their common part is flow at once).
  void AddTerminal(int node, double source_cap, double sink_cap);
  // Adds an edge pair: capacity a→b `cap_ab` and b→a `cap_ba`.
  void AddEdge(int a, int b, double cap_ab, double cap_ba);
  // Runs to completion and returns the maximum flow (= the minimum cut's capacity). Call once.
  double Solve();
  // After Solve: whether the node is on the source side of a minimum cut (the nodes still reachable from the
  // source in the residual graph).
  bool SourceSide(int node) const;
  int nodes() const { return static_cast<int>(nodes_.size()); }

 private:
  struct Arc {
    int head;  // node the arc points to
    int next;  // next arc out of the same tail, -1 ends the list
    double cap;  // residual capacity; the reverse arc is index ^ 1
  };
  struct Node {
    int first = -1;   // first outgoing arc
    int parent = -1;  // arc to the parent in its tree, or kTerminal / kOrphan; kFree (-1) = in no tree
    bool sink = false;  // tree membership when parent != kFree
    double tr_cap = 0;  // residual terminal capacity: > 0 from the source, < 0 to the sink
    int64_t stamp = 0;  // when dist was last known to lead to a terminal
    int dist = 0;       // tree depth at that time
    bool active = false;
  };
  static constexpr int kFree = -1, kTerminal = -2, kOrphan = -3;

  void Activate(int node);
  double Augment(int s_node, int t_node, int arc);
  void Adopt(int node);

  std::vector<Node> nodes_;
  std::vector<Arc> arcs_;
  std::vector<int> active_, orphans_;
  size_t active_head_ = 0;
  int64_t time_ = 0;
  double flow_ = 0;
};

// The pixels whose centres lie in `box` ([x1, x2) × [y1, y2), continuous pixel coordinates), clipped to a
// width × height image: columns [x0, x1), rows [y0, y1). Empty when the box misses the image.
struct PixelRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool Empty() const { return x1 <= x0 || y1 <= y0; }
  int64_t Area() const { return Empty() ? 0 : static_cast<int64_t>(x1 - x0) * (y1 - y0); }
};
PixelRect PixelsOf(const Box2& box, int width, int height);

// InputError for an empty image, a channel count other than 1, 3 or 4, a box holding no pixel of the image, or
// a prior that is not a 1-channel mask of the image's size: the checks every segmentation path makes first.
void CheckSegmentationInput(const ImageU8& image, const Box2& box, const ImageF* prior);

// Foreground mask (1 channel, image size, 0 or 1). `box` is the object's pixel box, clipped to the image;
// `prior` (optional, 1 channel, image size, 0..1) marks sure foreground; `background` (optional, the same)
// marks sure background inside the box too (a projected 3D box's polygon is tighter than its bounding
// rectangle); sure foreground wins where both are set. InputError when the box has no pixels inside the image.
// The caller checks the result's area.
ImageF GrabCut(const ImageU8& image, const Box2& box, const ImageF* prior = nullptr, const GrabCutOptions& options = {},
               const ImageF* background = nullptr);

// Keeps the largest 4-connected component of mask ≥ 0.5 and fills its holes (background regions not
// 4-connected to the image border). Returns a 0/1 mask.
ImageF LargestComponentFilled(const ImageF& mask);

}  // namespace sd::models
