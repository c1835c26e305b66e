// The LibTorch half of the runtime. The only translation unit that includes LibTorch headers: they cost ~15 s
// of compile time each, and the rest of the code base should not care which framework runs the models.
#include <ATen/Context.h>
#include <ATen/Parallel.h>
#include <torch/cuda.h>
#include <torch/script.h>
#include <torch/version.h>

#include "core/error.h"
#include "core/parallel.h"
#include "models/runtime.h"

namespace sd::models {

namespace {

constexpr const char* kContractFile = "synthdrive_contract.json";

// Whether `shape` fits `spec` (-1 = any size).
bool Matches(const std::vector<int64_t>& shape, const std::vector<int64_t>& spec) {
  if (shape.size() != spec.size()) return false;
  for (size_t i = 0; i < shape.size(); ++i)
    if (spec[i] != -1 && spec[i] != shape[i]) return false;
  return true;
}

torch::Device ParseDevice(const std::string& name, const std::filesystem::path& file) {
  try {
    torch::Device device(name);
    if (device.is_cuda() && !torch::cuda::is_available())
      throw InputError(file, Msg() << "device '" << name << "' asked for, but this LibTorch build sees no CUDA device");
    return device;
  } catch (const c10::Error&) {
    throw InputError(file, Msg() << "unknown device '" << name << "' (use cpu, cuda or cuda:N)");
  }
}

// LibTorch keeps its own thread pool; follow the process-wide limit (--threads) rather than its default,
// which on some machines is a single thread.
void ApplyThreadLimit() {
  const int threads = MaxThreads();
  if (threads > 0 && at::get_num_threads() != threads) at::set_num_threads(threads);
}

}  // namespace

bool RuntimeAvailable() { return true; }

std::string RuntimeDescription() {
  ApplyThreadLimit();
  return Msg() << "LibTorch " << TORCH_VERSION << ", " << (torch::cuda::is_available() ? "CUDA available" : "CPU")
               << ", " << at::get_num_threads() << " threads";
}

struct Model::Impl {
  std::filesystem::path file;
  ModelContract contract;
  torch::jit::Module module;
  torch::Device device{torch::kCPU};
  bool half = false;
};

Model::Model(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Model::Model(Model&&) noexcept = default;
Model& Model::operator=(Model&&) noexcept = default;
Model::~Model() = default;

Model Model::Load(const std::filesystem::path& file, std::string_view stage, const RuntimeOptions& options) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec))
    throw InputError(file, Msg() << "no such model file (the " << stage << " stage needs a TorchScript file; "
                                 << "see docs/models.md)");
  auto impl = std::make_unique<Impl>();
  impl->file = file;
  impl->device = ParseDevice(options.device, file);
  if (impl->device.is_cuda()) {
    // float32 means float32: LibTorch would otherwise run convolutions in TF32 on recent GPUs (10 mantissa
    // bits), several hundred times the CPU's error, and the contracts' verification figures would not hold.
    // `half` is the opt-in for speed. Deterministic cuDNN algorithms: the same input gives the same output run
    // after run, as on the CPU (a dataset made twice must not differ).
    at::globalContext().setAllowTF32CuDNN(false);
    at::globalContext().setAllowTF32CuBLAS(false);
    at::globalContext().setDeterministicCuDNN(true);
    at::globalContext().setBenchmarkCuDNN(false);
  }
  impl->half = options.half;
  if (impl->half && !impl->device.is_cuda())
    throw InputError(file, "half precision is for CUDA devices only");

  torch::jit::ExtraFilesMap extra{{kContractFile, ""}};
  try {
    impl->module = torch::jit::load(file.string(), impl->device, extra);
  } catch (const c10::Error& e) {
    const std::string what = e.what_without_backtrace();
    throw InputError(file, Msg() << "not a readable TorchScript archive (" << what.substr(0, what.find('\n')) << ")");
  }
  if (extra[kContractFile].empty())
    throw InputError(file, Msg() << "TorchScript archive without a SynthDrive contract (" << kContractFile
                                 << "); export it with the tools/ exporter for the " << stage << " stage");
  impl->contract = ModelContract::Parse(extra[kContractFile], file);
  if (impl->contract.stage != stage)
    throw InputError(file, Msg() << "is a '" << impl->contract.stage << "' model ('" << impl->contract.name
                                 << "'), expected a '" << stage << "' model");
  impl->module.eval();
  if (impl->half) impl->module.to(torch::kHalf);
  ApplyThreadLimit();
  return Model(std::move(impl));
}

