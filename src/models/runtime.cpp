// The parts of the runtime that do not need LibTorch: tensors, contracts, where models live.
#include "models/runtime.h"

#include <dlfcn.h>
#include <unistd.h>

#include <array>
#include <cstdlib>
#include <mutex>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/parallel.h"
#include "io/json.h"
#include "models/torch_backend.h"

namespace sd::models {

Tensor::Tensor(std::vector<int64_t> tensor_shape, float fill) : shape(std::move(tensor_shape)) {
  values.assign(static_cast<size_t>(numel()), fill);
}

int64_t Tensor::numel() const {
  int64_t n = 1;
  for (int64_t d : shape) n *= d;
  return shape.empty() ? 0 : n;
}

namespace {

TensorSpec ParseSpec(const JsonReader& j) {
  TensorSpec spec;
  spec.name = j["name"].String();
  const JsonReader shape = j["shape"];
  for (size_t i = 0; i < shape.Size(); ++i) {
    const int64_t d = shape[i].Integer();
    if (d == 0 || d < -1) shape[i].Fail("a dimension is a positive size or -1 (any)");
    spec.shape.push_back(d);
  }
  spec.dtype = j.StringOr("dtype", "float32");
  if (spec.dtype != "float32") j["dtype"].Fail("only float32 tensors cross the runtime boundary, found " + spec.dtype);
  spec.layout = j.StringOr("layout", "");
  spec.encoding = j.StringOr("encoding", "");
  if (j.Has("range")) {
    const JsonReader range = j["range"];
    if (range.Size() != 2) range.Fail("expected [low, high]");
    spec.range = {range[0].Number(), range[1].Number()};
    if (!(spec.range[0] < spec.range[1])) range.Fail("low must be below high");
  }
  return spec;
}

std::vector<TensorSpec> ParseSpecs(const JsonReader& list) {
  std::vector<TensorSpec> specs;
  for (size_t i = 0; i < list.Size(); ++i) specs.push_back(ParseSpec(list[i]));
  if (specs.empty()) list.Fail("names no tensors");
  return specs;
}

std::map<std::string, double> NumericMembers(const nlohmann::json& object) {
  std::map<std::string, double> out;
  if (!object.is_object()) return out;
  for (const auto& [key, value] : object.items())
    if (value.is_number()) out[key] = value.get<double>();
  return out;
}

}  // namespace

ModelContract ModelContract::Parse(const std::string& text, const std::filesystem::path& file) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    throw InputError(file, Msg() << "SynthDrive contract is not valid JSON (" << e.what() << ")");
  }
  const JsonReader root(j, file, "synthdrive_contract.json");
  const std::string format = root["format"].String();
  if (format != "synthdrive-model/1")
    root["format"].Fail("unknown contract format '" + format + "' (this build reads synthdrive-model/1)");
  ModelContract c;
  c.stage = root["stage"].String();
  c.name = root["name"].String();
  c.source = root.StringOr("source", "");
  c.license = root.StringOr("license", "");
  c.inputs = ParseSpecs(root["inputs"]);
  c.outputs = ParseSpecs(root["outputs"]);
  if (j.contains("params")) c.params = NumericMembers(j["params"]);
  if (j.contains("verification")) c.verification = NumericMembers(j["verification"]);
  c.json = text;
  return c;
}

double ModelContract::Param(const std::string& key, const std::filesystem::path& file) const {
  const auto it = params.find(key);
  if (it == params.end())
    throw InputError(file, Msg() << "the " << stage << " contract of '" << name << "' has no params." << key);
  return it->second;
}

