#include "models/lrm.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "models/resample.h"

namespace sd::models {

LrmReconstructor::LrmReconstructor(LrmReconstructor&&) noexcept = default;
LrmReconstructor& LrmReconstructor::operator=(LrmReconstructor&&) noexcept = default;
LrmReconstructor::~LrmReconstructor() = default;

LrmReconstructor LrmReconstructor::Load(const std::filesystem::path& dir, const RuntimeOptions& runtime,
                                        const LrmOptions& options) {
  if (options.grid < 3 || options.grid > 1024)
    throw InputError({}, Msg() << "LRM grid must be 3..1024 nodes per axis, got " << options.grid);
  if (options.chunk < 1) throw InputError({}, Msg() << "LRM chunk must be >= 1 point, got " << options.chunk);
  std::string missing;
  std::error_code ec;
  for (const char* name : {kLrmEncoderFile, kLrmDecoderFile})
    if (!std::filesystem::is_regular_file(dir / name, ec)) missing += std::string(missing.empty() ? "" : ", ") + name;
  if (!missing.empty())
    throw InputError(dir, Msg() << "LRM model folder lacks " << missing
                                << " (tools/export/export_lrm.py writes lrm_encoder.pt and lrm_decoder.pt)");
  LrmReconstructor r;
  r.options_ = options;
  const std::filesystem::path enc_file = dir / kLrmEncoderFile, dec_file = dir / kLrmDecoderFile;
  r.encoder_ = std::make_unique<Model>(Model::Load(enc_file, kLrmEncoderStage, runtime));
  r.decoder_ = std::make_unique<Model>(Model::Load(dec_file, kLrmDecoderStage, runtime));
  const ModelContract& ec_ = r.encoder_->contract();
  const ModelContract& dc = r.decoder_->contract();
  r.image_size_ = static_cast<int>(ec_.Param("image_size", enc_file));
  // A decoder traced at a fixed point count declares it; every call then sends exactly that many points.
  if (dc.inputs.size() == 2 && dc.inputs[1].shape.size() == 3 && dc.inputs[1].shape[1] > 0)
    r.fixed_points_ = static_cast<int>(dc.inputs[1].shape[1]);
  if (const auto it = ec_.params.find("background"); it != ec_.params.end())
    r.background_ = static_cast<float>(std::clamp(it->second, 0.0, 1.0));
  const auto shaped = [](const std::vector<TensorSpec>& specs, size_t i, std::vector<int64_t> expected) {
    if (i >= specs.size() || specs[i].shape.size() != expected.size()) return false;
    for (size_t k = 0; k < expected.size(); ++k)
      if (expected[k] != -1 && specs[i].shape[k] != -1 && specs[i].shape[k] != expected[k]) return false;
    return true;
  };
  const int s = r.image_size_;
  if (ec_.inputs.size() != 1 || ec_.outputs.size() != 1 || !shaped(ec_.inputs, 0, {1, 3, s, s}) ||
      !shaped(ec_.outputs, 0, {1, 3, -1, -1, -1}))
    throw InputError(enc_file, Msg() << "an lrm_encoder maps one image [1, 3, " << s << ", " << s
                                     << "] to one triplane [1, 3, C, R, R]; its contract says otherwise");
  if (dc.inputs.size() != 2 || dc.outputs.size() != 2 || !shaped(dc.inputs, 0, {1, 3, -1, -1, -1}) ||
      !shaped(dc.inputs, 1, {1, -1, 3}) || !shaped(dc.outputs, 0, {1, -1, 1}) || !shaped(dc.outputs, 1, {1, -1, 3}))
    throw InputError(dec_file, "an lrm_decoder maps (triplane [1, 3, C, R, R], points [1, P, 3]) to (sdf [1, P, 1], "
                               "colour [1, P, 3]); its contract says otherwise");
  return r;
}

std::string LrmReconstructor::Describe() const {
  const ModelContract& c = encoder_->contract();
  Msg m;
  m << "LRM " << c.name << " / " << decoder_->contract().name << " ("
    << (c.source.empty() ? encoder_->file().string() : c.source);
  if (!c.license.empty()) m << ", " << c.license;
  m << "; grid " << options_.grid << "^3; TorchScript on " << RuntimeDescription() << ", device " << encoder_->device()
    << ")";
  return m;
}

ImageF LrmReconstructor::PrepareImage(const ImageF& image) const {
  if (image.empty()) throw InputError({}, "LRM: empty image");
  const int ch = image.channels();
  if (ch != 3 && ch != 4) throw InputError({}, Msg() << "LRM: " << ch << "-channel image (RGB or RGBA)");
  const int w = image.width(), h = image.height(), side = std::max(w, h);
  const int x0 = (side - w) / 2, y0 = (side - h) / 2;
  ImageF square(side, side, 3, background_);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = ch == 4 ? image.at(x, y, 3) : 1.0f;
      for (int c = 0; c < 3; ++c) square.at(x0 + x, y0 + y, c) = a * image.at(x, y, c) + (1 - a) * background_;
    }
  ImageF out = side == image_size_ ? square : ResizeBicubic(square, image_size_, image_size_);
  for (float& v : out.vector()) v = std::clamp(v, 0.0f, 1.0f);
  return out;
}

