#include "models/clip_tokenizer.h"

#include <fstream>

#include <gtest/gtest.h>

#include "core/error.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

// A handmade merges file. Ids follow from the reference layout: 0..255 the byte symbols in the map's order
// ('!'..'~' first, so a printable ASCII byte b has id b - 33; then 0xA1..0xAC at 94.., 0xAE..0xFF at 106..,
// then the 68 non-printable bytes from 188: byte 0 -> 188, byte 1 -> 189, ...), 256..511 the same with
// "</w>", 512 + rank per merge, then <|startoftext|> and <|endoftext|>.
constexpr const char* kMerges =
    "#version: 0.2\n"
    "h e\n"         // 512 "he"
    "l l\n"         // 513 "ll"
    "he ll\n"       // 514 "hell"
    "hell o</w>\n"  // 515 "hello</w>"
    "w o\n"         // 516 "wo"
    "r l\n";        // 517 "rl"

int Byte(char c) { return c - 33; }           // printable ASCII
int WordEnd(char c) { return 256 + Byte(c); }  // printable ASCII + "</w>"

class ClipTokenizerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::ofstream(dir_ / "merges.txt") << kMerges;
  }
  ClipTokenizer Load(int max_merges = -1) const { return ClipTokenizer::Load(dir_ / "merges.txt", max_merges); }
  testing::TempDir dir_;
};

TEST_F(ClipTokenizerTest, VocabularyLayoutAndSpecialTokens) {
  const ClipTokenizer t = Load();
  EXPECT_EQ(t.vocab_size(), 520);
  EXPECT_EQ(t.start_token(), 518);
  EXPECT_EQ(t.end_token(), 519);
}

TEST_F(ClipTokenizerTest, HandComputedIds) {
  const ClipTokenizer t = Load();
  // h e l l o</w> -> he (rank 0) -> ll (1) -> hell (2) -> hello</w> (3).
  EXPECT_EQ(t.Encode("hello"), (std::vector<int>{515}));
  // w o r l d</w> -> wo (4) -> rl (5); "rl d</w>" is no merge.
  EXPECT_EQ(t.Encode("world"), (std::vector<int>{516, 517, WordEnd('d')}));
  // "hell" ends a word: "l l</w>" is no merge, so only "he" merges.
  EXPECT_EQ(t.Encode("hell"), (std::vector<int>{512, Byte('l'), WordEnd('l')}));
  // Punctuation runs are pieces of their own.
  EXPECT_EQ(t.Encode("hello, world!"), (std::vector<int>{515, WordEnd(','), 516, 517, WordEnd('d'), WordEnd('!')}));
  // Contractions split off; numbers are one digit per piece.
  EXPECT_EQ(t.Encode("it's 42"),
            (std::vector<int>{Byte('i'), WordEnd('t'), Byte('\''), WordEnd('s'), WordEnd('4'), WordEnd('2')}));
  // Non-ASCII: U+00E9 is bytes C3 A9; 0xC3 is the 127th map entry (106 + 0xC3 - 0xAE), 0xA9 the 102nd.
  EXPECT_EQ(t.Encode("\xC3\xA9"), (std::vector<int>{127, 256 + 102}));
  // Upper case U+00C9 lower-cases to U+00E9 first.
  EXPECT_EQ(t.Encode("\xC3\x89"), (std::vector<int>{127, 256 + 102}));
  // A control byte maps to a code point >= 256: byte 1 is entry 189 of the map.
  EXPECT_EQ(t.Encode("\x01"), (std::vector<int>{256 + 189}));
  // Special tokens written in the text stay whole.
  EXPECT_EQ(t.Encode("a <|endoftext|>"), (std::vector<int>{WordEnd('a'), 519}));
}

TEST_F(ClipTokenizerTest, WhitespaceAndCaseAreNormalised) {
  const ClipTokenizer t = Load();
  EXPECT_EQ(t.Encode("  HeLLo \t\n World  "), t.Encode("hello world"));
  EXPECT_EQ(t.Encode("hello world"), (std::vector<int>{515, 516, 517, WordEnd('d')}));
  EXPECT_TRUE(t.Encode(" \t ").empty());
  // ftfy's defaults as the reference applies them: a curly apostrophe, full-width letters, a ligature.
  EXPECT_EQ(t.Encode("it\xE2\x80\x99s"), t.Encode("it's"));
  EXPECT_EQ(t.Encode("\xEF\xBC\xA8\xEF\xBD\x85llo"), t.Encode("hello"));  // U+FF28 U+FF45: full-width H e
  EXPECT_EQ(t.Encode("\xEF\xAC\x81"), t.Encode("fi"));                     // U+FB01
}

TEST_F(ClipTokenizerTest, TokenizeWrapsPadsAndTruncatesKeepingTheEndToken) {
  const ClipTokenizer t = Load();
  std::vector<int> expected{518, 515, 516, 517, WordEnd('d'), 519};
  expected.resize(77, 0);
  EXPECT_EQ(t.Tokenize("hello world"), expected);
  EXPECT_EQ(t.Tokenize("hello world", 4), (std::vector<int>{518, 515, 516, 519}));
  std::string long_text;
  for (int i = 0; i < 100; ++i) long_text += "world ";
  const std::vector<int> ids = t.Tokenize(long_text, 77);
  ASSERT_EQ(ids.size(), 77u);
  EXPECT_EQ(ids.front(), 518);
  EXPECT_EQ(ids.back(), 519);
  EXPECT_EQ(ids[75], WordEnd('d'));  // body ids 0..74 (wo rl d</w> repeated) before the end token
}

TEST_F(ClipTokenizerTest, DecodeRoundTrips) {
  const ClipTokenizer t = Load();
  EXPECT_EQ(t.Decode(t.Tokenize("Hello World")), "hello world");
  for (const std::string text : {"hello, world!", "it's 42 \xC3\xA9t\xC3\xA9", "a\x01 b ~~ hell", "wow  rlrl"}) {
    const std::vector<int> ids = t.Encode(text);
    EXPECT_EQ(t.Encode(t.Decode(ids)), ids) << text;
  }
  EXPECT_EQ(t.Decode(t.Encode("\xC3\xA9t\xC3\xA9")), "\xC3\xA9t\xC3\xA9");
}

TEST_F(ClipTokenizerTest, MaxMergesReadsOnlyTheFirstRanks) {
  const ClipTokenizer t = Load(3);  // he, ll, hell: "hell o</w>" is not read
  EXPECT_EQ(t.vocab_size(), 517);
  EXPECT_EQ(t.Encode("hello"), (std::vector<int>{514, WordEnd('o')}));
  EXPECT_THROW(Load(7), InputError);
}

TEST_F(ClipTokenizerTest, BadFilesAreNamed) {
  try {
    ClipTokenizer::Load(dir_ / "absent.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("absent.txt"), std::string::npos) << e.what();
  }
  std::ofstream(dir_ / "noheader.txt") << "h e\n";
  EXPECT_THROW(ClipTokenizer::Load(dir_ / "noheader.txt"), InputError);
  std::ofstream(dir_ / "bad.txt") << "#version: 0.2\nh e\nx y z\n";
  try {
    ClipTokenizer::Load(dir_ / "bad.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 3"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace sd::models
