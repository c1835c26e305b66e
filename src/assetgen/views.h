#pragma once
// Multi-view sets: the normal maps and silhouettes that supervise mesh refinement, their cameras, the
// Zero123++ v1.2 rig they default to, their folder format, and oracle rendering of a known mesh into them
// (for evaluation and tests).
//
// Frames: world = the object frame the cameras are given in (for the rig: the asset's canonical axes, the
// object normalised into the unit sphere). Normal maps are kept in memory as unit world-frame normals; on
// disk they are 8-bit RGB PNGs with rgb = (n + 1) / 2 in the frame `normal_frame` of cameras.json names:
// "camera" (OpenCV: x right, y down, z forward — what monocular normal estimators predict) or "world".
//
// Folder format (`<dir>/cameras.json`, "format": "synthdrive-views/1"):
//   { "format": "synthdrive-views/1", "normal_frame": "camera",
//     "views": [ { "name": "view_00", "normals": "normal_00.png", "mask": "mask_00.png",
//                  "width": 320, "height": 320, "fx": ..., "fy": ..., "cx": ..., "cy": ...,
//                  "T_world_cam": [[...4x4 row-major...]], "image": "image_00.png" }, ... ] }
// "image" is optional: an sRGB colour picture of the object at that camera (what texture fusion reads).
// Optional too: "synthetic": true for a view a shape prior made, "source": where a real view came from, "known":
// the mask of pixels inside the source camera's image (MultiView::known).
// Masks are 8-bit grey PNGs, 255 = object (soft edges allowed). All views of a set have the same size.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "core/mesh.h"
#include "core/rigid3.h"
#include "raster/raster.h"

