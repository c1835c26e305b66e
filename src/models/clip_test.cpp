#include "models/clip.h"

#include <cmath>
#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

namespace fs = std::filesystem;


ImageF RandomImage(int w, int h, int ch, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  ImageF img(w, h, ch);
  for (float& v : img.vector()) v = u(rng);
  return img;
}

double Norm(const Embedding& e) {
  double n2 = 0;
  for (float v : e) n2 += double(v) * v;
  return std::sqrt(n2);
}

float MaxDiff(const Embedding& a, const Embedding& b) {
  float worst = 0;
  for (size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
  return worst;
}

TEST(ResizeBicubic, KeepsConstantsAndRampsAndLowPassesWhenShrinking) {
  ImageF img(40, 30, 2);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) {
      img.at(x, y, 0) = 0.3f;
      img.at(x, y, 1) = (x % 2) ? 1.0f : 0.0f;  // the highest frequency there is
    }
  const ImageF small = ResizeBicubic(img, 10, 15);
  ASSERT_EQ(small.width(), 10);
  ASSERT_EQ(small.height(), 15);
  for (int y = 0; y < 15; ++y)
    for (int x = 1; x < 9; ++x) {
      EXPECT_NEAR(small.at(x, y, 0), 0.3f, 1e-5f);
      // A stretched kernel averages the stripes; plain bicubic taps would alias them to 0 or 1.
      EXPECT_NEAR(small.at(x, y, 1), 0.5f, 0.05f) << x << "," << y;
    }
}

TEST(ClipPreprocess, ShorterSideToSizeAndCentreCrop) {
  // A 100 x 50 image whose left and right quarters are black, middle white: after resizing to 448 x 224 and
  // cropping the centre 224, everything is white except the kernel's reach at the two boundaries.
  ImageF img(100, 50, 3, 0.0f);
  for (int y = 0; y < 50; ++y)
    for (int x = 25; x < 75; ++x)
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = 1.0f;
  const ImageF crop = ClipPreprocess(img, 224);
  ASSERT_EQ(crop.width(), 224);
  ASSERT_EQ(crop.height(), 224);
  EXPECT_NEAR(crop.at(112, 112, 0), 1.0f, 1e-5f);
  EXPECT_NEAR(crop.at(10, 100, 1), 1.0f, 1e-5f);
  EXPECT_LT(crop.at(0, 100, 1), 0.9f);  // the black quarter begins at the crop's left edge
}

// Against an independent Python statement of the reference tokenizer, on 128 merges learned from a small
// caption corpus (make_stage_test_models.py): realistic merge chains, contractions, punctuation runs, digits,
// underscores, Latin-1 letters, a special token in the text, truncation.
TEST(ClipTokenizer, MatchesThePythonReferenceOnTrainedMerges) {
  SD_REQUIRE_TEST_MODEL(merges, "bpe_trained.txt");
  const ClipTokenizer t = ClipTokenizer::Load(merges);
  std::ifstream in(testing::TestModel("tokenizer_cases.json"));
  const nlohmann::json cases = nlohmann::json::parse(in);
  ASSERT_GE(cases.size(), 9u);
  for (const auto& c : cases) {
    const std::string text = c["text"].get<std::string>();
    EXPECT_EQ(t.Tokenize(text), c["ids"].get<std::vector<int>>()) << text;
  }
}

class ClipEncoderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::TestModel("clip_tiny");
    if (dir_.empty()) GTEST_SKIP() << "tiny CLIP test models not built (needs python3 with torch)";
  }
  fs::path dir_;
};

TEST_F(ClipEncoderTest, LoadsTheFolderAndReadsItsContracts) {
  const ClipEncoder clip = ClipEncoder::Load(dir_);
  EXPECT_EQ(clip.embed_dim(), 16);
  EXPECT_EQ(clip.image_size(), 224);
  EXPECT_EQ(clip.context_length(), 77);
  EXPECT_EQ(clip.tokenizer().vocab_size(), 520);
  EXPECT_NE(clip.Describe().find("clip-tiny-image"), std::string::npos) << clip.Describe();
}

TEST_F(ClipEncoderTest, ImageEmbeddingMatchesTheEagerReference) {
  std::vector<int64_t> shape, eshape;
  const std::vector<float> nchw = testing::ReadRawFloats(testing::TestModel("clip_image_input.f32"), &shape);
  const std::vector<float> expected = testing::ReadRawFloats(testing::TestModel("clip_image_embedding.f32"), &eshape);
  const int s = static_cast<int>(shape[2]);
  ImageF img(s, s, 3);
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < s; ++y)
      for (int x = 0; x < s; ++x) img.at(x, y, c) = nchw[(static_cast<size_t>(c) * s + y) * s + x];
  const std::vector<Embedding> e = ClipEncoder::Load(dir_).EmbedImages(std::vector<ImageF>{img});
  ASSERT_EQ(e.size(), 1u);
  ASSERT_EQ(e[0].size(), expected.size());
  EXPECT_LT(MaxDiff(e[0], expected), 1e-5f);
}