Tensor LrmReconstructor::EncodeTriplane(const ImageF& image) const {
  const ImageF img = PrepareImage(image);
  const int s = image_size_;
  Tensor input({1, 3, s, s});
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < s; ++y)
      for (int x = 0; x < s; ++x) input.values[(static_cast<size_t>(c) * s + y) * s + x] = img.at(x, y, c);
  return encoder_->Run({input})[0];
}

void LrmReconstructor::Decode(const Tensor& triplane, const std::vector<float>& points, std::vector<float>* sdf,
                              std::vector<float>* colour) const {
  const size_t n = points.size() / 3;
  if (sdf) sdf->assign(n, 0.0f);
  if (colour) colour->assign(3 * n, 0.0f);
  const size_t chunk = static_cast<size_t>(fixed_points_ > 0 ? fixed_points_ : options_.chunk);
  for (size_t first = 0; first < n; first += chunk) {
    const size_t count = std::min(n - first, chunk);
    const size_t sent = fixed_points_ > 0 ? chunk : count;  // a fixed-size decoder gets the last point repeated
    Tensor p({1, static_cast<int64_t>(sent), 3});
    std::copy(points.begin() + static_cast<std::ptrdiff_t>(3 * first),
              points.begin() + static_cast<std::ptrdiff_t>(3 * (first + count)), p.values.begin());
    for (size_t i = count; i < sent; ++i)
      std::copy_n(points.begin() + static_cast<std::ptrdiff_t>(3 * (first + count - 1)), 3, p.values.begin() + 3 * i);
    const std::vector<Tensor> out = decoder_->Run({triplane, p});
    if (out[0].numel() != static_cast<int64_t>(sent) || out[1].numel() != static_cast<int64_t>(3 * sent))
      throw InputError(decoder_->file(), Msg() << "returned " << ModelContract::ShapeString(out[0].shape) << " and "
                                               << ModelContract::ShapeString(out[1].shape) << " for " << sent
                                               << " points");
    if (sdf)
      std::copy_n(out[0].values.begin(), count, sdf->begin() + static_cast<std::ptrdiff_t>(first));
    if (colour)
      std::copy_n(out[1].values.begin(), 3 * count, colour->begin() + static_cast<std::ptrdiff_t>(3 * first));
  }
}

geometry::ScalarGrid LrmReconstructor::SampleField(const Tensor& triplane) const {
  const int g = options_.grid;
  geometry::ScalarGrid grid;
  grid.dims = Eigen::Vector3i(g, g, g);
  grid.origin = Eigen::Vector3f::Constant(-0.5f);
  grid.voxel_size = 1.0f / static_cast<float>(g - 1);
  std::vector<float> points;
  points.reserve(static_cast<size_t>(g) * g * g * 3);
  for (int k = 0; k < g; ++k)
    for (int j = 0; j < g; ++j)
      for (int i = 0; i < g; ++i) {
        const Eigen::Vector3f p = grid.NodePosition(i, j, k);
        points.insert(points.end(), {p.x(), p.y(), p.z()});
      }
  std::vector<float> sdf;
  Decode(triplane, points, &sdf, nullptr);
  grid.values.resize(sdf.size());
  for (int k = 0; k < g; ++k)
    for (int j = 0; j < g; ++j)
      for (int i = 0; i < g; ++i) {
        const size_t idx = grid.Index(i, j, k);
        float v = std::isfinite(sdf[idx]) ? -sdf[idx] : -1.0f;  // NaN counts as outside
        const bool border = i == 0 || j == 0 || k == 0 || i == g - 1 || j == g - 1 || k == g - 1;
        if (border) v = std::min(v, -1e-6f);  // closes surfaces that reach the cube's faces
        grid.values[idx] = v;
      }
  return grid;
}

TriangleMesh LrmReconstructor::Reconstruct(const ImageF& image) const {
  const Tensor triplane = EncodeTriplane(image);
  TriangleMesh mesh = geometry::MarchingCubes(SampleField(triplane), 0.0f);
  if (mesh.faces.empty())
    throw InputError(encoder_->file(), "the LRM found no surface inside the unit cube for this image");
  std::vector<float> points;
  points.reserve(mesh.positions.size() * 3);
  for (const Eigen::Vector3f& p : mesh.positions) points.insert(points.end(), {p.x(), p.y(), p.z()});
  std::vector<float> colour;
  Decode(triplane, points, nullptr, &colour);
  mesh.colors.resize(mesh.positions.size());
  for (size_t v = 0; v < mesh.positions.size(); ++v)
    mesh.colors[v] = Eigen::Vector4f(SrgbToLinear(std::clamp(colour[3 * v], 0.0f, 1.0f)),
                                     SrgbToLinear(std::clamp(colour[3 * v + 1], 0.0f, 1.0f)),
                                     SrgbToLinear(std::clamp(colour[3 * v + 2], 0.0f, 1.0f)), 1.0f);
  mesh.ComputeVertexNormals();
  return mesh;
}

}  // namespace sd::models
