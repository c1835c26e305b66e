#include "models/normal_estimation.h"

#include <cmath>
#include <cstdlib>
#include <optional>
#include <random>

#include <gtest/gtest.h>

#include "core/error.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

// The tiny model computes 3 * (2r - 1, 2g - 1, -1 - b) per pixel and refuses sizes that are not multiples of 8:
// the C++ side must pad, crop back at the right offset and renormalise.
TEST(NormalEstimator, PadsCropsAndRenormalises) {
  SD_REQUIRE_TEST_MODEL(file, "normals_tiny.pt");
  const NormalEstimator est = NormalEstimator::FromModel(file);
  EXPECT_EQ(est.multiple(), 8);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  for (const auto& [w, h] : {std::pair{13, 21}, std::pair{16, 8}, std::pair{1, 1}}) {
    ImageF img(w, h, 3);
    for (float& v : img.vector()) v = u(rng);
    const ImageF n = est.Estimate(img);
    ASSERT_EQ(n.width(), w);
    ASSERT_EQ(n.height(), h);
    ASSERT_EQ(n.channels(), 3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const float ex = 2 * img.at(x, y, 0) - 1, ey = 2 * img.at(x, y, 1) - 1, ez = -1 - img.at(x, y, 2);
        const float len = std::sqrt(ex * ex + ey * ey + ez * ez);
        EXPECT_NEAR(n.at(x, y, 0), ex / len, 1e-5f);
        EXPECT_NEAR(n.at(x, y, 1), ey / len, 1e-5f);
        EXPECT_NEAR(n.at(x, y, 2), ez / len, 1e-5f);
        EXPECT_LT(n.at(x, y, 2), 0.0f);  // facing the camera: negative z in the OpenCV frame
      }
  }
}

TEST(NormalEstimator, NoClassicalFallbackTheMissingFileIsNamed) {
  testing::TempDir empty;
  const char* old = std::getenv("SYNTHDRIVE_MODELS");
  const std::optional<std::string> saved = old ? std::optional<std::string>(old) : std::nullopt;
  setenv("SYNTHDRIVE_MODELS", empty.path().c_str(), 1);
  try {
    NormalEstimator::Resolve("auto");
    ADD_FAILURE() << "normal estimation resolved without a model";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("normal_estimator.pt"), std::string::npos) << e.what();
  }
  if (saved) setenv("SYNTHDRIVE_MODELS", saved->c_str(), 1);
  else unsetenv("SYNTHDRIVE_MODELS");
}

TEST(NormalEstimator, OtherStagesAreRefused) {
  SD_REQUIRE_TEST_MODEL(file, "harmonizer_tiny.pt");
  try {
    NormalEstimator::FromModel(file);
    FAIL() << "a harmoniser loaded as a normal estimator";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("expected a 'normal_estimation' model"), std::string::npos) << e.what();
  }
  SD_REQUIRE_TEST_MODEL(normals, "normals_tiny.pt");
  EXPECT_THROW(NormalEstimator::FromModel(normals).Estimate(ImageF(4, 4, 1)), InputError);
}

}  // namespace
}  // namespace sd::models
