#pragma once
// The one model runtime (DESIGN.md): TorchScript modules on LibTorch, each file carrying its SynthDrive contract.
//
// A model file is a TorchScript archive (torch.jit.save) with one extra file, "synthdrive_contract.json":
//   { "format": "synthdrive-model/1", "stage": "super_resolution", "name": "esrgan-slim-x2",
//     "source": "...", "license": "MIT",
//     "inputs":  [ { "name": "image", "shape": [-1, 3, -1, -1], "dtype": "float32", "layout": "NCHW",
//                    "range": [0, 255], "encoding": "srgb" } ],
//     "outputs": [ ... same fields ... ],
//     "params": { "scale": 2, ... numbers the stage needs ... },
//     "verification": { "psnr_db": 44.1, ... how the exporter checked it ... } }
// -1 in a shape is "any size". The exporters under tools/ write it; docs/models.md has one contract per stage.
// Loading checks the contract is for the stage the caller asked for, so a CLIP file handed to the upscaler
// fails with a message naming the file, the expected stage and what was found — never a shape error deep
// inside LibTorch. Every Run checks its inputs and outputs against the contract's shapes.
//
// Without LibTorch (configured with -DSYNTHDRIVE_WITH_TORCH=OFF) the module still builds: RuntimeAvailable()
// is false and Load throws InputError saying so; every stage then takes its classical path.
#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/device.h"

namespace sd::models {

// A dense float32 tensor, row-major, in the layout its contract names (images: NCHW).
struct Tensor {
  std::vector<int64_t> shape;
  std::vector<float> values;

  Tensor() = default;
  Tensor(std::vector<int64_t> tensor_shape, float fill = 0.0f);
  int64_t numel() const;
};

struct TensorSpec {
  std::string name;
  std::vector<int64_t> shape;  // -1 = any size
  std::string dtype = "float32";
  std::string layout;    // "NCHW", "NC", ...
  std::string encoding;  // "srgb", "linear", "" ...
  std::array<double, 2> range{0, 1};
};

struct ModelContract {
  std::string stage, name, source, license;
  std::vector<TensorSpec> inputs, outputs;
  std::map<std::string, double> params;  // stage-specific numbers (scale, receptive radius, ...)
  std::map<std::string, double> verification;  // numeric figures the exporter measured (psnr_db, ...)
  std::string json;  // the contract as stored, for asset provenance

  // Parses the JSON text of a contract; InputError naming `file` for malformed JSON, a wrong "format",
  // or missing fields.
  static ModelContract Parse(const std::string& text, const std::filesystem::path& file);
  // Where a stage needs a parameter: InputError naming `file` when the contract lacks it.
  double Param(const std::string& key, const std::filesystem::path& file) const;
  // "[-1, 3, -1, -1]" etc., for messages.
  static std::string ShapeString(const std::vector<int64_t>& shape);
};

struct RuntimeOptions {
  // "cpu", "cuda" or "cuda:N" (needs a CUDA build of LibTorch); by default the process's device
  // (core/device.h: --device, $SYNTHDRIVE_DEVICE).
  std::string device = ToString(CurrentDevice());
  bool half = false;           // float16 weights and activations (CUDA only; inputs and outputs stay float32)
};

bool RuntimeAvailable();
std::string RuntimeDescription();  // "LibTorch 1.13.0, CPU, 2 threads" or why there is none

// Where installed model files live: $SYNTHDRIVE_MODELS, else $XDG_CACHE_HOME/synthdrive/models, else
// ~/.cache/synthdrive/models (scripts/fetch_models.sh fills it; outside the source tree).
std::filesystem::path DefaultModelDir();

class Model {
 public:
  // Loads `file` for `stage` on the options' device. InputError naming the file when it is missing, is not a
  // TorchScript archive, has no SynthDrive contract, or its contract is for another stage; or when the device
  // cannot be used.
  static Model Load(const std::filesystem::path& file, std::string_view stage, const RuntimeOptions& options = {});

  Model(Model&&) noexcept;
  Model& operator=(Model&&) noexcept;
  ~Model();

  const ModelContract& contract() const;
  const std::filesystem::path& file() const;
  std::string device() const;

  // One forward pass, no gradients. Inputs must match the contract (count, rank, fixed sizes); the outputs are
  // checked the same way, so a file whose module disagrees with its own contract is reported, naming the file.
  std::vector<Tensor> Run(const std::vector<Tensor>& inputs) const;

 private:
  struct Impl;
  explicit Model(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sd::models
