#include "models/clip_tokenizer.h"

#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "io/gzip.h"
#include "io/json.h"
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

// A gzip file of `data` in one stored (uncompressed) deflate block: RFC 1952 header, RFC 1951 block, CRC-32
// and length. Written by hand so the test needs no compressor.
std::string GzipStored(const std::string& data) {
  uint32_t crc = 0xFFFFFFFFu;
  for (unsigned char c : data) {
    crc ^= c;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  crc ^= 0xFFFFFFFFu;
  const auto le32 = [](uint32_t v) {
    return std::string{static_cast<char>(v), static_cast<char>(v >> 8), static_cast<char>(v >> 16),
                       static_cast<char>(v >> 24)};
  };
  const auto n = static_cast<uint16_t>(data.size());
  const auto nn = static_cast<uint16_t>(~n);
  std::string gz{'\x1f', '\x8b', 8, 0, 0, 0, 0, 0, 0, '\xff'};
  gz += std::string{1, static_cast<char>(n), static_cast<char>(n >> 8), static_cast<char>(nn),
                    static_cast<char>(nn >> 8)};  // final stored block, LEN, NLEN
  return gz + data + le32(crc) + le32(static_cast<uint32_t>(data.size()));
}

TEST_F(ClipTokenizerTest, ReadsGzipMergesFilesByMagic) {
  const std::string gz = GzipStored(kMerges);
  std::ofstream(dir_ / "merges.bin", std::ios::binary) << gz;  // no .gz suffix: the magic decides
  const ClipTokenizer t = ClipTokenizer::Load(dir_ / "merges.bin");
  EXPECT_EQ(t.vocab_size(), 520);
  EXPECT_EQ(t.Encode("hello world"), Load().Encode("hello world"));
  std::string corrupt = gz;
  corrupt[corrupt.size() - 6] ^= 0x01;  // a CRC byte
  std::ofstream(dir_ / "corrupt.txt.gz", std::ios::binary) << corrupt;
  try {
    ClipTokenizer::Load(dir_ / "corrupt.txt.gz");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("corrupt.txt.gz"), std::string::npos) << e.what();
  }
}

TEST_F(ClipTokenizerTest, HeaderMayCarryAPrefixAsOpenAIsDoes) {
  std::ofstream(dir_ / "openai.txt") << "\"bpe_simple_vocab_16e6.txt#version: 0.2\nh e\n";
  EXPECT_EQ(ClipTokenizer::Load(dir_ / "openai.txt").vocab_size(), 515);
}

// The reference runs html.unescape twice after ftfy.
TEST_F(ClipTokenizerTest, HtmlReferencesAreUnescapedTwice) {
  const ClipTokenizer t = Load();
  EXPECT_EQ(t.Encode("a &amp; b"), t.Encode("a & b"));
  EXPECT_EQ(t.Encode("a &amp;amp; b"), t.Encode("a & b"));  // twice
  EXPECT_EQ(t.Encode("&lt;hello&gt;"), t.Encode("<hello>"));
  EXPECT_EQ(t.Encode("&#104;&#x65;llo"), t.Encode("hello"));
  EXPECT_EQ(t.Encode("&eacute &Eacute;"), t.Encode("\xC3\xA9 \xC3\xA9"));  // a legacy name needs no ';'
  EXPECT_EQ(t.Encode("&notit;"), t.Encode("\xC2\xACit;"));  // the longest legacy prefix
  EXPECT_EQ(t.Encode("&#128;"), t.Encode("\xE2\x82\xAC"));  // C1 controls read as windows-1252
  EXPECT_EQ(t.Encode("a&#1;b"), t.Encode("ab"));              // a control vanishes
  EXPECT_EQ(t.Encode("&hellip"), t.Encode("& hellip"));       // not legacy: needs its ';'
  EXPECT_EQ(t.Decode(t.Encode("&bogus; &#x;")), "& bogus ; &# x ;");  // not references: kept as written
}

TEST_F(ClipTokenizerTest, LowerCasingFollowsPythonsStrLower) {
  const ClipTokenizer t = Load();
  EXPECT_EQ(t.Encode("\xD0\x9C\xD0\x9E\xD0\xA1"), t.Encode("\xD0\xBC\xD0\xBE\xD1\x81"));  // Cyrillic
  EXPECT_EQ(t.Encode("\xC6\xAF\xE1\xBB\x9C"), t.Encode("\xC6\xB0\xE1\xBB\x9D"));  // Vietnamese U+01AF U+1EDC
  EXPECT_EQ(t.Encode("\xC4\xB0"), t.Encode("i\xCC\x87"));  // U+0130 -> i + U+0307
  // Capital sigma: final at a word's end, medial elsewhere. ΟΔΟΣ -> οδος with U+03C2; ΣΑ -> σα.
  EXPECT_EQ(t.Encode("\xCE\x9F\xCE\x94\xCE\x9F\xCE\xA3."), t.Encode("\xCE\xBF\xCE\xB4\xCE\xBF\xCF\x82."));
  EXPECT_EQ(t.Encode("\xCE\xA3\xCE\x91"), t.Encode("\xCF\x83\xCE\xB1"));
  EXPECT_EQ(t.Encode("\xCE\xA3"), t.Encode("\xCF\x83"));  // alone: not preceded by a letter
}

