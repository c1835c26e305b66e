#include "models/runtime.h"

#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

namespace fs = std::filesystem;

Tensor ReadRaw(const fs::path& file) {
  Tensor t;
  t.values = testing::ReadRawFloats(file, &t.shape);
  return t;
}

std::string LoadError(const fs::path& file, std::string_view stage) {
  try {
    Model::Load(file, stage);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(ModelContract, ParsesTheStoredFields) {
  const ModelContract c = ModelContract::Parse(R"({"format": "synthdrive-model/1", "stage": "super_resolution",
      "name": "m", "license": "MIT",
      "inputs": [{"name": "image", "shape": [-1, 3, -1, -1], "range": [0, 255], "layout": "NCHW"}],
      "outputs": [{"name": "image", "shape": [-1, 3, -1, -1]}],
      "params": {"scale": 2, "receptive_radius": 9.5, "note": "text is ignored"},
      "verification": {"psnr_db": 44.5}})",
                                               "m.pt");
  EXPECT_EQ(c.stage, "super_resolution");
  EXPECT_EQ(c.license, "MIT");
  ASSERT_EQ(c.inputs.size(), 1u);
  EXPECT_EQ(c.inputs[0].shape, (std::vector<int64_t>{-1, 3, -1, -1}));
  EXPECT_DOUBLE_EQ(c.inputs[0].range[1], 255);
  EXPECT_DOUBLE_EQ(c.outputs[0].range[1], 1);  // default range
  EXPECT_DOUBLE_EQ(c.Param("receptive_radius", "m.pt"), 9.5);
  EXPECT_EQ(c.params.count("note"), 0u);
  EXPECT_DOUBLE_EQ(c.verification.at("psnr_db"), 44.5);
  EXPECT_THROW(c.Param("missing", "m.pt"), InputError);
}

TEST(ModelContract, RejectsMalformedContractsNamingTheFile) {
  const auto error = [](const std::string& text) {
    try {
      ModelContract::Parse(text, "bad.pt");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error("{not json").find("bad.pt: SynthDrive contract is not valid JSON"), std::string::npos);
  EXPECT_NE(error(R"({"format": "other/2"})").find("unknown contract format 'other/2'"), std::string::npos);
  EXPECT_NE(error(R"({"format": "synthdrive-model/1", "stage": "s"})").find("name"), std::string::npos);
  const std::string zero_dim = error(R"({"format": "synthdrive-model/1", "stage": "s", "name": "n",
      "inputs": [{"name": "x", "shape": [0, 3]}], "outputs": [{"name": "y", "shape": [1]}]})");
  EXPECT_NE(zero_dim.find("positive size or -1"), std::string::npos) << zero_dim;
  const std::string half = error(R"({"format": "synthdrive-model/1", "stage": "s", "name": "n",
      "inputs": [{"name": "x", "shape": [1], "dtype": "float16"}], "outputs": [{"name": "y", "shape": [1]}]})");
  EXPECT_NE(half.find("only float32"), std::string::npos) << half;
}

TEST(Runtime, DescribesItself) {
  if (!RuntimeAvailable()) GTEST_SKIP() << "built without LibTorch: " << RuntimeDescription();
  EXPECT_NE(RuntimeDescription().find("LibTorch"), std::string::npos);
}

TEST(Runtime, RunsATinyModelAsItsReferenceDid) {
  SD_REQUIRE_TEST_MODEL(file, "sr_tiny_x2.pt");
  const Model model = Model::Load(file, "super_resolution");
  EXPECT_EQ(model.contract().name, "sr-tiny-x2");
  EXPECT_EQ(model.device(), ToString(CurrentDevice()));  // the process's device (SYNTHDRIVE_DEVICE)
  const Tensor input = ReadRaw(testing::TestModel("sr_tiny_x2_input.f32"));
  const Tensor expected = ReadRaw(testing::TestModel("sr_tiny_x2_output.f32"));
  const std::vector<Tensor> out = model.Run({input});
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].shape, expected.shape);
  float worst = 0;
  for (size_t i = 0; i < expected.values.size(); ++i)
    worst = std::max(worst, std::abs(out[0].values[i] - expected.values[i]));
  EXPECT_LT(worst, 1e-3f);  // of a 0..255 range
}

