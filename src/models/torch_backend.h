#pragma once
// The seam between the model runtime (runtime.cpp) and LibTorch (runtime_torch.cpp), so that LibTorch is loaded
// only when a model is. LibTorch brings some 270 shared libraries whose loading and static initialisation took
// 0.6 s of every synthdrive process, also of the commands that never run a model; runtime_torch.cpp is therefore
// built as a plugin (libsynthdrive_torch.so) that runtime.cpp opens with dlopen at the first model load (the GPU
// build, tools/gpu/CMakeLists.txt, builds the same plugin against a CUDA LibTorch).
//
// Both sides are built from this source tree with one compiler and one C++ library, so C++ types cross the seam;
// exceptions do not: every call reports failure through `error`, and runtime.cpp turns it into an InputError
// naming the model file. Internal to src/models.
#include <string>
#include <vector>

#include "models/runtime.h"

namespace sd::models::torch_backend {

constexpr int kAbiVersion = 1;

struct Module;  // a loaded TorchScript module on its device (opaque)

struct Api {
  int abi_version = kAbiVersion;
  // "LibTorch 1.13.0, CPU, 2 threads"; `threads` > 0 first sets LibTorch's intra-op threads.
  std::string (*describe)(int threads);
  // Loads `file` onto `device` ("cpu", "cuda", "cuda:N"); float16 weights when `half`. On success fills the
  // contract's JSON text (empty when the archive has none) and the device's name; on failure returns null and
  // fills `error` with one line.
  Module* (*load)(const std::string& file, const std::string& device, bool half, int threads, const std::string& contract_file,
                  std::string* contract_json, std::string* device_name, std::string* error);
  void (*destroy)(Module* module);
  // One forward pass without gradients; `to_half[i]` converts input i to float16 (half modules), the rest stay
  // float32. Outputs in float32 on the host. False with `error` filled on failure.
  // Tensor crosses as a plain struct (shape, values): its constructors live in runtime.cpp, outside the plugin.
  bool (*run)(const Module* module, const std::vector<Tensor>& inputs, const std::vector<bool>& to_half, int threads,
              std::vector<Tensor>* outputs, std::string* error);
};

}  // namespace sd::models::torch_backend

// Defined by runtime_torch.cpp: the plugin's one exported symbol.
extern "C" const sd::models::torch_backend::Api* SynthdriveTorchBackend();
