#include "models/clip_tokenizer.h"

#include <algorithm>
#include <fstream>
#include <limits>
#include <sstream>

#include "core/error.h"

namespace sd::models {

namespace {

constexpr const char* kStartOfText = "<|startoftext|>";
constexpr const char* kEndOfText = "<|endoftext|>";
constexpr const char* kEndOfWord = "</w>";

void AppendUtf8(char32_t cp, std::string* out) {
  if (cp < 0x80) {
    out->push_back(static_cast<char>(cp));
  } else if (cp < 0x800) {
    out->push_back(static_cast<char>(0xC0 | (cp >> 6)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else if (cp < 0x10000) {
    out->push_back(static_cast<char>(0xE0 | (cp >> 12)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else {
    out->push_back(static_cast<char>(0xF0 | (cp >> 18)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  }
}

// Code points of UTF-8 text; a byte that does not start a valid sequence becomes U+FFFD, as Python's
// errors="replace" would make of it (the reference only ever sees valid str).
std::u32string DecodeUtf8(const std::string& s) {
  std::u32string out;
  size_t i = 0;
  while (i < s.size()) {
    const auto b = static_cast<unsigned char>(s[i]);
    int len = b < 0x80 ? 1 : (b >> 5) == 0x6 ? 2 : (b >> 4) == 0xE ? 3 : (b >> 3) == 0x1E ? 4 : 0;
    char32_t cp = len == 1 ? b : len == 2 ? (b & 0x1F) : len == 3 ? (b & 0x0F) : (b & 0x07);
    bool ok = len > 0 && i + len <= s.size();
    for (int k = 1; ok && k < len; ++k) {
      const auto c = static_cast<unsigned char>(s[i + k]);
      if ((c >> 6) != 0x2) ok = false;
      cp = (cp << 6) | (c & 0x3F);
    }
    if (!ok) {
      out.push_back(0xFFFD);
      ++i;
    } else {
      out.push_back(cp);
      i += len;
    }
  }
  return out;
}

std::string EncodeUtf8(const std::u32string& s) {
  std::string out;
  for (char32_t cp : s) AppendUtf8(cp, &out);
  return out;
}

struct Range {
  char32_t lo, hi;
};

bool InRanges(char32_t cp, const Range* ranges, size_t n) {
  for (size_t i = 0; i < n; ++i)
    if (cp >= ranges[i].lo && cp <= ranges[i].hi) return true;
  return false;
}

// Python's str.isspace (what the reference's \s matches).
bool IsSpace(char32_t cp) {
  static constexpr Range kSpace[] = {{0x09, 0x0D}, {0x1C, 0x20}, {0x85, 0x85},     {0xA0, 0xA0},
                                     {0x1680, 0x1680}, {0x2000, 0x200A}, {0x2028, 0x2029}, {0x202F, 0x202F},
                                     {0x205F, 0x205F}, {0x3000, 0x3000}};
  return InRanges(cp, kSpace, std::size(kSpace));
}

// \p{L}: the letter blocks of the scripts CLIP's training captions mostly use (Latin with its extensions,
// Greek, Cyrillic, Armenian, Hebrew, Arabic, Devanagari, Thai, Georgian, kana, CJK ideographs, Hangul,
// full-width Latin). Marks, modifier letters and rarer scripts fall into the punctuation class instead.
bool IsLetter(char32_t cp) {
  static constexpr Range kLetter[] = {
      {'A', 'Z'},       {'a', 'z'},       {0xAA, 0xAA},     {0xB5, 0xB5},     {0xBA, 0xBA},     {0xC0, 0xD6},
      {0xD8, 0xF6},     {0xF8, 0x2C1},    {0x370, 0x374},   {0x376, 0x377},   {0x37B, 0x37D},   {0x37F, 0x37F},
      {0x386, 0x386},   {0x388, 0x3F5},   {0x3F7, 0x481},   {0x48A, 0x52F},   {0x531, 0x556},   {0x561, 0x587},
      {0x5D0, 0x5EA},   {0x620, 0x64A},   {0x671, 0x6D3},   {0x904, 0x939},   {0xE01, 0xE30},   {0x10A0, 0x10FF},
      {0x1E00, 0x1FBC}, {0x3041, 0x3096}, {0x30A1, 0x30FA}, {0x3400, 0x4DBF}, {0x4E00, 0x9FFF}, {0xAC00, 0xD7A3},
      {0xF900, 0xFAFF}, {0xFF21, 0xFF3A}, {0xFF41, 0xFF5A}, {0xFF66, 0xFF9D}};
  return InRanges(cp, kLetter, std::size(kLetter));
}

// \p{N}: decimal digits of the same scripts, superscripts, subscripts, vulgar fractions, number forms,
// circled numbers.
bool IsNumber(char32_t cp) {
  static constexpr Range kNumber[] = {{'0', '9'},       {0xB2, 0xB3},     {0xB9, 0xB9},     {0xBC, 0xBE},
                                      {0x660, 0x669},   {0x6F0, 0x6F9},   {0x966, 0x96F},   {0xE50, 0xE59},
                                      {0x2070, 0x2070}, {0x2074, 0x2079}, {0x2080, 0x2089}, {0x2150, 0x2189},
                                      {0x2460, 0x249B}, {0x3007, 0x3007}, {0x3021, 0x3029}, {0xFF10, 0xFF19}};
  return InRanges(cp, kNumber, std::size(kNumber));
}

// Lower case for the scripts whose case mapping is a fixed offset or alternating pairs.
char32_t ToLower(char32_t cp) {
  if (cp >= 'A' && cp <= 'Z') return cp + 32;
  if (cp < 0xC0) return cp;
  if (cp <= 0xDE) return cp == 0xD7 ? cp : cp + 32;
  if (cp >= 0x100 && cp <= 0x137 && cp != 0x130) return cp | 1;                  // pairs: even upper, odd lower
  if (cp >= 0x139 && cp <= 0x148) return (cp & 1) ? cp + 1 : cp;                 // odd upper
  if (cp >= 0x14A && cp <= 0x177) return cp | 1;
  if (cp == 0x178) return 0xFF;
  if (cp >= 0x179 && cp <= 0x17E) return (cp & 1) ? cp + 1 : cp;
  if (cp == 0x386) return 0x3AC;
  if (cp >= 0x388 && cp <= 0x38A) return cp + 37;
  if (cp == 0x38C) return 0x3CC;
  if (cp >= 0x38E && cp <= 0x38F) return cp + 63;
  if (cp >= 0x391 && cp <= 0x3AB && cp != 0x3A2) return cp + 32;
  if (cp >= 0x400 && cp <= 0x40F) return cp + 80;
  if (cp >= 0x410 && cp <= 0x42F) return cp + 32;
  if ((cp >= 0x460 && cp <= 0x481) || (cp >= 0x48A && cp <= 0x4BF)) return cp | 1;
  return cp;
}

// The parts of ftfy.fix_text's defaults (which the reference runs first) that change common captions:
// curly quotes become straight ones, full-width forms their ASCII letters, Latin ligatures their letters.
// (Its mojibake repair and NFC normalisation are not reproduced.)
std::u32string FixText(const std::u32string& text) {
  std::u32string out;
  for (char32_t cp : text) {
    if (cp >= 0x2018 && cp <= 0x201B) out.push_back(U'\'');
    else if (cp >= 0x201C && cp <= 0x201F) out.push_back(U'"');
    else if (cp >= 0xFF01 && cp <= 0xFF5E) out.push_back(cp - 0xFF01 + 0x21);
    else if (cp == 0x3000) out.push_back(U' ');
    else if (cp == 0xFB00) out += U"ff";
    else if (cp == 0xFB01) out += U"fi";
    else if (cp == 0xFB02) out += U"fl";
    else if (cp == 0xFB03) out += U"ffi";
    else if (cp == 0xFB04) out += U"ffl";
    else out.push_back(cp);
  }
  return out;
}

// Whitespace runs -> one space, trimmed, lower-cased.
std::u32string Clean(const std::string& text) {
  std::u32string out;
  bool pending_space = false;
  for (char32_t cp : FixText(DecodeUtf8(text))) {
    if (IsSpace(cp)) {
      pending_space = !out.empty();
      continue;
    }
    if (pending_space) out.push_back(U' ');
    pending_space = false;
    out.push_back(ToLower(cp));
  }
  return out;
}

bool StartsWith(const std::u32string& s, size_t at, const char* ascii) {
  for (size_t k = 0; ascii[k]; ++k)
    if (at + k >= s.size() || s[at + k] != static_cast<char32_t>(static_cast<unsigned char>(ascii[k]))) return false;
  return true;
}

// The reference pattern's pieces, leftmost alternative first at each position (see the header).
std::vector<std::string> PreTokenize(const std::u32string& text) {
  std::vector<std::string> pieces;
  size_t i = 0;
  const auto is_other = [](char32_t c) { return !IsSpace(c) && !IsLetter(c) && !IsNumber(c); };
  while (i < text.size()) {
    size_t len = 0;
    if (StartsWith(text, i, kStartOfText)) {
      len = std::char_traits<char>::length(kStartOfText);
    } else if (StartsWith(text, i, kEndOfText)) {
      len = std::char_traits<char>::length(kEndOfText);
    } else if (text[i] == U'\'' && (StartsWith(text, i, "'re") || StartsWith(text, i, "'ve") ||
                                     StartsWith(text, i, "'ll"))) {
      len = 3;
    } else if (text[i] == U'\'' && (StartsWith(text, i, "'s") || StartsWith(text, i, "'t") ||
                                     StartsWith(text, i, "'m") || StartsWith(text, i, "'d"))) {
      len = 2;
    } else if (IsLetter(text[i])) {
      while (i + len < text.size() && IsLetter(text[i + len])) ++len;
    } else if (IsNumber(text[i])) {
      len = 1;
    } else if (is_other(text[i])) {
      while (i + len < text.size() && is_other(text[i + len])) ++len;
    }
    if (len == 0) {  // whitespace: between pieces, dropped
      ++i;
      continue;
    }
    pieces.push_back(EncodeUtf8(text.substr(i, len)));
    i += len;
  }
  return pieces;
}

}  // namespace

ClipTokenizer ClipTokenizer::Load(const std::filesystem::path& merges_file, int max_merges) {
  std::ifstream in(merges_file, std::ios::binary);
  if (!in) throw InputError(merges_file, "cannot read the CLIP BPE merges file (tools/export/export_clip.py writes it)");
  ClipTokenizer t;
  // The reference byte -> unicode map: printable Latin-1 bytes stand for themselves, the other 68 bytes
  // (controls, space, DEL, no-break space, soft hyphen) take code points 256, 257, ... in byte order, so every
  // byte is a visible character and BPE never has to split on whitespace.
  std::vector<int> order;
  for (int b = '!'; b <= '~'; ++b) order.push_back(b);
  for (int b = 0xA1; b <= 0xAC; ++b) order.push_back(b);
  for (int b = 0xAE; b <= 0xFF; ++b) order.push_back(b);
  std::vector<char32_t> code(256, 0);
  std::vector<bool> printable(256, false);
  for (int b : order) {
    code[b] = static_cast<char32_t>(b);
    printable[b] = true;
  }
  char32_t next = 256;
  for (int b = 0; b < 256; ++b)
    if (!printable[b]) {
      code[b] = next++;
      order.push_back(b);
    }
  t.byte_symbol_.resize(256);
  for (int b = 0; b < 256; ++b) {
    AppendUtf8(code[b], &t.byte_symbol_[b]);
    t.symbol_byte_[t.byte_symbol_[b]] = b;
  }
  for (int b : order) t.symbols_.push_back(t.byte_symbol_[b]);
  for (int b : order) t.symbols_.push_back(t.byte_symbol_[b] + kEndOfWord);

  std::string line;
  if (!std::getline(in, line) || line.empty() || line[0] != '#')
    throw InputError(merges_file, "not a CLIP BPE merges file: the first line must be a '#version' header");
  int line_no = 1, rank = 0;
  while ((max_merges < 0 || rank < max_merges) && std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    std::istringstream fields(line);
    std::string a, b, extra;
    if (!(fields >> a >> b) || (fields >> extra))
      throw InputError(merges_file, Msg() << "line " << line_no << ": a merge is two symbols, found '" << line << "'");
    t.merge_ranks_.emplace(a + " " + b, rank++);
    t.symbols_.push_back(a + b);
  }
  if (max_merges >= 0 && rank < max_merges)
    throw InputError(merges_file, Msg() << "has " << rank << " merges, the model's vocabulary needs " << max_merges);
  t.symbols_.push_back(kStartOfText);
  t.symbols_.push_back(kEndOfText);
  for (size_t i = 0; i < t.symbols_.size(); ++i) t.ids_[t.symbols_[i]] = static_cast<int>(i);  // later wins, as the reference's dict
  t.cache_[kStartOfText] = {kStartOfText};
  t.cache_[kEndOfText] = {kEndOfText};
  return t;
}

// Sennrich et al.'s merge loop: repeatedly merge every occurrence (left to right, non-overlapping) of the
// adjacent pair with the lowest rank; stop when no adjacent pair is a known merge.
const std::vector<std::string>& ClipTokenizer::Bpe(const std::string& piece) const {
  if (const auto it = cache_.find(piece); it != cache_.end()) return it->second;
  std::vector<std::string> word;
  for (unsigned char b : piece) word.push_back(byte_symbol_[b]);
  word.back() += kEndOfWord;
  while (word.size() > 1) {
    int best = std::numeric_limits<int>::max();
    size_t best_at = 0;
    for (size_t i = 0; i + 1 < word.size(); ++i) {
      const auto it = merge_ranks_.find(word[i] + " " + word[i + 1]);
      if (it != merge_ranks_.end() && it->second < best) {
        best = it->second;
        best_at = i;
      }
    }
    if (best == std::numeric_limits<int>::max()) break;
    const std::string first = word[best_at], second = word[best_at + 1];
    std::vector<std::string> merged;
    for (size_t i = 0; i < word.size();) {
      if (i + 1 < word.size() && word[i] == first && word[i + 1] == second) {
        merged.push_back(first + second);
        i += 2;
      } else {
        merged.push_back(word[i++]);
      }
    }
    word = std::move(merged);
  }
  return cache_.emplace(piece, std::move(word)).first->second;
}

std::vector<int> ClipTokenizer::Encode(const std::string& text) const {
  std::vector<int> ids;
  for (const std::string& piece : PreTokenize(Clean(text)))
    for (const std::string& symbol : Bpe(piece)) {
      const auto it = ids_.find(symbol);
      SD_CHECK(it != ids_.end(), << "BPE produced '" << symbol << "', not in the vocabulary");
      ids.push_back(it->second);
    }
  return ids;
}

std::vector<int> ClipTokenizer::Tokenize(const std::string& text, int context_length) const {
  SD_CHECK(context_length >= 2, << context_length);
  std::vector<int> ids{start_token()};
  const std::vector<int> body = Encode(text);
  ids.insert(ids.end(), body.begin(), body.end());
  ids.push_back(end_token());
  if (static_cast<int>(ids.size()) > context_length) {
    ids.resize(static_cast<size_t>(context_length));
    ids.back() = end_token();
  }
  ids.resize(static_cast<size_t>(context_length), 0);
  return ids;
}

std::string ClipTokenizer::Decode(const std::vector<int>& ids) const {
  std::string out;
  for (int id : ids) {
    if (id == end_token()) break;
    if (id == start_token()) continue;
    SD_CHECK(id >= 0 && id < vocab_size(), << id);
    std::string symbol = symbols_[static_cast<size_t>(id)];
    const bool word_end = symbol.size() >= 4 && symbol.compare(symbol.size() - 4, 4, kEndOfWord) == 0;
    if (word_end) symbol.resize(symbol.size() - 4);
    std::string one;
    for (char32_t cp : DecodeUtf8(symbol)) {
      one.clear();
      AppendUtf8(cp, &one);
      const auto it = symbol_byte_.find(one);
      SD_CHECK(it != symbol_byte_.end(), << "symbol '" << symbol << "' of id " << id);
      out.push_back(static_cast<char>(it->second));
    }
    if (word_end) out.push_back(' ');
  }
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

}  // namespace sd::models
