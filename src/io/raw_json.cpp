#include "io/raw_json.h"

#include <algorithm>
#include <cstring>

#include "core/error.h"

namespace sd {

Span RawJson::Root() const {
  const size_t b = SkipWs(0);
  return {b, ValueEnd(b)};
}

std::vector<Span> RawJson::Elements(Span arr) const {
  if (!IsArray(arr)) Fail(arr.begin, "expected an array");
  std::vector<Span> out;
  size_t i = SkipWs(arr.begin + 1);
  if (text_[i] == ']') return out;
  for (;;) {
    const size_t e = ValueEnd(i);
    out.push_back({i, e});
    i = SkipWs(e);
    if (text_[i] == ']') return out;
    if (text_[i] != ',') Fail(i, "expected ',' or ']'");
    i = SkipWs(i + 1);
  }
}

std::vector<RawMember> RawJson::Members(Span obj) const {
  if (!IsObject(obj)) Fail(obj.begin, "expected an object");
  std::vector<RawMember> out;
  size_t i = SkipWs(obj.begin + 1);
  if (text_[i] == '}') return out;
  for (;;) {
    if (text_[i] != '"') Fail(i, "expected a key");
    const size_t key_end = ValueEnd(i);
    RawMember m;
    const nlohmann::json key = nlohmann::json::parse(Text({i, key_end}), nullptr, false);
    if (!key.is_string()) Fail(i, "malformed key");
    m.key = key.get<std::string>();
    size_t v = SkipWs(key_end);
    if (text_[v] != ':') Fail(v, "expected ':'");
    v = SkipWs(v + 1);
    m.value = {v, ValueEnd(v)};
    m.item = {i, m.value.end};
    i = SkipWs(m.value.end);
    out.push_back(std::move(m));
    if (text_[i] == '}') return out;
    if (text_[i] != ',') Fail(i, "expected ',' or '}'");
    i = SkipWs(i + 1);
  }
}

std::optional<RawMember> RawJson::Member(Span obj, const std::string& key) const {
  for (RawMember& m : Members(obj))
    if (m.key == key) return m;
  return std::nullopt;
}

std::string RawJson::LineIndent(size_t pos) const {
  pos = std::min(pos, text_.size());
  size_t start = text_.rfind('\n', pos == 0 ? 0 : pos - 1);
  start = start == std::string::npos ? 0 : start + 1;
  size_t e = start;
  while (e < text_.size() && (text_[e] == ' ' || text_[e] == '\t')) ++e;
  return text_.substr(start, e - start);
}

JsonStyle RawJson::Style() const {
  JsonStyle s;
  const Span root = Root();
  if (!IsArray(root) && !IsObject(root)) return s;
  const size_t first = SkipWs(root.begin + 1);
  if (text_.substr(root.begin + 1, first - root.begin - 1).find('\n') != std::string::npos) s.unit = LineIndent(first);
  bool have_key_sep = false, have_item_sep = false;
  Span c = root;
  for (int depth = 0; depth < 64 && (IsArray(c) || IsObject(c)) && !(have_key_sep && have_item_sep); ++depth) {
    std::vector<Span> items, children;
    if (IsArray(c)) {
      items = children = Elements(c);
    } else {
      for (const RawMember& m : Members(c)) items.push_back(m.item), children.push_back(m.value);
      if (!items.empty() && !have_key_sep) {
        const size_t key_end = ValueEnd(items[0].begin);
        s.key_sep = text_.substr(key_end, children[0].begin - key_end);
        have_key_sep = true;
      }
    }
    if (items.size() >= 2 && !have_item_sep) {
      s.item_sep = text_.substr(items[0].end, items[1].begin - items[0].end);
      have_item_sep = true;
    }
    if (children.empty()) break;
    c = children[0];
  }
  if (!s.unit.empty()) s.item_sep = ",";
  return s;
}

size_t RawJson::SkipWs(size_t i) const {
  while (i < text_.size() && (text_[i] == ' ' || text_[i] == '\t' || text_[i] == '\n' || text_[i] == '\r')) ++i;
  if (i >= text_.size()) Fail(i, "unexpected end of file");
  return i;
}

// One pass over the value starting at `i`; containers are matched by counting (no recursion), so nesting depth
// costs nothing.
size_t RawJson::ValueEnd(size_t i) const {
  if (i >= text_.size()) Fail(i, "unexpected end of file");
  const char c = text_[i];
  auto string_end = [&](size_t k) {
    for (++k; k < text_.size(); ++k) {
      if (text_[k] == '\\') ++k;
      else if (text_[k] == '"') return k + 1;
    }
    Fail(k, "unterminated string");
  };
  if (c == '"') return string_end(i);
  if (c == '{' || c == '[') {
    size_t depth = 0;
    for (; i < text_.size(); ++i) {
      const char d = text_[i];
      if (d == '"') i = string_end(i) - 1;
      else if (d == '{' || d == '[') ++depth;
      else if ((d == '}' || d == ']') && --depth == 0) return i + 1;
    }
    Fail(i, "unterminated container");
  }
  size_t e = i;
  while (e < text_.size() && !std::strchr(",]} \t\r\n", text_[e])) ++e;
  if (e == i) Fail(i, "expected a value");
  return e;
}

void RawJson::Fail(size_t pos, const std::string& what) const {
  throw InputError(file_, Msg() << "byte " << pos << ": " << what);
}

std::string Serialize(const ojson& v, const JsonStyle& s, const std::string& indent) {
  if (!v.is_structured() || v.empty()) return v.dump();
  const bool array = v.is_array();
  const std::string inner = indent + s.unit;
  std::string out(1, array ? '[' : '{');
  bool first = true;
  for (auto it = v.begin(); it != v.end(); ++it) {
    if (!first) out += s.unit.empty() ? s.item_sep : ",";
    first = false;
    if (!s.unit.empty()) out += "\n" + inner;
    if (!array) out += ojson(it.key()).dump() + s.key_sep;
    out += Serialize(it.value(), s, inner);
  }
  if (!s.unit.empty()) out += "\n" + indent;
  out += array ? ']' : '}';
  return out;
}

ojson ArrayOf(const Items& items) {
  ojson a = ojson::array();
  for (const auto& kv : items) a.push_back(kv.second);
  return a;
}
ojson ObjectOf(const Items& items) {
  ojson o = ojson::object();
  for (const auto& [k, v] : items) o[k] = v;
  return o;
}

Splice AppendItems(const RawJson& j, Span c, const Items& items, const JsonStyle& s) {
  const bool array = j.IsArray(c);
  std::vector<Span> have;
  if (array) have = j.Elements(c);
  else
    for (const RawMember& m : j.Members(c)) have.push_back(m.item);
  auto item_text = [&](const std::pair<std::string, ojson>& kv, const std::string& indent) {
    return (array ? std::string() : ojson(kv.first).dump() + s.key_sep) + Serialize(kv.second, s, indent);
  };
  std::string text;
  if (!have.empty()) {
    const std::string lead(j.Text({c.begin + 1, have[0].begin}));
    std::string sep = have.size() >= 2 ? std::string(j.Text({have[0].end, have[1].begin}))
                      : lead.find('\n') != std::string::npos ? "," + lead
                      : s.unit.empty() ? s.item_sep : ",";
    const size_t nl = sep.rfind('\n');
    const std::string indent = nl == std::string::npos ? j.LineIndent(have.back().begin) : sep.substr(nl + 1);
    for (const auto& kv : items) text += sep + item_text(kv, indent);
    return {have.back().end, have.back().end, text};
  }
  if (items.empty()) return {c.end, c.end, ""};
  const std::string outer = j.LineIndent(c.begin), inner = outer + s.unit;
  for (size_t k = 0; k < items.size(); ++k) {
    if (k) text += s.unit.empty() ? s.item_sep : ",";
    if (!s.unit.empty()) text += "\n" + inner;
    text += item_text(items[k], inner);
  }
  if (!s.unit.empty()) text += "\n" + outer;
  return {c.begin + 1, c.end - 1, text};
}

void ExtendMember(const RawJson& j, Span obj, const std::string& key, const Items& items, bool as_object, const JsonStyle& s,
                  std::vector<Splice>* splices, Items* new_members) {
  if (items.empty()) return;
  const std::optional<RawMember> m = j.Member(obj, key);
  const ojson value = as_object ? ObjectOf(items) : ArrayOf(items);
  if (!m) {
    new_members->push_back({key, value});
  } else if (as_object ? j.IsObject(m->value) : j.IsArray(m->value)) {
    splices->push_back(AppendItems(j, m->value, items, s));
  } else {
    splices->push_back({m->value.begin, m->value.end, Serialize(value, s, j.LineIndent(m->item.begin))});
  }
}

std::string ApplySplices(const RawJson& j, Span within, std::vector<Splice> splices) {
  std::stable_sort(splices.begin(), splices.end(), [](const Splice& a, const Splice& b) { return a.begin < b.begin; });
  std::string out;
  size_t at = within.begin;
  for (const Splice& s : splices) {
    SD_CHECK(s.begin >= at && s.end >= s.begin && s.end <= within.end, << "overlapping splice at " << s.begin);
    out += j.Text({at, s.begin});
    out += s.text;
    at = s.end;
  }
  out += j.Text({at, within.end});
  return out;
}

std::string ArrayWith(const RawJson& j, Span arr, const std::vector<Span>& elements, const std::vector<std::string>& keep,
                      const JsonStyle& s) {
  if (keep.empty() || elements.empty()) return "[]";
  const std::string lead(j.Text({arr.begin + 1, elements[0].begin}));
  const std::string trail(j.Text({elements.back().end, arr.end - 1}));
  const std::string sep = elements.size() >= 2 ? std::string(j.Text({elements[0].end, elements[1].begin}))
                          : lead.find('\n') != std::string::npos ? "," + lead
                          : s.unit.empty() ? s.item_sep : ",";
  std::string out = "[" + lead;
  for (size_t k = 0; k < keep.size(); ++k) out += (k ? sep : "") + keep[k];
  return out + trail + "]";
}

}  // namespace sd
