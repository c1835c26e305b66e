// The runtime of a build configured without LibTorch (-DSYNTHDRIVE_WITH_TORCH=OFF): every load says so, and
// each stage falls back to its classical method.
#include "core/error.h"
#include "models/runtime.h"

namespace sd::models {

bool RuntimeAvailable() { return false; }
std::string RuntimeDescription() { return "no model runtime: this build was configured without LibTorch"; }

struct Model::Impl {
  std::filesystem::path file;
  ModelContract contract;
};

Model::Model(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Model::Model(Model&&) noexcept = default;
Model& Model::operator=(Model&&) noexcept = default;
Model::~Model() = default;

Model Model::Load(const std::filesystem::path& file, std::string_view stage, const RuntimeOptions&) {
  throw InputError(file, Msg() << "cannot load a " << stage
                               << " model: this build has no LibTorch (reconfigure with -DSYNTHDRIVE_WITH_TORCH=ON)");
}

const ModelContract& Model::contract() const { return impl_->contract; }
const std::filesystem::path& Model::file() const { return impl_->file; }
std::string Model::device() const { return "none"; }
std::vector<Tensor> Model::Run(const std::vector<Tensor>&) const {
  SD_CHECK(false, << "a Model cannot exist without LibTorch");
  return {};
}

}  // namespace sd::models
