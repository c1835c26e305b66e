#pragma once
// CLIP's byte-level BPE tokenizer (Radford et al. 2021), written from the published algorithm, so that text
// queries become the exact token ids the "clip_text" model was trained on.
//
// Vocabulary file: OpenAI's bpe_simple_vocab_16e6.txt format, gzip-compressed as it ships (.txt.gz) or plain
// text as tools/export/export_clip.py writes it beside the model (told apart by the gzip magic, not the name;
// at most 64 MiB decompressed). The first line is a header the reference skips unread; it must contain
// "#version" (OpenAI's reads '"bpe_simple_vocab_16e6.txt#version: 0.2'). Every further non-empty line is one
// merge "a b" in rank order. The vocabulary is implied: the 256 byte symbols, the same with "</w>" appended,
// one symbol per merge, then <|startoftext|> and <|endoftext|>. The reference tokenizer uses only the first
// 49152 - 256 - 2 = 48894 merges of the published file (vocabulary 49408): `max_merges` says how many to read
// (the contract's vocab_size - 514), so the same file gives the same ids.
//
// Encoding, as the reference (openai/CLIP simple_tokenizer.py; checked id for id against its output on the
// published vocabulary, clip_tokenizer_test.cpp):
//  1. clean-up, in the reference's order:
//     a. the parts of ftfy.fix_text that matter for captions: curly quotes straightened, full-width forms and
//        Latin ligatures to ASCII;
//     b. html.unescape twice: numeric references by the HTML5 rules, named ones for HTML 4's entities,
//        &apos; and HTML5's names of ASCII characters (legacy names also without ';');
//     c. whitespace: the ends stripped (Python's str.isspace), every run of \s (Unicode White_Space, which
//        unlike str.isspace lacks U+001C..U+001F) to one space, stripped again;
//     d. Python's str.lower: the full Unicode simple mapping, U+0130 to "i" + U+0307, capital sigma to final
//        sigma at a word's end (the "cased" / "case-ignorable" context is approximated; clip_tokenizer.cpp).
//  2. pre-tokenisation by the reference pattern (compiled with re.IGNORECASE), hand-written (std::regex has
//     no \p{L}):
//       <|startoftext|> | <|endoftext|> | 's | 't | 're | 've | 'm | 'll | 'd | \p{L}+ | \p{N} | [^\s\p{L}\p{N}]+
//     tried in that order at each position; whitespace between pieces is dropped. \p{L} and \p{N} are tables
//     generated from the Unicode database (15.1), so every script is classed as the reference classes it.
//     IGNORECASE's two effects on lower-cased text are kept: U+017F (long s) matches the pattern's "s", and
//     U+0345 matches no alternative, so it is dropped.
//  3. each piece's UTF-8 bytes become printable symbols (the reference byte -> unicode map), the last one gets
//     "</w>", and adjacent symbol pairs merge lowest rank first until no pair has a rank (cached per piece).
// Not reproduced: the Unicode normalisation (NFC) that ftfy ends with, so decomposed text ("e" + U+0301)
// gives other ids than its composed form would (the reference composes it to U+00E9); ftfy's mojibake repair,
// control-character removal and its own HTML unescaping before quotes are uncurled ("&rsquo;" stays a curly
// quote); HTML5's other ~1,800 entity names (&NotNestedGreaterGreater;), which stay as written.
// Tokenize() wraps the ids in <|startoftext|> ... <|endoftext|>, truncates to the context length keeping
// <|endoftext|> as the last id (what clip.tokenize(truncate=True) and open_clip do), and pads with 0.
#include <cstdint>
#include <filesystem>
#include <string>
#include <unordered_map>
#include <vector>

namespace sd::models {

class ClipTokenizer {
 public:
  // Reads the merges file (plain or gzip); InputError naming it when it is missing, corrupt gzip, over 64 MiB
  // decompressed, has no header, a malformed merge line, or fewer merges than `max_merges` (-1: all lines).
  static ClipTokenizer Load(const std::filesystem::path& merges_file, int max_merges = -1);

  // BPE ids of `text` without start / end tokens. Not safe to call concurrently on one tokenizer (the
  // per-piece cache is filled as it goes).
  std::vector<int> Encode(const std::string& text) const;
  // [start, Encode(text)..., end] truncated to `context_length` (the last id stays the end token) and padded
  // with 0 to exactly `context_length` ids.
  std::vector<int> Tokenize(const std::string& text, int context_length = 77) const;
  // Text of ids: "</w>" becomes a space (a trailing one is dropped), the start token is skipped, decoding
  // stops at the end token (so padding after it is ignored).
  std::string Decode(const std::vector<int>& ids) const;

  int vocab_size() const { return static_cast<int>(symbols_.size()); }
  int start_token() const { return vocab_size() - 2; }
  int end_token() const { return vocab_size() - 1; }

 private:
  ClipTokenizer() = default;
  const std::vector<std::string>& Bpe(const std::string& piece) const;

  std::vector<std::string> symbols_;                  // id -> symbol (UTF-8 of the byte-mapped characters)
  std::unordered_map<std::string, int> ids_;          // symbol -> id
  std::unordered_map<std::string, int> merge_ranks_;  // "a b" -> rank
  std::vector<std::string> byte_symbol_;              // byte -> its printable symbol (UTF-8)
  std::unordered_map<std::string, int> symbol_byte_;  // inverse
  mutable std::unordered_map<std::string, std::vector<std::string>> cache_;
};

}  // namespace sd::models