const ModelContract& Model::contract() const { return impl_->contract; }
const std::filesystem::path& Model::file() const { return impl_->file; }
std::string Model::device() const { return impl_->device.str(); }

std::vector<Tensor> Model::Run(const std::vector<Tensor>& inputs) const {
  const ModelContract& c = impl_->contract;
  if (inputs.size() != c.inputs.size())
    throw InputError(impl_->file, Msg() << "'" << c.name << "' takes " << c.inputs.size() << " inputs, given "
                                        << inputs.size());
  ApplyThreadLimit();
  c10::InferenceMode inference;
  std::vector<torch::jit::IValue> args;
  for (size_t i = 0; i < inputs.size(); ++i) {
    const Tensor& t = inputs[i];
    if (!Matches(t.shape, c.inputs[i].shape))
      throw InputError(impl_->file, Msg() << "input '" << c.inputs[i].name << "' of '" << c.name << "' must be "
                                          << ModelContract::ShapeString(c.inputs[i].shape) << ", given "
                                          << ModelContract::ShapeString(t.shape));
    SD_CHECK(static_cast<int64_t>(t.values.size()) == t.numel(), << t.values.size() << " vs " << t.numel());
    // from_blob does not copy; .to() below makes the copy the module may keep, so `inputs` stay the caller's.
    torch::Tensor x = torch::from_blob(const_cast<float*>(t.values.data()), t.shape, torch::kFloat32);
    // Token ids stay float32 in half mode: float16 holds integers exactly only up to 2048, and a CLIP id
    // (up to 49407) would reach the embedding lookup rounded to another token.
    const bool to_half = impl_->half && c.inputs[i].encoding != "token_ids";
    x = x.to(impl_->device, to_half ? torch::kHalf : torch::kFloat32, /*non_blocking=*/false, /*copy=*/true);
    args.emplace_back(std::move(x));
  }

  torch::jit::IValue result;
  try {
    result = impl_->module.forward(args);
  } catch (const c10::Error& e) {
    const std::string what = e.what_without_backtrace();
    throw InputError(impl_->file, Msg() << "forward pass of '" << c.name << "' failed: "
                                        << what.substr(0, what.find('\n')));
  }

  std::vector<torch::Tensor> outs;
  if (result.isTensor()) {
    outs.push_back(result.toTensor());
  } else if (result.isTuple()) {
    for (const auto& v : result.toTupleRef().elements()) outs.push_back(v.toTensor());
  } else if (result.isTensorList()) {
    for (const auto& v : result.toTensorVector()) outs.push_back(v);
  } else {
    throw InputError(impl_->file, Msg() << "'" << c.name << "' returned " << result.tagKind()
                                        << ", expected tensors");
  }
  if (outs.size() != c.outputs.size())
    throw InputError(impl_->file, Msg() << "'" << c.name << "' returned " << outs.size() << " outputs, its contract "
                                        << "names " << c.outputs.size());
  std::vector<Tensor> out(outs.size());
  for (size_t i = 0; i < outs.size(); ++i) {
    torch::Tensor y = outs[i].to(torch::kCPU, torch::kFloat32).contiguous();
    out[i].shape.assign(y.sizes().begin(), y.sizes().end());
    if (!Matches(out[i].shape, c.outputs[i].shape))
      throw InputError(impl_->file, Msg() << "output '" << c.outputs[i].name << "' of '" << c.name << "' is "
                                          << ModelContract::ShapeString(out[i].shape) << ", its contract says "
                                          << ModelContract::ShapeString(c.outputs[i].shape));
    out[i].values.assign(y.data_ptr<float>(), y.data_ptr<float>() + y.numel());
  }
  return out;
}

}  // namespace sd::models
