#pragma once
// Monocular normal estimation: a camera-frame normal per pixel from one colour image, what refinement is
// supervised with (assetgen/views.h, normal_frame "camera") when the views come from a generator, not a mesh.
//
// Contract "normal_estimation" (runtime.h; docs/models.md):
//   input  "image":   [N, 3, H, W] float32, RGB, sRGB-encoded, 0..1, NCHW; H and W multiples of
//                     params.multiple (8 for convolutional U-Nets, 14 for DINOv2-patch models). Any
//                     normalisation the network needs is inside the exported module.
//   output "normals": [N, 3, H, W] float32, the surface normal in the camera frame of OpenCV — x right, y down,
//                     z forward (into the scene), the frame of views.h's "camera" normals. A normal points out
//                     of the surface, so every surface the camera sees faces it: n·z < 0; a wall facing the
//                     camera head-on is (0, 0, -1). (Estimators trained in OpenGL's frame — x right, y up, z
//                     towards the viewer, facing normals with z > 0 — have y and z negated in the exporter.)
//                     Not necessarily unit length: the C++ side renormalises.
//   params: "multiple".
//
// NormalEstimator pads the image to the next multiple by replicating its border (no hard edge for the network
// to explain), runs it and crops back to the input size.
//
// Classical path: none. A normal from one image is shape-from-shading, which needs known lighting and albedo;
// no sound single-image method exists for arbitrary photographs, so without a model file the stage refuses,
// naming the file it needs (Resolve("auto")).
#include <filesystem>
#include <memory>
#include <string>

#include "core/image.h"
#include "models/runtime.h"

namespace sd::models {

constexpr const char* kNormalEstimationStage = "normal_estimation";
constexpr const char* kNormalEstimatorFile = "normal_estimator.pt";  // the installed default in DefaultModelDir()

class NormalEstimator {
 public:
  // InputError naming the file when it is unusable (runtime.h), its multiple is not a positive integer, or its
  // contract does not map one [N, 3, H, W] image to [N, 3, H, W] normals.
  static NormalEstimator FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime = {});
  // "auto": DefaultModelDir()/normal_estimator.pt — InputError naming that file and its exporter when absent
  // (there is no classical fallback); a path: that file.
  static NormalEstimator Resolve(const std::string& choice, const RuntimeOptions& runtime = {});

  NormalEstimator(NormalEstimator&&) noexcept;
  NormalEstimator& operator=(NormalEstimator&&) noexcept;
  ~NormalEstimator();

  int multiple() const { return multiple_; }
  std::string Describe() const;

  // `image`: sRGB-encoded 0..1, 3 channels (RGBA: alpha ignored). Result: same size, 3 channels, unit normals in
  // the OpenCV camera frame; (0, 0, 0) where the model gave a zero or non-finite vector.
  ImageF Estimate(const ImageF& image) const;

 private:
  explicit NormalEstimator(std::unique_ptr<Model> model, int multiple);
  std::unique_ptr<Model> model_;
  int multiple_ = 1;
};

}  // namespace sd::models
