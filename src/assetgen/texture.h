#pragma once
// Appearance stage (DESIGN.md generate stage "texture fusion"): colour images of an object at known cameras
// fused onto its mesh, as per-vertex colours (the paper's fusion) and as a baked UV texture atlas.
//
// Fusion (the paper's rule): each vertex takes its colour from the view that sees it most head-on — the
// largest cosine between its normal and the direction to the camera — among the views where it is visible
// (depth test against the rasterised mesh, so no colour passes through an occluder); colour seams between
// neighbouring vertices that took different views are smoothed by Laplacian smoothing restricted to the seam
// band; vertices no view sees get colour propagated from their visible neighbours (every vertex ends with one).
//
// Colours are linear RGB in memory (ImageF), sRGB on disk, as everywhere (core/image.h).
#include <vector>

#include <Eigen/Core>

#include "assetgen/views.h"
#include "core/image.h"
#include "core/mesh.h"

namespace sd {

namespace models {
class Upscaler;
}

// One colour image of the object with its camera. `mask` (1 channel, 0..1) may be empty: then every pixel the
// mesh covers counts as object.
struct ColorView {
  ViewCamera view;
  ImageF color;  // 3 channels, linear RGB, camera.width x camera.height
  ImageF mask;   // empty or 1 channel, same size
  // Made by a shape prior (a real view rotated about the axis or mirrored), not seen by a camera: it colours
  // a point only where it sees it clearly more head-on than every real view (kSyntheticViewWeight).
  bool synthetic = false;
};
// Views are ranked by the cosine between the surface normal and the direction to the camera; a synthetic
// view's cosine counts this much: a real view at 60 degrees still beats a synthetic one seen head-on at 0.
constexpr float kSyntheticViewWeight = 0.5f;

// Where a texture's colour came from, as fractions of the surface (texels of the atlas, or vertices): real
// camera pixels, synthetic views (symmetry), or propagated from neighbours (seen by no view).
struct TextureProvenance {
  double real = 0, synthetic = 0, propagated = 0;
};
using ColorViewSet = std::vector<ColorView>;

struct VertexFusionOptions {
  float depth_tolerance = 0.01f;   // relative depth slack of the visibility test (fraction of the camera distance)
  float min_cosine = 0.05f;        // grazing views below this cosine never give colour
  int seam_smoothing_iterations = 3;
  float seam_smoothing_weight = 0.5f;  // per iteration: c <- (1 - w) c + w * mean(neighbours), seam band only
};

struct VertexFusionResult {
  std::vector<Eigen::Vector3f> colors;  // linear RGB, one per vertex
  std::vector<int> source_view;         // the view each vertex took its colour from; -1 = propagated
  int propagated = 0;                   // vertices no view saw
  TextureProvenance provenance;         // by vertex count
};

// InputError when the mesh has no faces, no views are given, or a view's image size disagrees with its camera.
VertexFusionResult FuseVertexColors(const TriangleMesh& mesh, const ColorViewSet& views,
                                    const VertexFusionOptions& options = {});

// The paper's "×2 super-resolution of the views" ahead of fusion: colours go through `upscaler` as sRGB-encoded
// values (what the learned models were trained on), masks are resampled bicubically, and each camera becomes
// the same camera at the new resolution (views.h Supersampled), so geometry and colour stay registered.
ColorViewSet SuperResolveViews(const ColorViewSet& views, const models::Upscaler& upscaler);

}  // namespace sd
