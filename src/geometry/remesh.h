#pragma once
// Continuous remeshing for inverse rendering (after Palfinger, "Continuous Remeshing for Inverse Rendering",
// CAVW 2022): an Adam-like optimiser whose per-vertex step and per-vertex target edge length adapt to how
// fast each vertex moves, interleaved with local remeshing (edge split / collapse / flip and tangential
// smoothing) that keeps the mesh manifold and free of fold-overs. Where the surface still moves, edges get
// longer (fast, robust progress); where it has settled, they get shorter so fine detail can appear.
#include <vector>

#include <Eigen/Core>

namespace sd::geometry {

struct RemeshOptions {
  float learning_rate = 0.3f;        // step relative to the vertex's target edge length
  float beta1 = 0.8f;                // momentum of the gradient
  float beta2 = 0.99f;               // momentum of the squared gradient norm
  // Step: each vertex also moves smooth_gain * speed of the way to its neighbours' centroid (Laplacian
  // smoothing of the update; boundary vertices towards their two rim neighbours). Remesh: tangential
  // relaxation of interior vertices by this fraction.
  float smooth_gain = 0.2f;
  float edge_length_min = 0.005f;    // target edge length limits (in the mesh's units)
  float edge_length_max = 0.15f;
  float edge_length_tolerance = 0.5f;  // split above (1 + tol) * target, collapse below (1 - tol) * target
  float gain = 0.2f;                 // how fast the target edge length follows the vertex velocity
  // Speed |m1_hat| / sqrt(m2_hat) of the Adam step at which the target edge length is stable: ~1 while the
  // gradient points one way, ~0.33 for pure 3D noise (sqrt((1 - b1) / (1 + b1)), beta1 = 0.8) and less for a
  // vertex oscillating around its optimum, so 0.4 grows edges while the surface travels and shrinks them
  // (down to edge_length_min) once it has settled, noise or not.
  float velocity_target = 0.4f;
  bool remesh = true;                // false: plain adaptive optimiser, topology fixed
  // Splits stop at this many vertices: a safety net (the paper's reference code has one too) for gradients
  // so noisy that the surface crumples and keeps asking for more vertices.
  int max_vertices = 1000000;
};

// What one Remesh() pass did. A rejection is a wanted operation that was refused: the collapse of an edge
// shorter than (1 - tol) * target, or a flip that would bring the valences closer to 6 (4 on the boundary).
// Each refusal is counted once, under the first test it failed; candidates that an earlier operation of the
// same pass already changed are dropped without counting.
struct RemeshStats {
  struct Rejections {
    int boundary = 0;   // collapse: another edge of the two faces lies on the boundary, which stays as it is
    int link = 0;       // the surface would pinch (collapse: link condition) or an edge would double (flip)
    int valence = 0;    // a vertex would keep too few neighbours, or (collapse) the merged one too many
    int sliver = 0;     // a resulting face would fall below the quality floor
    int fold_over = 0;  // a resulting face would turn too far, or against the surrounding surface
    int too_long = 0;   // collapse: a resulting edge would be split again at once
    int Total() const { return boundary + link + valence + sliver + fold_over + too_long; }
    Rejections& operator+=(const Rejections& other);
  };
  int splits = 0;  // interior and boundary edges split at their midpoints
  int collapses = 0;
  int flips = 0;
  Rejections collapse_rejected, flip_rejected;

  RemeshStats& operator+=(const RemeshStats& other);
};

class ContinuousRemesher {
 public:
  // Throws InputError when the mesh is empty, not manifold or not consistently oriented, or the options are
  // out of range (edge length limits not 0 < min <= max, tolerance outside (0, 1)). Target edge lengths start
  // at each vertex's mean edge length (clamped to the limits).
  ContinuousRemesher(std::vector<Eigen::Vector3f> positions, std::vector<Eigen::Vector3i> faces,
                     const RemeshOptions& options);

  const std::vector<Eigen::Vector3f>& positions() const { return positions_; }
  const std::vector<Eigen::Vector3i>& faces() const { return faces_; }
  const RemeshOptions& options() const { return options_; }
  // Options changed here are checked as the constructor checks them, at the next Step() or Remesh(): that
  // call throws the same InputError and leaves the mesh and the optimiser state as they were.
  RemeshOptions& mutable_options() { return options_; }

  // One optimiser step from dL/dpositions (one entry per current vertex).
  void Step(const std::vector<Eigen::Vector3f>& grad);
  // One pass of split / collapse / flip / tangential smoothing towards the per-vertex target lengths.
  // Optimiser state follows the vertices (new vertices interpolate it). Keeps the mesh manifold; an edge
  // operation that would fold a face over or create a non-manifold configuration is skipped. Open meshes keep
  // their boundary curve: boundary edges are split at midpoints but never collapsed or flipped, and boundary
  // vertices are never moved or removed by Remesh() (Step still moves them). Vertex and face arrays are
  // renumbered compactly (unreferenced vertices are dropped), so callers re-read positions() and faces().
  // No-op (all counts zero) when options().remesh is false.
  RemeshStats Remesh();

  float MeanTargetEdgeLength() const;

 private:
  RemeshOptions options_;
  std::vector<Eigen::Vector3f> positions_;
  std::vector<Eigen::Vector3i> faces_;
  // Per-vertex optimiser state.
  std::vector<Eigen::Vector3f> m1_;  // first moment of the gradient
  std::vector<float> m2_;            // second moment of the gradient norm
  std::vector<Eigen::Vector3f> velocity_;
  std::vector<float> target_length_;
  int step_count_ = 0;
};

}  // namespace sd::geometry