// Piece boundaries show as "</w>" on a piece's last symbol, so "x y" with a space encodes as x and y cut apart.
TEST_F(ClipTokenizerTest, PreTokenisationClassesEveryScriptAsTheReference) {
  const ClipTokenizer t = Load();
  // Katakana with its prolonged sound mark U+30FC (a letter, Lm) is one piece.
  EXPECT_NE(t.Encode("\xE3\x82\xAB\xE3\x83\xBC\xE3\x83\xB3"), t.Encode("\xE3\x82\xAB \xE3\x83\xBC \xE3\x83\xB3"));
  // Bengali KA, virama (a mark: the punctuation class), SSA: three pieces.
  EXPECT_EQ(t.Encode("\xE0\xA6\x95\xE0\xA7\x8D\xE0\xA6\xB7"), t.Encode("\xE0\xA6\x95 \xE0\xA7\x8D \xE0\xA6\xB7"));
  // Tamil digit ten U+0BF0 is a number: a piece of its own.
  EXPECT_EQ(t.Encode("a\xE0\xAF\xB0" "b"), t.Encode("a \xE0\xAF\xB0 b"));
  // U+001C..U+001F: stripped at the ends (str.isspace) but kept inside (not regex \s): the punctuation class.
  EXPECT_EQ(t.Encode("\x1c hello \x1f"), t.Encode("hello"));
  EXPECT_EQ(t.Encode("a\x1c" "b"), t.Encode("a \x1c b"));
  EXPECT_NE(t.Encode("a\x1c" "b"), t.Encode("a b"));
  // re.IGNORECASE: long s (U+017F) ends a contraction as "s" does; U+0345 matches nothing and is dropped.
  EXPECT_EQ(t.Encode("'\xC5\xBFx"), t.Encode("'\xC5\xBF x"));
  EXPECT_EQ(t.Encode("a\xCD\x85" "b"), t.Encode("a b"));
}

// OpenAI's published vocabulary (gzip, read as it ships) against the ids CLIP's own Python tokenizer gives 51
// prompts (the README says 50): driving objects, contractions, case, punctuation, whitespace, accents, CJK,
// emoji, HTML entities, an over-long prompt (../shared/data/models/clip/README.md).
class ClipReferenceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    SD_REQUIRE_SHARED(vocab, "models/clip/bpe_simple_vocab_16e6.txt.gz");
    SD_REQUIRE_SHARED(reference, "models/clip/reference_tokens.json");
    vocab_ = vocab;
    reference_ = ReadJsonFile(reference);
    // The reference reads merges 1..48894 of the file: vocabulary 49408 = 256 bytes x 2 + merges + 2 specials.
    max_merges_ = reference_.at("vocab_size").get<int>() - 514;
  }
  std::filesystem::path vocab_;
  nlohmann::json reference_;
  int max_merges_ = 0;
};

TEST_F(ClipReferenceTest, ReproducesEveryReferenceTokenisation) {
  const ClipTokenizer t = ClipTokenizer::Load(vocab_, max_merges_);
  EXPECT_EQ(t.vocab_size(), reference_.at("vocab_size").get<int>());
  EXPECT_EQ(t.start_token(), reference_.at("sot").get<int>());
  EXPECT_EQ(t.end_token(), reference_.at("eot").get<int>());
  const nlohmann::json& cases = reference_.at("cases");
  ASSERT_GE(cases.size(), 50u);  // the README counts 50; the file holds 51
  constexpr int kContext = 77;
  for (const nlohmann::json& c : cases) {
    const std::string text = c.at("text").get<std::string>();
    const std::vector<int> bpe_ids = c.at("bpe_ids").get<std::vector<int>>();
    EXPECT_EQ(t.Encode(text), bpe_ids) << "'" << text << "'";
    // The reference file records bare BPE ids; the model input wraps them in start / end, truncates keeping
    // the end token last (clip.tokenize(truncate=True), open_clip) and pads with 0.
    std::vector<int> expected{t.start_token()};
    expected.insert(expected.end(), bpe_ids.begin(), bpe_ids.end());
    expected.push_back(t.end_token());
    if (expected.size() > kContext) {
      expected.resize(kContext);
      expected.back() = t.end_token();
    }
    expected.resize(kContext, 0);
    EXPECT_EQ(t.Tokenize(text, kContext), expected) << "'" << text << "'";
  }
}

TEST_F(ClipReferenceTest, GzipAndPlainMergesFilesGiveTheSameTokenizer) {
  testing::TempDir tmp;
  const std::filesystem::path plain = tmp / "bpe_simple_vocab_16e6.txt";
  std::ofstream(plain, std::ios::binary) << ReadMaybeGzipFile(vocab_, size_t{64} << 20);
  const ClipTokenizer from_gz = ClipTokenizer::Load(vocab_, max_merges_);
  const ClipTokenizer from_txt = ClipTokenizer::Load(plain, max_merges_);
  ASSERT_EQ(from_gz.vocab_size(), from_txt.vocab_size());
  for (int id = 0; id < from_gz.vocab_size(); ++id)
    ASSERT_EQ(from_gz.Decode({id}), from_txt.Decode({id})) << "id " << id;
  for (const nlohmann::json& c : reference_.at("cases")) {
    const std::string text = c.at("text").get<std::string>();
    EXPECT_EQ(from_gz.Tokenize(text), from_txt.Tokenize(text)) << "'" << text << "'";
  }
  // Without a limit every merge line is read, from either form.
  EXPECT_EQ(ClipTokenizer::Load(vocab_).vocab_size(), ClipTokenizer::Load(plain).vocab_size());
}

}  // namespace
}  // namespace sd::models
