// The LibTorch backend of the model runtime (models/torch_backend.h): a plugin, libsynthdrive_torch.so, that
// runtime.cpp opens at the first model load. The only translation unit that includes LibTorch headers: they cost
// ~15 s of compile time each, and the rest of the code base should not care which framework runs the models.
// Nothing here throws across the seam, and nothing here uses the program's global state (thread limit, device):
// the caller passes what it needs.
#include <ATen/Context.h>
#include <ATen/Parallel.h>
#include <torch/cuda.h>
#include <torch/script.h>
#include <torch/version.h>

#include <sstream>

#include "models/torch_backend.h"

namespace sd::models::torch_backend {

struct Module {
  torch::jit::Module module;
  torch::Device device{torch::kCPU};
  bool half = false;
};

namespace {

// LibTorch keeps its own thread pool; follow the process-wide limit (--threads) rather than its default,
// which on some machines is a single thread.
void ApplyThreads(int threads) {
  if (threads > 0 && at::get_num_threads() != threads) at::set_num_threads(threads);
}

std::string FirstLine(const c10::Error& e) {
  const std::string what = e.what_without_backtrace();
  return what.substr(0, what.find('\n'));
}

std::string Describe(int threads) {
  ApplyThreads(threads);
  std::ostringstream m;
  m << "LibTorch " << TORCH_VERSION << ", " << (torch::cuda::is_available() ? "CUDA available" : "CPU") << ", "
    << at::get_num_threads() << " threads";
  return m.str();
}

Module* Load(const std::string& file, const std::string& device_name, bool half, int threads,
             const std::string& contract_file, std::string* contract_json, std::string* device_out, std::string* error) {
  auto m = std::make_unique<Module>();
  try {
    m->device = torch::Device(device_name);
  } catch (const c10::Error&) {
    *error = "unknown device '" + device_name + "' (use cpu, cuda or cuda:N)";
    return nullptr;
  }
  if (m->device.is_cuda() && !torch::cuda::is_available()) {
    *error = "device '" + device_name + "' asked for, but this LibTorch build sees no CUDA device";
    return nullptr;
  }
  if (m->device.is_cuda()) {
    // float32 means float32: LibTorch would otherwise run convolutions in TF32 on recent GPUs (10 mantissa
    // bits), several hundred times the CPU's error, and the contracts' verification figures would not hold.
    // `half` is the opt-in for speed. Deterministic cuDNN algorithms: the same input gives the same output run
    // after run, as on the CPU (a dataset made twice must not differ).
    at::globalContext().setAllowTF32CuDNN(false);
    at::globalContext().setAllowTF32CuBLAS(false);
    at::globalContext().setDeterministicCuDNN(true);
    at::globalContext().setBenchmarkCuDNN(false);
  }
  m->half = half;
  torch::jit::ExtraFilesMap extra{{contract_file, ""}};
  try {
    m->module = torch::jit::load(file, m->device, extra);
  } catch (const c10::Error& e) {
    *error = "not a readable TorchScript archive (" + FirstLine(e) + ")";
    return nullptr;
  }
  *contract_json = extra[contract_file];
  *device_out = m->device.str();
  m->module.eval();
  if (m->half) m->module.to(torch::kHalf);
  ApplyThreads(threads);
  return m.release();
}

void Destroy(Module* m) { delete m; }

bool Run(const Module* m, const std::vector<Tensor>& inputs, const std::vector<bool>& to_half, int threads,
         std::vector<Tensor>* outputs, std::string* error) {
  ApplyThreads(threads);
  try {
    c10::InferenceMode inference;
    std::vector<torch::jit::IValue> args;
    for (size_t i = 0; i < inputs.size(); ++i) {
      const Tensor& t = inputs[i];
      // from_blob does not copy; .to() below makes the copy the module may keep, so `inputs` stay the caller's.
      torch::Tensor x = torch::from_blob(const_cast<float*>(t.values.data()), t.shape, torch::kFloat32);
      if (m->device.is_cuda()) {
        // Pageable memory reaches the GPU through the driver's small bounce buffers; a pinned copy (PyTorch caches
        // the pinned blocks) goes at the bus's speed.
        torch::Tensor pinned = torch::empty(t.shape, torch::TensorOptions().dtype(torch::kFloat32).pinned_memory(true));
        pinned.copy_(x);
        x = pinned;
      }
      x = x.to(m->device, to_half[i] ? torch::kHalf : torch::kFloat32, /*non_blocking=*/false, /*copy=*/true);
      args.emplace_back(std::move(x));
    }
    // forward() is not const; the module is not changed by a pass in inference mode.
    torch::jit::IValue result = const_cast<torch::jit::Module&>(m->module).forward(args);
    std::vector<torch::Tensor> outs;
    if (result.isTensor()) {
      outs.push_back(result.toTensor());
    } else if (result.isTuple()) {
      for (const auto& v : result.toTupleRef().elements()) outs.push_back(v.toTensor());
    } else if (result.isTensorList()) {
      for (const auto& v : result.toTensorVector()) outs.push_back(v);
    } else {
      *error = std::string("returned ") + result.tagKind() + ", expected tensors";
      return false;
    }
    outputs->assign(outs.size(), Tensor{});
    for (size_t i = 0; i < outs.size(); ++i) {
      torch::Tensor y = outs[i].to(torch::kCPU, torch::kFloat32).contiguous();
      (*outputs)[i].shape.assign(y.sizes().begin(), y.sizes().end());
      (*outputs)[i].values.assign(y.data_ptr<float>(), y.data_ptr<float>() + y.numel());
    }
    return true;
  } catch (const c10::Error& e) {
    *error = FirstLine(e);
    return false;
  }
}

}  // namespace
}  // namespace sd::models::torch_backend

extern "C" __attribute__((visibility("default"))) const sd::models::torch_backend::Api* SynthdriveTorchBackend() {
  using namespace sd::models::torch_backend;
  static const Api api{kAbiVersion, &Describe, &Load, &Destroy, &Run};
  return &api;
}