TEST_F(ClipEncoderTest, TextEmbeddingGoesThroughTheTokenizerExactly) {
  // The reference was computed in Python from the hand-worked ids of "hello world"; "Hello,   World"
  // must tokenise differently (the comma) and " HELLO  world " identically.
  std::vector<int64_t> shape;
  const std::vector<float> expected = testing::ReadRawFloats(testing::TestModel("clip_text_hello_world.f32"), &shape);
  const ClipEncoder clip = ClipEncoder::Load(dir_);
  const std::vector<Embedding> e = clip.EmbedTexts({"hello world", " HELLO  world ", "hello, world"});
  ASSERT_EQ(e.size(), 3u);
  EXPECT_LT(MaxDiff(e[0], expected), 1e-5f);
  EXPECT_LT(MaxDiff(e[1], expected), 1e-6f);
  EXPECT_GT(MaxDiff(e[2], expected), 1e-3f);
  EXPECT_NEAR(ClipEncoder::Similarity(e[0], e[1]), 1.0f, 1e-5f);
}

TEST_F(ClipEncoderTest, UnitNormAndBatchEquivalence) {
  std::vector<ImageF> images{RandomImage(300, 200, 3, 1), RandomImage(64, 96, 3, 2), RandomImage(224, 224, 4, 3),
                             RandomImage(50, 50, 1, 4), RandomImage(231, 500, 3, 5)};
  ClipOptions one;
  one.batch_size = 1;
  ClipOptions two;
  two.batch_size = 2;
  const std::vector<Embedding> a = ClipEncoder::Load(dir_, {}, one).EmbedImages(images);
  const std::vector<Embedding> b = ClipEncoder::Load(dir_, {}, two).EmbedImages(images);
  ASSERT_EQ(a.size(), images.size());
  ASSERT_EQ(b.size(), images.size());
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].size(), 16u);
    EXPECT_NEAR(Norm(a[i]), 1.0, 1e-5);
    EXPECT_LT(MaxDiff(a[i], b[i]), 1e-5f) << i;
    EXPECT_NEAR(ClipEncoder::Similarity(a[i], a[i]), 1.0f, 1e-5f);
  }
  const std::vector<std::string> texts{"hello", "world", "hello world", "wow", "", "a much longer caption"};
  const std::vector<Embedding> ta = ClipEncoder::Load(dir_, {}, one).EmbedTexts(texts);
  const std::vector<Embedding> tb = ClipEncoder::Load(dir_, {}, two).EmbedTexts(texts);
  for (size_t i = 0; i < ta.size(); ++i) {
    EXPECT_NEAR(Norm(ta[i]), 1.0, 1e-5);
    EXPECT_LT(MaxDiff(ta[i], tb[i]), 1e-5f) << texts[i];
  }
  EXPECT_TRUE(ClipEncoder::Load(dir_).EmbedImages(std::vector<ImageF>{}).empty());
  EXPECT_THROW(ClipEncoder::Similarity(ta[0], Embedding(3, 0.0f)), InputError);
}

TEST_F(ClipEncoderTest, MissingFilesAreAllNamedAndSwappedStagesRefused) {
  testing::TempDir tmp;
  fs::copy_file(dir_ / kClipImageFile, tmp / kClipImageFile);
  try {
    ClipEncoder::Load(tmp.path());
    FAIL() << "a folder without the text model and vocabulary loaded";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("clip_text.pt, bpe_simple_vocab_16e6.txt"), std::string::npos) << what;
    EXPECT_EQ(what.find("lacks clip_image.pt"), std::string::npos) << what;
  }
  // The text model saved under the image model's name: the runtime names the file and both stages.
  testing::TempDir swapped;
  fs::copy_file(dir_ / kClipTextFile, swapped / kClipImageFile);
  fs::copy_file(dir_ / kClipImageFile, swapped / kClipTextFile);
  fs::copy_file(dir_ / kClipVocabFile, swapped / kClipVocabFile);
  try {
    ClipEncoder::Load(swapped.path());
    FAIL() << "swapped CLIP models loaded";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("clip_image.pt: is a 'clip_text' model"), std::string::npos) << what;
  }
  EXPECT_THROW(ClipEncoder::Load(testing::TestModel("normals_tiny.pt")), InputError);
}

}  // namespace
}  // namespace sd::models
