#pragma once
// CLIP's byte-level BPE tokenizer (Radford et al. 2021), written from the published algorithm, so that text
// queries become the exact token ids the "clip_text" model was trained on.
//
// Vocabulary file: OpenAI's bpe_simple_vocab_16e6.txt format (what tools/export/export_clip.py writes beside
// the model, uncompressed): the first line is a header ("#version: ..."), every further non-empty line one
// merge "a b" in rank order. The vocabulary is implied: the 256 byte symbols, the same with "</w>" appended,
// one symbol per merge, then <|startoftext|> and <|endoftext|>. The reference tokenizer uses only the first
// 49152 - 256 - 2 = 48894 merges of the published file (vocabulary 49408): `max_merges` says how many to read
// (the contract's vocab_size - 514), so the same file gives the same ids.
//
// Encoding, as the reference:
//  1. clean-up: curly quotes straightened, full-width forms and Latin ligatures to ASCII (the parts of the
//     reference's ftfy.fix_text that matter for captions; not its mojibake repair, NFC normalisation or HTML
//     unescaping), runs of whitespace to one space, ends trimmed, lower-cased (ASCII, Latin-1, Latin
//     Extended-A, Greek and Cyrillic; other scripts pass unchanged).
//  2. pre-tokenisation by the reference pattern, hand-written (std::regex has no \p{L}):
//       <|startoftext|> | <|endoftext|> | 's | 't | 're | 've | 'm | 'll | 'd | \p{L}+ | \p{N} | [^\s\p{L}\p{N}]+
//     tried in that order at each position; whitespace between pieces is dropped. The letter / number classes
//     are a table of the main Unicode ranges (documented in clip_tokenizer.cpp), not the full database.
//  3. each piece's UTF-8 bytes become printable symbols (the reference byte -> unicode map), the last one gets
//     "</w>", and adjacent symbol pairs merge lowest rank first until no pair has a rank (cached per piece).
// Tokenize() wraps the ids in <|startoftext|> ... <|endoftext|>, truncates to the context length keeping
// <|endoftext|> as the last id (what open_clip does), and pads with 0.
#include <cstdint>
#include <filesystem>
#include <string>
#include <unordered_map>
#include <vector>

namespace sd::models {

class ClipTokenizer {
 public:
  // Reads the merges file; InputError naming it when it is missing, has no header, a malformed merge line,
  // or fewer merges than `max_merges` (-1: all lines).
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
