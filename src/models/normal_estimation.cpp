#include "models/normal_estimation.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace sd::models {

NormalEstimator::NormalEstimator(std::unique_ptr<Model> model, int multiple)
    : model_(std::move(model)), multiple_(multiple) {}
NormalEstimator::NormalEstimator(NormalEstimator&&) noexcept = default;
NormalEstimator& NormalEstimator::operator=(NormalEstimator&&) noexcept = default;
NormalEstimator::~NormalEstimator() = default;

NormalEstimator NormalEstimator::FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime) {
  auto model = std::make_unique<Model>(Model::Load(file, kNormalEstimationStage, runtime));
  const ModelContract& c = model->contract();
  const double multiple = c.Param("multiple", file);
  if (multiple < 1 || multiple != std::floor(multiple) || multiple > 1024)
    throw InputError(file, Msg() << "normal_estimation multiple must be an integer 1..1024, the contract says " << multiple);
  for (const auto* specs : {&c.inputs, &c.outputs})
    if (specs->size() != 1 || specs->front().shape.size() != 4 || specs->front().shape[1] != 3)
      throw InputError(file, "a normal_estimation model maps one image [N, 3, H, W] to normals [N, 3, H, W]; "
                             "its contract says otherwise");
  return NormalEstimator(std::move(model), static_cast<int>(multiple));
}

NormalEstimator NormalEstimator::Resolve(const std::string& choice, const RuntimeOptions& runtime) {
  if (choice != "auto") return FromModel(choice, runtime);
  const std::filesystem::path file = DefaultModelDir() / kNormalEstimatorFile;
  std::error_code ec;
  if (std::filesystem::is_regular_file(file, ec) && !RuntimeAvailable())
    throw InputError(file, Msg() << "normal estimation needs a learned model and " << RuntimeDescription()
                                 << " (there is no classical single-image method)");
  if (!std::filesystem::is_regular_file(file, ec))
    throw InputError(file, "no normal estimation model installed; there is no classical single-image method. "
                           "Export one with tools/export/export_normal_estimator.py");
  return FromModel(file, runtime);
}

std::string NormalEstimator::Describe() const {
  const ModelContract& c = model_->contract();
  Msg m;
  m << c.name << " (" << (c.source.empty() ? model_->file().string() : c.source);
  if (!c.license.empty()) m << ", " << c.license;
  m << "; multiple " << multiple_ << "; TorchScript on " << RuntimeDescription() << ", device " << model_->device()
    << ")";
  return m;
}

ImageF NormalEstimator::Estimate(const ImageF& image) const {
  if (image.empty()) throw InputError({}, "normal estimation: empty image");
  if (image.channels() != 3 && image.channels() != 4)
    throw InputError({}, Msg() << "normal estimation: " << image.channels() << "-channel image (RGB or RGBA)");
  const int w = image.width(), h = image.height(), m = multiple_;
  const int pw = (w + m - 1) / m * m, ph = (h + m - 1) / m * m;
  // Border replication into the padding; the image sits at the top-left so cropping back is an offset of 0.
  Tensor input({1, 3, ph, pw});
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < ph; ++y)
      for (int x = 0; x < pw; ++x)
        input.values[(static_cast<size_t>(c) * ph + y) * pw + x] =
            std::clamp(image.at(std::min(x, w - 1), std::min(y, h - 1), c), 0.0f, 1.0f);
  const Tensor out = model_->Run({input})[0];
  if (out.shape[2] != ph || out.shape[3] != pw)
    throw InputError(model_->file(), Msg() << "'" << model_->contract().name << "' turned a " << pw << "x" << ph
                                           << " image into " << out.shape[3] << "x" << out.shape[2] << " normals");
  ImageF normals(w, h, 3, 0.0f);
  const size_t plane = static_cast<size_t>(ph) * pw;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * pw + x;
      const float nx = out.values[i], ny = out.values[plane + i], nz = out.values[2 * plane + i];
      const float len = std::sqrt(nx * nx + ny * ny + nz * nz);
      if (!(len > 1e-12f) || !std::isfinite(len)) continue;
      normals.at(x, y, 0) = nx / len;
      normals.at(x, y, 1) = ny / len;
      normals.at(x, y, 2) = nz / len;
    }
  return normals;
}

}  // namespace sd::models
