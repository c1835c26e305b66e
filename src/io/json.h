#pragma once
// JSON helpers: reading with located errors (the file and the JSON path of the bad value).
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace sd {

// JSON nested deeper than this is refused (no dataset, scenario or asset record comes near it).
inline constexpr int kMaxJsonDepth = 512;
// Parses JSON text; InputError naming `where` for malformed text, a leading UTF-8 byte-order mark, a number out of
// range (1e999) or nesting deeper than kMaxJsonDepth.
nlohmann::json ParseJsonText(std::string_view text, const std::filesystem::path& where);
// InputError naming `where` when `text` nests deeper than kMaxJsonDepth; for JSON another library parses
// recursively (glTF through tinygltf), before it overflows the stack.
void CheckJsonNesting(std::string_view text, const std::filesystem::path& where);
// Parses a JSON file; throws InputError naming the file and the parse error position.
nlohmann::json ReadJsonFile(const std::filesystem::path& path);
// A JSON Lines file (one value per line, blank lines skipped): calls fn(value, "<file>:<line>") in order, so
// the caller's own errors can name the line too. InputError naming file and line for a line that is not JSON.
void ForEachJsonLine(const std::filesystem::path& path,
                     const std::function<void(const nlohmann::json& value, const std::string& where)>& fn);
// Writes `j` atomically (temporary file + rename). indent < 0 writes compactly.
void WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& j, int indent = 2);

// Typed access that throws InputError("<file>: <json path>: <problem>") instead of nlohmann's messages.
class JsonReader {
 public:
  JsonReader(const nlohmann::json& j, std::filesystem::path file, std::string json_path = "")
      : j_(j), file_(std::move(file)), path_(std::move(json_path)) {}
  JsonReader operator[](const std::string& key) const;  // required member
  JsonReader operator[](size_t index) const;            // required element
  bool Has(const std::string& key) const { return j_.is_object() && j_.contains(key) && !j_.at(key).is_null(); }
  size_t Size() const;                                   // array size (throws if not an array)
  double Number() const;
  double NumberOr(const std::string& key, double fallback) const;
  int64_t Integer() const;
  // An integer within [lo, hi] (a JSON float holding a whole number counts); InputError naming the bound otherwise,
  // so a caller can narrow it to int without an overflowing cast.
  int64_t IntegerIn(int64_t lo, int64_t hi) const;
  std::string String() const;
  std::string StringOr(const std::string& key, const std::string& fallback) const;
  bool Bool() const;
  const nlohmann::json& raw() const { return j_; }
  const std::filesystem::path& file() const { return file_; }
  const std::string& json_path() const { return path_; }
  [[noreturn]] void Fail(const std::string& problem) const;

 private:
  const nlohmann::json& j_;
  std::filesystem::path file_;
  std::string path_;
};

}  // namespace sd