namespace sd {

struct ViewCamera {
  std::string name;
  PinholeCamera camera;
  Rigid3d T_world_cam;
};

struct MultiView {
  ViewCamera view;
  ImageF normals;  // 3 channels, unit world-frame normals; (0, 0, 0) outside the object
  ImageF mask;     // 1 channel, 0..1
  ImageF color;    // empty, or 3 channels, linear RGB (the "image" of the view)
  // Empty when every pixel shows the scene; else 1 channel, 1 where the pixel shows the camera's image and 0 where
  // it lies beyond the source image's border (a log object cut by the image edge, its view still framing the
  // whole object): there the silhouette and colour are unknown, so such pixels carve nothing, supervise nothing
  // and texture nothing. cameras.json "known": a grey PNG, 255 = known.
  ImageF known;
  // Made by a shape prior from a real view (rotated about the object's axis, or mirrored), not seen by a
  // camera; texturing prefers real views (texture.h). cameras.json "synthetic": true.
  bool synthetic = false;
  std::string source;  // where a real view came from ("<log> frame 50 back_camera"); cameras.json "source"
};

using MultiViewSet = std::vector<MultiView>;

// Whether every pixel of the view shows the scene (MultiView::known empty or all 1).
bool IsWhole(const MultiView& view);
// The view's silhouette with its unknown pixels counted as object: a view cut by the image border cannot say the
// object is absent there (what carving a visual hull wants).
ImageF MaskOrUnknown(const MultiView& view);

// The Zero123++ v1.2 rig (DESIGN.md): 6 views at azimuth 30°, 90°, …, 330° (from +x towards +y, about +z),
// elevation +20° / -10° alternating, 30° vertical field of view, square images, looking at the origin from
// kRigDistance with +z up in the image. kRigDistance frames the unit sphere with a small margin
// (asin(1/4) = 14.5° < 15°).
constexpr double kRigDistance = 4.0;
std::vector<ViewCamera> Zero123PlusPlusRig(int image_size = 320);
// A camera at (azimuth, elevation) in degrees, `distance` from the origin, looking at it, +z up.
ViewCamera OrbitCamera(const std::string& name, double azimuth_deg, double elevation_deg, double distance,
                       double vertical_fov_deg, int width, int height);

// The sphere about the bounding-box centre of `positions` through the farthest of them: what the rig frames.
struct BoundingSphere {
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();
  float radius = 0;
};
BoundingSphere BoundingSphereOf(const std::vector<Eigen::Vector3f>& positions);

// The clip transform (raster/raster.h) of a camera viewing an object inside `sphere`: z/w spans the sphere
// with half a radius to spare on either side, so objects and rigs of any scale render.
Eigen::Matrix4f ClipFromWorldAround(const PinholeCamera& camera, const Rigid3d& T_world_cam, const BoundingSphere& sphere);
// The camera at `factor` times the resolution: same field of view, pixel centres still at +0.5.
PinholeCamera Supersampled(const PinholeCamera& camera, int factor);
// Output pixel (x, y) of a raster made at Supersampled(camera, ss) (`raster_width` = ss · camera.width): calls
// visit(p) for each of its ss² samples that a triangle covers (p indexes the raster's arrays) and returns how
// many did. The one box-filter resolve of every supersampled render in assetgen.
template <typename Visit>
int VisitCoveredSamples(const raster::RasterBuffer& rast, int raster_width, int x, int y, int ss, Visit&& visit) {
  int covered = 0;
  for (int sy = 0; sy < ss; ++sy) {
    for (int sx = 0; sx < ss; ++sx) {
      const size_t p = static_cast<size_t>(y * ss + sy) * raster_width + (x * ss + sx);
      if (rast.triangle[p] < 0) continue;
      ++covered;
      visit(p);
    }
  }
  return covered;
}
// The mesh rasterised at `camera` with ClipFromWorldAround(camera, T_world_cam, sphere).
raster::RasterBuffer RasterizeView(const TriangleMesh& mesh, const PinholeCamera& camera, const Rigid3d& T_world_cam,
                                   const BoundingSphere& sphere);

// Uniform scale + translation that puts the mesh's vertices into the sphere of `radius` about the origin
// (centre of the bounding box to the origin; farthest vertex at `radius`). p' = scale * (p - centre).
struct SphereNormalization {
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();
  float scale = 1;
  void Apply(TriangleMesh* mesh) const;
  void Undo(TriangleMesh* mesh) const;
};
SphereNormalization NormalizeIntoSphere(const TriangleMesh& mesh, float radius = 1.0f);

// Reads <dir>/cameras.json and the images it names. InputError naming the file for: missing files,
// malformed JSON, unknown normal_frame, images whose size disagrees with their camera or with each other,
// non-positive intrinsics, a non-rigid pose, or no views.
MultiViewSet LoadViews(const std::filesystem::path& dir);
// Writes the folder atomically (staging directory); refuses an existing `dir` unless `overwrite`.
void SaveViews(const MultiViewSet& views, const std::filesystem::path& dir, const std::string& normal_frame,
               bool overwrite);

// Oracle views of a known mesh: exact geometric (face) normals, coverage masks and unlit base colour
// (texture_eval.h RenderAlbedo), anti-aliased by
// `supersample`² samples per pixel. Rendering can use perturbed cameras (the stored cameras stay nominal)
// and the images can be degraded, to mimic what a learned normal estimator and segmenter deliver.
struct OracleDegradation {
  float blur_sigma_px = 0;        // Gaussian blur of normals and masks
  float normal_noise = 0;         // per-pixel Gaussian noise on each normal component (then renormalised)
  float pose_error_deg = 0;       // random rotation of each rendering camera about a random axis
  float pose_error_translation = 0;  // random camera shift (world units)
  uint64_t seed = 1;
  bool Any() const { return blur_sigma_px > 0 || normal_noise > 0 || pose_error_deg > 0 || pose_error_translation > 0; }
};
MultiViewSet RenderOracleViews(const TriangleMesh& mesh, const std::vector<ViewCamera>& cameras, int supersample = 2,
                               const OracleDegradation& degradation = {});

// A false-colour picture of a normal map with its mask (for reports): rgb = (n + 1) / 2, grey background.
ImageU8 NormalMapPreview(const MultiView& view);

}  // namespace sd