std::string ModelContract::ShapeString(const std::vector<int64_t>& shape) {
  std::string s = "[";
  for (size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
  return s + "]";
}

std::filesystem::path DefaultModelDir() {
  if (const char* dir = std::getenv("SYNTHDRIVE_MODELS"); dir && *dir) return dir;
  if (const char* cache = std::getenv("XDG_CACHE_HOME"); cache && *cache)
    return std::filesystem::path(cache) / "synthdrive" / "models";
  if (const char* home = std::getenv("HOME"); home && *home)
    return std::filesystem::path(home) / ".cache" / "synthdrive" / "models";
  return std::filesystem::path(".synthdrive-models");
}

// ---- The runtime: LibTorch through its plugin (torch_backend.h) ----

namespace {

constexpr const char* kContractFile = "synthdrive_contract.json";
constexpr const char* kPluginName = "libsynthdrive_torch.so";

// Whether `shape` fits `spec` (-1 = any size).
bool Matches(const std::vector<int64_t>& shape, const std::vector<int64_t>& spec) {
  if (shape.size() != spec.size()) return false;
  for (size_t i = 0; i < shape.size(); ++i)
    if (spec[i] != -1 && spec[i] != shape[i]) return false;
  return true;
}

// The backend, found once: compiled into this program, else the plugin beside the program or in the build's
// library folder. `why` says what was tried when there is none.
struct Backend {
  const torch_backend::Api* api = nullptr;
  std::string why;
};

const Backend& TheBackend() {
  static const Backend backend = [] {
    Backend b;
#ifndef SYNTHDRIVE_TORCH_PLUGIN
    b.why = "no model runtime: this build was configured without LibTorch";
    return b;
#else
    std::vector<std::string> candidates;
    if (const char* env = std::getenv("SYNTHDRIVE_TORCH_PLUGIN"); env && *env) candidates.push_back(env);
    std::array<char, 4096> exe{};
    if (const ssize_t n = readlink("/proc/self/exe", exe.data(), exe.size() - 1); n > 0) {
      const std::filesystem::path dir = std::filesystem::path(std::string(exe.data(), static_cast<size_t>(n))).parent_path();
      candidates.push_back((dir / kPluginName).string());
      candidates.push_back((dir / ".." / "lib" / kPluginName).string());
    }
    candidates.push_back(SYNTHDRIVE_TORCH_PLUGIN);  // where this build put it
    std::string tried;
    for (const std::string& path : candidates) {
      std::error_code ec;
      if (!std::filesystem::is_regular_file(path, ec)) {
        tried += (tried.empty() ? "" : ", ") + path;
        continue;
      }
      void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
      if (!handle) {
        b.why = Msg() << "the LibTorch plugin " << path << " cannot be loaded: " << dlerror();
        return b;
      }
      using Entry = const torch_backend::Api* (*)();
      const auto entry = reinterpret_cast<Entry>(dlsym(handle, "SynthdriveTorchBackend"));
      const torch_backend::Api* api = entry ? entry() : nullptr;
      if (!api || api->abi_version != torch_backend::kAbiVersion) {
        b.why = Msg() << "the LibTorch plugin " << path << " is of another build (rebuild it with this program)";
        return b;
      }
      b.api = api;
      return b;
    }
    b.why = Msg() << "no model runtime: the LibTorch plugin " << kPluginName << " is not installed (looked at " << tried << ")";
    return b;
#endif
  }();
  return backend;
}

}  // namespace

namespace {
const torch_backend::Api* Api() { return TheBackend().api; }
}  // namespace

bool RuntimeAvailable() { return Api() != nullptr; }

std::string RuntimeDescription() {
  const torch_backend::Api* api = Api();
  return api ? api->describe(MaxThreads()) : TheBackend().why;
}

struct Model::Impl {
  std::filesystem::path file;
  ModelContract contract;
  std::string device;
  bool half = false;
  const torch_backend::Api* api = nullptr;
  torch_backend::Module* module = nullptr;
  ~Impl() {
    if (module) api->destroy(module);
  }
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
  const torch_backend::Api* api = Api();  // loads LibTorch, the first time
  if (!api)
    throw InputError(file, Msg() << "cannot load a " << stage << " model: " << TheBackend().why
                                 << " (a build with LibTorch: -DSYNTHDRIVE_WITH_TORCH=ON)");
  if (options.half && options.device.rfind("cuda", 0) != 0) throw InputError(file, "half precision is for CUDA devices only");
  auto impl = std::make_unique<Impl>();
  impl->file = file;
  impl->half = options.half;
  impl->api = api;
  std::string contract_json, error;
  impl->module = api->load(file.string(), options.device, options.half, MaxThreads(), kContractFile, &contract_json,
                           &impl->device, &error);
  if (!impl->module) throw InputError(file, error);
  if (contract_json.empty())
    throw InputError(file, Msg() << "TorchScript archive without a SynthDrive contract (" << kContractFile
                                 << "); export it with the tools/ exporter for the " << stage << " stage");
  impl->contract = ModelContract::Parse(contract_json, file);
  if (impl->contract.stage != stage)
    throw InputError(file, Msg() << "is a '" << impl->contract.stage << "' model ('" << impl->contract.name
                                 << "'), expected a '" << stage << "' model");
  return Model(std::move(impl));
}

const ModelContract& Model::contract() const { return impl_->contract; }
const std::filesystem::path& Model::file() const { return impl_->file; }
std::string Model::device() const { return impl_->device; }

std::vector<Tensor> Model::Run(const std::vector<Tensor>& inputs) const {
  const ModelContract& c = impl_->contract;
  if (inputs.size() != c.inputs.size())
    throw InputError(impl_->file, Msg() << "'" << c.name << "' takes " << c.inputs.size() << " inputs, given "
                                        << inputs.size());
  std::vector<bool> to_half(inputs.size());
  for (size_t i = 0; i < inputs.size(); ++i) {
    const Tensor& t = inputs[i];
    if (!Matches(t.shape, c.inputs[i].shape))
      throw InputError(impl_->file, Msg() << "input '" << c.inputs[i].name << "' of '" << c.name << "' must be "
                                          << ModelContract::ShapeString(c.inputs[i].shape) << ", given "
                                          << ModelContract::ShapeString(t.shape));
    SD_CHECK(static_cast<int64_t>(t.values.size()) == t.numel(), << t.values.size() << " vs " << t.numel());
    // Token ids stay float32 in half mode: float16 holds integers exactly only up to 2048, and a CLIP id
    // (up to 49407) would reach the embedding lookup rounded to another token.
    to_half[i] = impl_->half && c.inputs[i].encoding != "token_ids";
  }
  std::vector<Tensor> out;
  std::string error;
  if (!impl_->api->run(impl_->module, inputs, to_half, MaxThreads(), &out, &error))
    throw InputError(impl_->file, Msg() << "forward pass of '" << c.name << "' failed: " << error);
  if (out.size() != c.outputs.size())
    throw InputError(impl_->file, Msg() << "'" << c.name << "' returned " << out.size() << " outputs, its contract "
                                        << "names " << c.outputs.size());
  for (size_t i = 0; i < out.size(); ++i)
    if (!Matches(out[i].shape, c.outputs[i].shape))
      throw InputError(impl_->file, Msg() << "output '" << c.outputs[i].name << "' of '" << c.name << "' is "
                                          << ModelContract::ShapeString(out[i].shape) << ", its contract says "
                                          << ModelContract::ShapeString(c.outputs[i].shape));
  return out;
}

}  // namespace sd::models
