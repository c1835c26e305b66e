#pragma once
// JSON edited as text. A derivative dataset's annotation files are the input's text with records spliced in:
// untouched records (other frames, other tables, every field an edit does not extend) keep the bytes they had.
// Re-serialising parsed JSON would not: nlohmann sorts keys, formats numbers and whitespace its own way and
// turns Python's NaN into null. Added records are laid out like their neighbours (JsonStyle).
//
// The scanner walks the text of one value without building a tree. It is safe on any input (bounded work,
// every access checked; a malformed text is an InputError naming the file and the byte), but it checks only
// the structure it walks: validate the file with a real parser (ReadJsonFile) before editing it.
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace sd {

struct Span {
  size_t begin = 0, end = 0;  // [begin, end) in the file text
};

struct RawMember {
  std::string key;
  Span item;   // from the key's opening quote to the value's end
  Span value;
};

struct Splice {
  size_t begin = 0, end = 0;  // replaced range (empty: insertion)
  std::string text;
};

// How a file lays out its containers, so added records look like their neighbours: `unit` is one level of
// indentation ("" for one-line files such as Lyft's tables), separators as the file writes them.
struct JsonStyle {
  std::string unit;
  std::string item_sep = ", ";  // between items of a one-line container
  std::string key_sep = ": ";
};

class RawJson {
 public:
  RawJson(std::string text, std::filesystem::path file) : text_(std::move(text)), file_(std::move(file)) {}
  const std::string& text() const { return text_; }
  std::string_view Text(Span s) const { return std::string_view(text_).substr(s.begin, s.end - s.begin); }

  Span Root() const;  // the top-level value (surrounding whitespace excluded)
  bool IsArray(Span s) const { return s.end > s.begin && text_[s.begin] == '['; }
  bool IsObject(Span s) const { return s.end > s.begin && text_[s.begin] == '{'; }
  std::vector<Span> Elements(Span array) const;
  std::vector<RawMember> Members(Span object) const;
  std::optional<RawMember> Member(Span object, const std::string& key) const;  // the first member named `key`
  std::string LineIndent(size_t pos) const;  // the whitespace that starts the line holding `pos`
  JsonStyle Style() const;                   // the file's layout, read off its first containers

 private:
  size_t SkipWs(size_t i) const;
  size_t ValueEnd(size_t i) const;
  [[noreturn]] void Fail(size_t pos, const std::string& what) const;

  std::string text_;
  std::filesystem::path file_;
};

using ojson = nlohmann::ordered_json;                      // added records keep the dataset's field order
using Items = std::vector<std::pair<std::string, ojson>>;  // keys are ignored for arrays

// `v` as the file lays out its own values, starting on a line indented by `indent`. Numbers are nlohmann's
// shortest round-trip form; only added records are written this way.
std::string Serialize(const ojson& v, const JsonStyle& s, const std::string& indent);
ojson ArrayOf(const Items& items);
ojson ObjectOf(const Items& items);

// Appends `items` to the array or object `c`, separated and indented like the items already there.
Splice AppendItems(const RawJson& j, Span c, const Items& items, const JsonStyle& s);
// Adds `items` to the container `key` of object `obj`: appended when it is there, the value replaced when it is
// null or of another type, and the member created (in `new_members`, added to `obj` by the caller in one go)
// when it is missing. `as_object` picks the container type.
void ExtendMember(const RawJson& j, Span obj, const std::string& key, const Items& items, bool as_object,
                  const JsonStyle& s, std::vector<Splice>* splices, Items* new_members);
// The text of `within` with `splices` (absolute offsets inside it, non-overlapping) applied.
std::string ApplySplices(const RawJson& j, Span within, std::vector<Splice> splices);
// The array `arr` with only the elements `keep` (their text unchanged), in that order, laid out as before.
std::string ArrayWith(const RawJson& j, Span arr, const std::vector<Span>& elements, const std::vector<std::string>& keep,
                      const JsonStyle& s);

}  // namespace sd
