// The parts of the runtime that do not need LibTorch: tensors, contracts, where models live.
#include "models/runtime.h"

#include <cstdlib>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "io/json.h"

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

}  // namespace sd::models
