#include "io/json.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include "core/error.h"
#include "io/files.h"

namespace sd {

void CheckJsonNesting(std::string_view text, const std::filesystem::path& where) {
  int depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxJsonDepth)
        throw InputError(where, Msg() << "malformed JSON: nested deeper than " << kMaxJsonDepth << " levels (at byte " << i << ")");
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
}

nlohmann::json ParseJsonText(std::string_view text, const std::filesystem::path& where) {
  // RFC 8259 forbids a byte-order mark, Python's json refuses one, and the info writer's splice cannot place
  // its additions after one: said here, not as "data_list is not an array" after the frames were rendered.
  if (text.starts_with("\xEF\xBB\xBF"))
    throw InputError(where, "malformed JSON: starts with a UTF-8 byte-order mark (JSON forbids it; save the file without a BOM)");
  // Nesting first: nothing downstream is written for 100,000-deep lists (a scenario comment holding them parsed,
  // then overflowed the stack when synth.json was written).
  CheckJsonNesting(text, where);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    // nlohmann's message starts with "[json.exception.parse_error.101] parse error at line 3, column 5: ..." (or
    // out_of_range.406 for a number such as 1e999): the file is named, the library's tag is not.
    std::string what = e.what();
    const auto pos = what.find("] ");
    throw InputError(where, "malformed JSON: " + (pos == std::string::npos ? what : what.substr(pos + 2)));
  }
}

nlohmann::json ReadJsonFile(const std::filesystem::path& path) { return ParseJsonText(ReadFileToString(path), path); }

void ForEachJsonLine(const std::filesystem::path& path,
                     const std::function<void(const nlohmann::json& value, const std::string& where)>& fn) {
  std::istringstream lines(ReadFileToString(path));
  std::string line;
  for (int n = 1; std::getline(lines, line); ++n) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const std::string where = path.string() + ":" + std::to_string(n);
    fn(ParseJsonText(line, where), where);
  }
}

void WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& j, int indent) {
  WriteFileAtomic(path, j.dump(indent) + "\n");
}

void JsonReader::Fail(const std::string& problem) const {
  throw InputError(file_, (path_.empty() ? std::string("(root)") : path_) + ": " + problem);
}

JsonReader JsonReader::operator[](const std::string& key) const {
  if (!j_.is_object()) Fail("expected an object");
  auto it = j_.find(key);
  if (it == j_.end()) Fail("missing required field '" + key + "'");
  return JsonReader(*it, file_, path_ + "." + key);
}

JsonReader JsonReader::operator[](size_t index) const {
  if (!j_.is_array()) Fail("expected an array");
  if (index >= j_.size()) Fail(Msg() << "index " << index << " out of range (size " << j_.size() << ")");
  return JsonReader(j_[index], file_, path_ + "[" + std::to_string(index) + "]");
}

size_t JsonReader::Size() const {
  if (!j_.is_array()) Fail("expected an array");
  return j_.size();
}

double JsonReader::Number() const {
  if (!j_.is_number()) Fail(std::string("expected a number, found ") + j_.type_name());
  return j_.get<double>();
}

double JsonReader::NumberOr(const std::string& key, double fallback) const {
  return Has(key) ? (*this)[key].Number() : fallback;
}

int64_t JsonReader::Integer() const {
  if (j_.is_number_unsigned() && j_.get<uint64_t>() > static_cast<uint64_t>(std::numeric_limits<int64_t>::max()))
    Fail("integer " + j_.dump() + " is out of range");
  if (!j_.is_number_integer()) {
    // Range first: casting a double outside int64's range is undefined behaviour, not a wrapped value.
    if (j_.is_number_float()) {
      const double v = j_.get<double>();
      if (std::abs(v) < 9.2e18 && v == std::trunc(v)) return static_cast<int64_t>(v);
    }
    Fail(std::string("expected an integer, found ") + (j_.is_number_float() ? j_.dump() : j_.type_name()));
  }
  return j_.get<int64_t>();
}

int64_t JsonReader::IntegerIn(int64_t lo, int64_t hi) const {
  const int64_t v = Integer();
  if (v < lo || v > hi) Fail(Msg() << "integer " << v << " outside [" << lo << ", " << hi << "]");
  return v;
}

std::string JsonReader::String() const {
  if (!j_.is_string()) Fail(std::string("expected a string, found ") + j_.type_name());
  return j_.get<std::string>();
}

std::string JsonReader::StringOr(const std::string& key, const std::string& fallback) const {
  return Has(key) ? (*this)[key].String() : fallback;
}

bool JsonReader::Bool() const {
  if (!j_.is_boolean()) Fail(std::string("expected true/false, found ") + j_.type_name());
  return j_.get<bool>();
}

}  // namespace sd