TEST(Runtime, ChecksInputsAgainstTheContract) {
  SD_REQUIRE_TEST_MODEL(file, "sr_tiny_x2.pt");
  const Model model = Model::Load(file, "super_resolution");
  try {
    model.Run({Tensor({1, 4, 8, 8})});
    FAIL() << "a 4-channel input passed a [-1, 3, -1, -1] contract";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("must be [-1, 3, -1, -1], given [1, 4, 8, 8]"), std::string::npos) << e.what();
  }
  EXPECT_THROW(model.Run({}), InputError);
}

TEST(Runtime, RejectsUnusableFilesNamingThem) {
  SD_REQUIRE_TEST_MODEL(good, "sr_tiny_x2.pt");
  testing::TempDir tmp;
  EXPECT_NE(LoadError(tmp / "absent.pt", "super_resolution").find("absent.pt: no such model file"), std::string::npos);

  std::ofstream(tmp / "garbage.pt") << "this is not a zip archive";
  EXPECT_NE(LoadError(tmp / "garbage.pt", "super_resolution").find("garbage.pt: not a readable TorchScript archive"),
            std::string::npos);

  // A weight file cut short, as an interrupted copy leaves it.
  const auto size = fs::file_size(good);
  fs::copy_file(good, tmp / "truncated.pt");
  fs::resize_file(tmp / "truncated.pt", size / 2);
  EXPECT_NE(LoadError(tmp / "truncated.pt", "super_resolution").find("truncated.pt: not a readable TorchScript"),
            std::string::npos);

  const std::string no_contract = LoadError(testing::TestModel("no_contract.pt"), "super_resolution");
  EXPECT_NE(no_contract.find("without a SynthDrive contract"), std::string::npos) << no_contract;

  const std::string wrong_stage = LoadError(testing::TestModel("wrong_stage.pt"), "super_resolution");
  EXPECT_NE(wrong_stage.find("is a 'clip_image' model ('clip-tiny'), expected a 'super_resolution' model"),
            std::string::npos)
      << wrong_stage;
}

TEST(Runtime, RejectsDevicesItCannotUse) {
  SD_REQUIRE_TEST_MODEL(file, "sr_tiny_x2.pt");
  RuntimeOptions bogus;
  bogus.device = "tpu:7";
  EXPECT_THROW(Model::Load(file, "super_resolution", bogus), InputError);
  RuntimeOptions half_on_cpu;
  half_on_cpu.device = "cpu";
  half_on_cpu.half = true;
  EXPECT_THROW(Model::Load(file, "super_resolution", half_on_cpu), InputError);
}

// The same model on the GPU: float32 results equal the CPU's to rounding, float16 to half precision.
TEST(Runtime, CudaAgreesWithCpu) {
  SD_REQUIRE_TEST_MODEL(file, "sr_tiny_x2.pt");
  if (RuntimeDescription().find("CUDA available") == std::string::npos)
    GTEST_SKIP() << "this LibTorch sees no CUDA device: " << RuntimeDescription();
  const Tensor input = ReadRaw(testing::TestModel("sr_tiny_x2_input.f32"));
  RuntimeOptions cpu, cuda, cuda_half;
  cpu.device = "cpu";
  cuda.device = cuda_half.device = "cuda";
  cuda_half.half = true;
  const Tensor reference = Model::Load(file, "super_resolution", cpu).Run({input})[0];
  const Model on_gpu = Model::Load(file, "super_resolution", cuda);
  EXPECT_EQ(on_gpu.device().rfind("cuda", 0), 0u) << on_gpu.device();
  for (const auto& [options, tolerance] : {std::pair{cuda, 1e-3f}, std::pair{cuda_half, 0.5f}}) {
    const Tensor out = Model::Load(file, "super_resolution", options).Run({input})[0];
    ASSERT_EQ(out.shape, reference.shape);
    float worst = 0;
    for (size_t i = 0; i < out.values.size(); ++i) worst = std::max(worst, std::abs(out.values[i] - reference.values[i]));
    EXPECT_LT(worst, tolerance) << (options.half ? "float16" : "float32");  // of a 0..255 range
  }
}

}  // namespace
}  // namespace sd::models
