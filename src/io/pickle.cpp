#include "io/pickle.h"

#include <zlib.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "io/files.h"
#include "io/gzip.h"

namespace sd::pickle {
namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------------------------
// Value nodes

struct Value::Node {
  std::string text;                                  // kStr (UTF-8), kBytes
  std::vector<Value> elements;                       // kList, kTuple
  std::vector<std::pair<Value, Value>> entries;      // kDict, insertion order
  // kDict with at least kIndexFrom entries: key hash -> position in `entries` (kept in step by DictInsert).
  std::unique_ptr<std::unordered_multimap<uint64_t, uint32_t>> index;
  std::unique_ptr<Array> array;
  std::unique_ptr<Object> object;
  // Nesting height (a str or an empty list: 0 / 1). Exact for loaded trees, which the loader keeps <= max_depth.
  uint32_t height = 0;
  // Loader bookkeeping: `inserted` once the node is inside another value (from then on it may not change, which
  // keeps loaded trees acyclic); `pending` for an ndarray from _reconstruct that BUILD has not filled yet.
  bool inserted = false;
  bool pending = false;

  Node() = default;
  Node(const Node& o) : text(o.text), elements(o.elements), entries(o.entries), height(o.height) {
    if (o.index) index = std::make_unique<std::unordered_multimap<uint64_t, uint32_t>>(*o.index);
    if (o.array) array = std::make_unique<Array>(*o.array);
    if (o.object) object = std::make_unique<Object>(*o.object);
  }
  Node& operator=(const Node&) = delete;
};

// The loader's and writer's access to node internals.
struct Access {
  static Value Make(Kind kind) {
    Value v(kind);
    v.node_ = std::make_shared<Value::Node>();
    return v;
  }
  // The loader builds nodes in place (CPython semantics: the memo and the stack see one object).
  static Value::Node& NodeOf(const Value& v) { return *v.node_; }
  static Value::Node* NodePtr(const Value& v) { return v.node_.get(); }
  static long UseCount(const Value& v) { return v.node_.use_count(); }
};

namespace {

constexpr size_t kIndexFrom = 16;

uint32_t HeightOf(const Value& v) {
  const Value::Node* n = Access::NodePtr(v);
  return n ? n->height : 0;
}

[[noreturn]] void WrongKind(const Value& v, const char* wanted) {
  throw InputError({}, Msg() << "pickle value is a " << KindName(v.kind()) << ", not " << wanted);
}

// --- UTF-8 and the other text encodings pickles use

void AppendUtf8(std::string* out, uint32_t cp) {
  if (cp < 0x80) {
    out->push_back(static_cast<char>(cp));
  } else if (cp < 0x800) {
    out->push_back(static_cast<char>(0xc0 | (cp >> 6)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3f)));
  } else if (cp < 0x10000) {
    out->push_back(static_cast<char>(0xe0 | (cp >> 12)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3f)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3f)));
  } else {
    out->push_back(static_cast<char>(0xf0 | (cp >> 18)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3f)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3f)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3f)));
  }
}

bool IsScalarValue(uint32_t cp) { return cp <= 0x10ffff && (cp < 0xd800 || cp > 0xdfff); }

// Decodes one code point at s[*i]; false for invalid UTF-8 (overlong forms, surrogates, > U+10FFFF, truncated).
bool NextCodePoint(std::string_view s, size_t* i, uint32_t* cp) {
  const auto b = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = b(*i);
  int n;
  uint32_t v;
  if (c < 0x80) {
    *cp = c;
    ++*i;
    return true;
  } else if ((c & 0xe0) == 0xc0) {
    n = 1, v = c & 0x1f;
  } else if ((c & 0xf0) == 0xe0) {
    n = 2, v = c & 0x0f;
  } else if ((c & 0xf8) == 0xf0) {
    n = 3, v = c & 0x07;
  } else {
    return false;
  }
  if (*i + static_cast<size_t>(n) >= s.size()) return false;
  for (int k = 1; k <= n; ++k) {
    if ((b(*i + k) & 0xc0) != 0x80) return false;
    v = (v << 6) | (b(*i + k) & 0x3f);
  }
  static constexpr uint32_t kMin[] = {0, 0x80, 0x800, 0x10000};
  if (v < kMin[n] || !IsScalarValue(v)) return false;
  *cp = v;
  *i += n + 1;
  return true;
}

bool ValidUtf8(std::string_view s) {
  uint32_t cp;
  for (size_t i = 0; i < s.size();) {
    if (static_cast<unsigned char>(s[i]) < 0x80) {
      ++i;
      continue;
    }
    if (!NextCodePoint(s, &i, &cp)) return false;
  }
  return true;
}

std::string Utf8FromLatin1(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (unsigned char c : s) AppendUtf8(&out, c);
  return out;
}

// The latin-1 bytes of a str whose code points are all < 256 (how protocols < 3 carry bytes).
bool Latin1FromUtf8(std::string_view s, std::string* out) {
  out->clear();
  out->reserve(s.size());
  uint32_t cp;
  for (size_t i = 0; i < s.size();) {
    if (!NextCodePoint(s, &i, &cp) || cp > 0xff) return false;
    out->push_back(static_cast<char>(cp));
  }
  return true;
}

// --- dict keys: Python's equality and a hash consistent with it

bool IsNumericScalar(const Value& v) {
  if (v.kind() != Kind::kArray) return false;
  const Array& a = v.array();
  return a.ndim() == 0 && a.dtype != DType::kObject && a.dtype != DType::kUnicode;
}

bool IsStringLike(const Value& v) {
  return v.kind() == Kind::kStr ||
         (v.kind() == Kind::kArray && v.array().ndim() == 0 && v.array().dtype == DType::kUnicode);
}

// A number as Python compares it: an exact int64 when integral and in range, else a double.
struct Number {
  bool integral;
  int64_t i;
  double d;
};

bool AsNumber(const Value& v, Number* n) {
  double d;
  switch (v.kind()) {
    case Kind::kBool:
    case Kind::kInt:
      *n = {true, v.AsInt(), 0};
      return true;
    case Kind::kFloat:
      d = v.AsDouble();
      break;
    case Kind::kArray:
      if (!IsNumericScalar(v)) return false;
      if (IsInteger(v.array().dtype) || v.array().dtype == DType::kBool) {
        if (v.array().dtype != DType::kUInt64 || v.array().At<uint64_t>(0) <= uint64_t(INT64_MAX)) {
          *n = {true, v.array().AsInt(0), 0};
          return true;
        }
      }
      d = v.array().AsDouble(0);
      break;
    default:
      return false;
  }
  // 2^63 as a double is outside int64; -2^63 is inside.
  if (std::isfinite(d) && d == std::floor(d) && d >= -9223372036854775808.0 && d < 9223372036854775808.0) {
    *n = {true, static_cast<int64_t>(d), d};
  } else {
    *n = {false, 0, d};
  }
  return true;
}

bool Hashable(const Value& k) {
  switch (k.kind()) {
    case Kind::kList:
    case Kind::kDict:
      return false;
    case Kind::kArray:
      return k.array().scalar;  // numpy scalars hash, arrays (0-d ones too) do not
    case Kind::kTuple:
      for (const Value& e : k.elements())
        if (!Hashable(e)) return false;
      return true;
    default:
      return true;
  }
}

uint64_t Mix(uint64_t h, uint64_t v) { return (h ^ v) * 0x100000001b3ull + 0x9e3779b97f4a7c15ull; }

uint64_t KeyHash(const Value& k) {
  Number n;
  if (AsNumber(k, &n)) {
    if (n.integral) return Mix(1, static_cast<uint64_t>(n.i));
    uint64_t bits;
    std::memcpy(&bits, &n.d, 8);
    return Mix(2, bits);
  }
  if (IsStringLike(k)) return Mix(3, std::hash<std::string>()(k.AsString()));
  switch (k.kind()) {
    case Kind::kNone:
      return 4;
    case Kind::kBytes:
      return Mix(5, std::hash<std::string>()(k.AsBytes()));
    case Kind::kTuple: {
      uint64_t h = 6;
      for (const Value& e : k.elements()) h = Mix(h, KeyHash(e));
      return h;
    }
    default:  // objects: by identity
      return Mix(7, reinterpret_cast<uintptr_t>(k.identity()));
  }
}

bool KeyEquals(const Value& a, const Value& b) {
  Number x, y;
  const bool na = AsNumber(a, &x), nb = AsNumber(b, &y);
  if (na || nb) {
    if (!(na && nb)) return false;
    if (x.integral && y.integral) return x.i == y.i;
    if (x.integral != y.integral) return false;  // an integral value never equals a non-integral one
    return x.d == y.d;
  }
  const bool sa = IsStringLike(a), sb = IsStringLike(b);
  if (sa || sb) return sa && sb && a.AsString() == b.AsString();
  if (a.kind() != b.kind()) return false;
  switch (a.kind()) {
    case Kind::kNone:
      return true;
    case Kind::kBytes:
      return a.AsBytes() == b.AsBytes();
    case Kind::kTuple:
      if (a.size() != b.size()) return false;
      for (size_t i = 0; i < a.size(); ++i)
        if (!KeyEquals(a[i], b[i])) return false;
      return true;
    default:
      return a.identity() == b.identity();
  }
}

ptrdiff_t DictFind(const Value::Node& n, const Value& key) {
  if (n.index) {
    const auto [lo, hi] = n.index->equal_range(KeyHash(key));
    for (auto it = lo; it != hi; ++it)
      if (KeyEquals(n.entries[it->second].first, key)) return it->second;
    return -1;
  }
  for (size_t i = 0; i < n.entries.size(); ++i)
    if (KeyEquals(n.entries[i].first, key)) return static_cast<ptrdiff_t>(i);
  return -1;
}

// Python's d[key] = v: replaces the value of an equal key in place (keeping its position and first key object),
// else appends. The caller has checked that the key is hashable.
void DictInsert(Value::Node& n, Value key, Value v) {
  const ptrdiff_t at = DictFind(n, key);
  if (at >= 0) {
    n.entries[static_cast<size_t>(at)].second = std::move(v);
    return;
  }
  n.entries.emplace_back(std::move(key), std::move(v));
  if (n.index) {
    n.index->emplace(KeyHash(n.entries.back().first), static_cast<uint32_t>(n.entries.size() - 1));
  } else if (n.entries.size() >= kIndexFrom) {
    n.index = std::make_unique<std::unordered_multimap<uint64_t, uint32_t>>();
    for (size_t i = 0; i < n.entries.size(); ++i) n.index->emplace(KeyHash(n.entries[i].first), static_cast<uint32_t>(i));
  }
}

// --- float16 and byte order

double HalfToDouble(uint16_t h) {
  const int sign = h >> 15, exp = (h >> 10) & 0x1f, frac = h & 0x3ff;
  double v;
  if (exp == 0) v = std::ldexp(frac, -24);                                   // subnormal
  else if (exp == 31) v = frac ? std::numeric_limits<double>::quiet_NaN() : std::numeric_limits<double>::infinity();
  else v = std::ldexp(frac + 1024, exp - 25);
  return sign ? -v : v;
}

void SwapEach(std::string* data, int unit) {
  if (unit <= 1) return;
  for (size_t i = 0; i + unit <= data->size(); i += unit) std::reverse(data->begin() + i, data->begin() + i + unit);
}

// Python's repr(float): the shortest round-trip digits; positional for 1e-4 <= |x| < 1e16, else d.ddde+XX.
std::string PythonFloatRepr(double x) {
  if (std::isnan(x)) return "NaN";  // json.dump's spelling (repr says nan); only dict keys need this
  if (std::isinf(x)) return x > 0 ? "Infinity" : "-Infinity";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), x, std::chars_format::scientific);
  std::string sci(buf, r.ptr);  // e.g. "-1.2345e+02"
  const size_t e = sci.find('e');
  const int exp = std::stoi(sci.substr(e + 1));
  std::string sign;
  std::string mant = sci.substr(0, e);
  if (mant[0] == '-') sign = "-", mant.erase(0, 1);
  std::string digits;
  for (char c : mant)
    if (c != '.') digits.push_back(c);
  if (exp >= -4 && exp < 16) {
    std::string out;
    if (exp < 0) {
      out = "0." + std::string(static_cast<size_t>(-exp - 1), '0') + digits;
    } else if (static_cast<int>(digits.size()) <= exp + 1) {
      out = digits + std::string(static_cast<size_t>(exp + 1 - static_cast<int>(digits.size())), '0') + ".0";
    } else {
      out = digits.substr(0, static_cast<size_t>(exp + 1)) + "." + digits.substr(static_cast<size_t>(exp + 1));
    }
    return sign + out;
  }
  std::string out = digits.substr(0, 1);
  if (digits.size() > 1) out += "." + digits.substr(1);
  char ebuf[16];
  std::snprintf(ebuf, sizeof(ebuf), "e%c%02d", exp < 0 ? '-' : '+', std::abs(exp));
  return sign + out + ebuf;
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Names and dtypes

const char* KindName(Kind kind) {
  switch (kind) {
    case Kind::kNone: return "None";
    case Kind::kBool: return "bool";
    case Kind::kInt: return "int";
    case Kind::kFloat: return "float";
    case Kind::kStr: return "str";
    case Kind::kBytes: return "bytes";
    case Kind::kList: return "list";
    case Kind::kTuple: return "tuple";
    case Kind::kDict: return "dict";
    case Kind::kArray: return "numpy array";
    case Kind::kObject: return "object";
  }
  return "?";
}

const char* DTypeName(DType dtype) {
  switch (dtype) {
    case DType::kBool: return "bool";
    case DType::kInt8: return "int8";
    case DType::kInt16: return "int16";
    case DType::kInt32: return "int32";
    case DType::kInt64: return "int64";
    case DType::kUInt8: return "uint8";
    case DType::kUInt16: return "uint16";
    case DType::kUInt32: return "uint32";
    case DType::kUInt64: return "uint64";
    case DType::kFloat16: return "float16";
    case DType::kFloat32: return "float32";
    case DType::kFloat64: return "float64";
    case DType::kObject: return "object";
    case DType::kUnicode: return "unicode";
  }
  return "?";
}

int FixedItemSize(DType dtype) {
  switch (dtype) {
    case DType::kBool: case DType::kInt8: case DType::kUInt8: return 1;
    case DType::kInt16: case DType::kUInt16: case DType::kFloat16: return 2;
    case DType::kInt32: case DType::kUInt32: case DType::kFloat32: return 4;
    case DType::kInt64: case DType::kUInt64: case DType::kFloat64: case DType::kObject: return 8;
    case DType::kUnicode: return 0;
  }
  return 0;
}

bool IsInteger(DType d) {
  return d == DType::kInt8 || d == DType::kInt16 || d == DType::kInt32 || d == DType::kInt64 || d == DType::kUInt8 ||
         d == DType::kUInt16 || d == DType::kUInt32 || d == DType::kUInt64;
}
bool IsFloat(DType d) { return d == DType::kFloat16 || d == DType::kFloat32 || d == DType::kFloat64; }

// ---------------------------------------------------------------------------------------------------------------
// Value

Value Value::Bool(bool b) {
  Value v(Kind::kBool);
  v.b_ = b;
  return v;
}
Value Value::Int(int64_t i) {
  Value v(Kind::kInt);
  v.i_ = i;
  return v;
}
Value Value::Float(double d) {
  Value v(Kind::kFloat);
  v.f_ = d;
  return v;
}
Value Value::Str(std::string utf8) {
  SD_CHECK(ValidUtf8(utf8), << "Value::Str of invalid UTF-8");
  Value v = Access::Make(Kind::kStr);
  v.node_->text = std::move(utf8);
  return v;
}
Value Value::Bytes(std::string bytes) {
  Value v = Access::Make(Kind::kBytes);
  v.node_->text = std::move(bytes);
  return v;
}

static Value Sequence(Kind kind, std::vector<Value> elements) {
  Value v = Access::Make(kind);
  Value::Node& n = Access::NodeOf(v);
  n.height = 1;
  for (const Value& e : elements) n.height = std::max(n.height, HeightOf(e) + 1);
  n.elements = std::move(elements);
  return v;
}
Value Value::List(std::vector<Value> elements) { return Sequence(Kind::kList, std::move(elements)); }
Value Value::Tuple(std::vector<Value> elements) { return Sequence(Kind::kTuple, std::move(elements)); }

Value Value::Dict(std::vector<std::pair<Value, Value>> entries) {
  Value v = Access::Make(Kind::kDict);
  Node& n = *v.node_;
  n.height = 1;
  n.entries.reserve(entries.size());
  for (auto& [k, x] : entries) {
    SD_CHECK(Hashable(k), << "Value::Dict: a " << KindName(k.kind()) << " key is unhashable");
    n.height = std::max({n.height, HeightOf(k) + 1, HeightOf(x) + 1});
    DictInsert(n, std::move(k), std::move(x));
  }
  return v;
}

Value Value::FromArray(Array array) {
  SD_CHECK(array.dtype == DType::kObject ? static_cast<int64_t>(array.objects.size()) == array.size()
                                         : static_cast<int64_t>(array.data.size()) == array.size() * array.itemsize,
           << "Value::FromArray: " << DTypeName(array.dtype) << " array data does not match its shape");
  Value v = Access::Make(Kind::kArray);
  v.node_->height = 1;
  for (const Value& e : array.objects) v.node_->height = std::max(v.node_->height, HeightOf(e) + 1);
  v.node_->array = std::make_unique<Array>(std::move(array));
  return v;
}

Value Value::FromObject(Object object) {
  Value v = Access::Make(Kind::kObject);
  v.node_->height = std::max({1u, HeightOf(object.args) + 1, HeightOf(object.state) + 1});
  v.node_->object = std::make_unique<Object>(std::move(object));
  return v;
}

Value::Node& Value::MutableNode() {
  SD_CHECK(node_, << "editing a " << KindName(kind_));
  if (node_.use_count() > 1) {
    node_ = std::make_shared<Node>(*node_);
  }
  node_->inserted = false;
  node_->pending = false;
  return *node_;
}

bool Value::AsBool() const {
  switch (kind_) {
    case Kind::kBool: return b_;
    case Kind::kInt: return i_ != 0;
    case Kind::kArray:
      if (array().ndim() == 0 && array().dtype == DType::kBool) return array().At<bool>(0);
      break;
    default: break;
  }
  WrongKind(*this, "a bool");
}

int64_t Value::AsInt() const {
  switch (kind_) {
    case Kind::kBool: return b_ ? 1 : 0;
    case Kind::kInt: return i_;
    case Kind::kArray:
      if (array().ndim() == 0 && (IsInteger(array().dtype) || array().dtype == DType::kBool)) return array().AsInt(0);
      break;
    default: break;
  }
  WrongKind(*this, "an int");
}

double Value::AsDouble() const {
  switch (kind_) {
    case Kind::kBool: return b_ ? 1 : 0;
    case Kind::kInt: return static_cast<double>(i_);
    case Kind::kFloat: return f_;
    case Kind::kArray:
      if (IsNumericScalar(*this)) return array().AsDouble(0);
      break;
    default: break;
  }
  WrongKind(*this, "a number");
}

std::string Value::AsString() const {
  if (kind_ == Kind::kStr) return node_->text;
  if (kind_ == Kind::kArray && array().ndim() == 0 && array().dtype == DType::kUnicode) return array().StringAt(0);
  WrongKind(*this, "a str");
}

const std::string& Value::AsBytes() const {
  if (kind_ != Kind::kBytes) WrongKind(*this, "bytes");
  return node_->text;
}

size_t Value::size() const {
  if (kind_ == Kind::kList || kind_ == Kind::kTuple) return node_->elements.size();
  if (kind_ == Kind::kDict) return node_->entries.size();
  WrongKind(*this, "a list, tuple or dict");
}

const Value& Value::operator[](size_t i) const {
  const std::vector<Value>& e = elements();
  SD_CHECK(i < e.size(), << "element " << i << " of a " << KindName(kind_) << " of " << e.size());
  return e[i];
}

const std::vector<Value>& Value::elements() const {
  if (kind_ != Kind::kList && kind_ != Kind::kTuple) WrongKind(*this, "a list or tuple");
  return node_->elements;
}

const Value* Value::Find(std::string_view key) const {
  if (kind_ != Kind::kDict) WrongKind(*this, "a dict");
  if (node_->index) {
    Value k = Access::Make(Kind::kStr);
    k.node_->text.assign(key);
    return Find(k);
  }
  for (const auto& [k, v] : node_->entries)
    if (IsStringLike(k) && (k.kind() == Kind::kStr ? k.node_->text == key : k.AsString() == key)) return &v;
  return nullptr;
}

const Value* Value::Find(const Value& key) const {
  if (kind_ != Kind::kDict) WrongKind(*this, "a dict");
  if (!Hashable(key)) return nullptr;
  const ptrdiff_t at = DictFind(*node_, key);
  return at < 0 ? nullptr : &node_->entries[static_cast<size_t>(at)].second;
}

const std::vector<std::pair<Value, Value>>& Value::items() const {
  if (kind_ != Kind::kDict) WrongKind(*this, "a dict");
  return node_->entries;
}

const Array& Value::array() const {
  if (kind_ != Kind::kArray) WrongKind(*this, "a numpy array");
  return *node_->array;
}

const Object& Value::object() const {
  if (kind_ != Kind::kObject) WrongKind(*this, "an object");
  return *node_->object;
}

void Value::Append(Value v) {
  SD_CHECK(kind_ == Kind::kList, << "Append to a " << KindName(kind_));
  Node& n = MutableNode();  // after `v` was copied: appending a list to itself appends the old version
  n.height = std::max(n.height, HeightOf(v) + 1);
  n.elements.push_back(std::move(v));
}

void Value::SetItem(size_t i, Value v) {
  SD_CHECK(kind_ == Kind::kList || kind_ == Kind::kTuple, << "SetItem on a " << KindName(kind_));
  Node& n = MutableNode();
  SD_CHECK(i < n.elements.size(), << "SetItem " << i << " of " << n.elements.size());
  n.height = std::max(n.height, HeightOf(v) + 1);
  n.elements[i] = std::move(v);
}

void Value::Set(std::string key, Value v) { Set(Str(std::move(key)), std::move(v)); }

void Value::Set(Value key, Value v) {
  SD_CHECK(kind_ == Kind::kDict, << "Set on a " << KindName(kind_));
  SD_CHECK(Hashable(key), << "Set: a " << KindName(key.kind()) << " key is unhashable");
  Node& n = MutableNode();
  n.height = std::max({n.height, HeightOf(key) + 1, HeightOf(v) + 1});
  DictInsert(n, std::move(key), std::move(v));
}

std::vector<Value>& Value::mutable_elements() {
  SD_CHECK(kind_ == Kind::kList || kind_ == Kind::kTuple, << "mutable_elements of a " << KindName(kind_));
  return MutableNode().elements;
}

Array& Value::mutable_array() {
  SD_CHECK(kind_ == Kind::kArray, << "mutable_array of a " << KindName(kind_));
  return *MutableNode().array;
}

Object& Value::mutable_object() {
  SD_CHECK(kind_ == Kind::kObject, << "mutable_object of a " << KindName(kind_));
  return *MutableNode().object;
}

bool operator==(const Value& a, const Value& b) {
  if (a.kind_ != b.kind_) return false;
  if (a.node_ && a.node_ == b.node_) return true;
  switch (a.kind_) {
    case Kind::kNone: return true;
    case Kind::kBool: return a.b_ == b.b_;
    case Kind::kInt: return a.i_ == b.i_;
    case Kind::kFloat: return std::memcmp(&a.f_, &b.f_, 8) == 0;
    case Kind::kStr:
    case Kind::kBytes: return a.node_->text == b.node_->text;
    case Kind::kList:
    case Kind::kTuple: return a.node_->elements == b.node_->elements;
    case Kind::kDict: return a.node_->entries == b.node_->entries;
    case Kind::kArray: {
      const Array &x = *a.node_->array, &y = *b.node_->array;
      if (x.dtype != y.dtype || x.itemsize != y.itemsize || x.shape != y.shape || x.scalar != y.scalar) return false;
      if (x.dtype == DType::kObject) return x.objects == y.objects;
      if (x.fortran_order == y.fortran_order) return x.data == y.data;
      return x.ToCOrder().data == y.ToCOrder().data;
    }
    case Kind::kObject: {
      const Object &x = *a.node_->object, &y = *b.node_->object;
      return x.module == y.module && x.name == y.name && x.via == y.via && x.args == y.args && x.state == y.state;
    }
  }
  return false;
}

// ---------------------------------------------------------------------------------------------------------------
// Array

int64_t Array::size() const {
  int64_t n = 1;
  for (int64_t d : shape) n *= d;
  return n;
}

int64_t Array::ByteOffset(int64_t i) const {
  SD_CHECK(i >= 0 && i < size(), << "element " << i << " of an array of " << size());
  if (!fortran_order || shape.size() <= 1) return i * itemsize;
  // Unravel the C-order index from the last axis; each coordinate weighs the column-major stride of its axis,
  // the product of the axes before it (no axis is 0 here: i < size()).
  int64_t offset = 0, stride = size(), rest = i;
  for (size_t k = shape.size(); k-- > 0;) {
    stride /= shape[k];
    offset += (rest % shape[k]) * stride;
    rest /= shape[k];
  }
  return offset * itemsize;
}

double Array::AsDouble(int64_t i) const {
  switch (dtype) {
    case DType::kBool: return At<bool>(i) ? 1 : 0;
    case DType::kInt8: return At<int8_t>(i);
    case DType::kInt16: return At<int16_t>(i);
    case DType::kInt32: return At<int32_t>(i);
    case DType::kInt64: return static_cast<double>(At<int64_t>(i));
    case DType::kUInt8: return At<uint8_t>(i);
    case DType::kUInt16: return At<uint16_t>(i);
    case DType::kUInt32: return At<uint32_t>(i);
    case DType::kUInt64: return static_cast<double>(At<uint64_t>(i));
    case DType::kFloat16: return HalfToDouble(At<uint16_t>(i));
    case DType::kFloat32: return At<float>(i);
    case DType::kFloat64: return At<double>(i);
    case DType::kObject: return ObjectAt(i).AsDouble();
    case DType::kUnicode: break;
  }
  throw InputError({}, Msg() << "a " << DTypeName(dtype) << " array element is not a number");
}

int64_t Array::AsInt(int64_t i) const {
  switch (dtype) {
    case DType::kBool: return At<bool>(i) ? 1 : 0;
    case DType::kInt8: return At<int8_t>(i);
    case DType::kInt16: return At<int16_t>(i);
    case DType::kInt32: return At<int32_t>(i);
    case DType::kInt64: return At<int64_t>(i);
    case DType::kUInt8: return At<uint8_t>(i);
    case DType::kUInt16: return At<uint16_t>(i);
    case DType::kUInt32: return At<uint32_t>(i);
    case DType::kUInt64: {
      const uint64_t v = At<uint64_t>(i);
      if (v > uint64_t(INT64_MAX)) throw InputError({}, Msg() << "uint64 element " << v << " does not fit int64");
      return static_cast<int64_t>(v);
    }
    case DType::kObject: return ObjectAt(i).AsInt();
    default: break;
  }
  throw InputError({}, Msg() << "a " << DTypeName(dtype) << " array element is not an integer");
}

std::string Array::StringAt(int64_t i) const {
  if (dtype == DType::kObject) return ObjectAt(i).AsString();
  if (dtype != DType::kUnicode) throw InputError({}, Msg() << "a " << DTypeName(dtype) << " array element is not a str");
  const size_t at = static_cast<size_t>(ByteOffset(i));
  size_t chars = static_cast<size_t>(itemsize / 4);
  uint32_t cp;
  while (chars > 0 && (std::memcpy(&cp, data.data() + at + 4 * (chars - 1), 4), cp == 0)) --chars;
  std::string out;
  for (size_t k = 0; k < chars; ++k) {
    std::memcpy(&cp, data.data() + at + 4 * k, 4);
    AppendUtf8(&out, IsScalarValue(cp) ? cp : 0xfffd);
  }
  return out;
}

const Value& Array::ObjectAt(int64_t i) const {
  SD_CHECK(dtype == DType::kObject, << "ObjectAt of a " << DTypeName(dtype) << " array");
  SD_CHECK(i >= 0 && i < static_cast<int64_t>(objects.size()), << "element " << i << " of " << objects.size());
  return objects[static_cast<size_t>(i)];
}

std::vector<double> Array::ToDoubles() const {
  const int64_t n = size();
  std::vector<double> out(static_cast<size_t>(n));
  if (!fortran_order || ndim() <= 1) {
    if (dtype == DType::kFloat64) {
      std::memcpy(out.data(), data.data(), static_cast<size_t>(n) * 8);
      return out;
    }
    if (dtype == DType::kFloat32) {
      for (int64_t i = 0; i < n; ++i) {
        float f;
        std::memcpy(&f, data.data() + 4 * i, 4);
        out[static_cast<size_t>(i)] = f;
      }
      return out;
    }
  }
  for (int64_t i = 0; i < n; ++i) out[static_cast<size_t>(i)] = AsDouble(i);
  return out;
}

Array Array::ToCOrder() const {
  Array out = *this;
  out.fortran_order = false;
  if (!fortran_order || ndim() <= 1 || dtype == DType::kObject) return out;
  const int64_t n = size();
  for (int64_t i = 0; i < n; ++i)
    std::memcpy(out.data.data() + i * itemsize, data.data() + ByteOffset(i), static_cast<size_t>(itemsize));
  return out;
}

Array Array::Zeros(DType dtype, std::vector<int64_t> shape, int chars) {
  Array a;
  a.dtype = dtype;
  a.itemsize = dtype == DType::kUnicode ? 4 * chars : FixedItemSize(dtype);
  a.shape = std::move(shape);
  for (int64_t d : a.shape) SD_CHECK(d >= 0, << "negative dimension " << d);
  if (dtype == DType::kObject) a.objects.resize(static_cast<size_t>(a.size()));
  else a.data.assign(static_cast<size_t>(a.size() * a.itemsize), '\0');
  return a;
}

Array Array::Objects(std::vector<Value> values, std::vector<int64_t> shape) {
  Array a;
  a.dtype = DType::kObject;
  a.itemsize = 8;
  a.shape = shape.empty() ? std::vector<int64_t>{static_cast<int64_t>(values.size())} : std::move(shape);
  SD_CHECK(a.size() == static_cast<int64_t>(values.size()), << "Array::Objects: shape does not hold the values");
  a.objects = std::move(values);
  return a;
}

Array Array::Unicode(const std::vector<std::string>& utf8, std::vector<int64_t> shape) {
  std::vector<std::vector<uint32_t>> cps(utf8.size());
  size_t chars = 0;
  for (size_t i = 0; i < utf8.size(); ++i) {
    SD_CHECK(ValidUtf8(utf8[i]), << "Array::Unicode of invalid UTF-8");
    uint32_t cp = 0;
    for (size_t k = 0; k < utf8[i].size();) {
      NextCodePoint(utf8[i], &k, &cp);
      cps[i].push_back(cp);
    }
    chars = std::max(chars, cps[i].size());
  }
  Array a = Zeros(DType::kUnicode, shape.empty() ? std::vector<int64_t>{static_cast<int64_t>(utf8.size())} : shape,
                  static_cast<int>(chars));
  SD_CHECK(a.size() == static_cast<int64_t>(utf8.size()), << "Array::Unicode: shape does not hold the values");
  for (size_t i = 0; i < cps.size(); ++i)
    if (!cps[i].empty()) std::memcpy(a.data.data() + i * a.itemsize, cps[i].data(), cps[i].size() * 4);
  return a;
}

// ---------------------------------------------------------------------------------------------------------------
// The allow-list

namespace {

enum class Role {
  kKeep,           // kept as a kObject (pandas, slice, set, ...)
  kReconstruct,    // numpy.core.multiarray._reconstruct: an empty ndarray that BUILD fills
  kFromBuffer,     // numpy.core.numeric._frombuffer(buffer, dtype, shape, order): protocol 5 arrays
  kScalar,         // numpy.core.multiarray.scalar(dtype, bytes)
  kNdarray,        // numpy.ndarray: only _reconstruct's argument
  kDtype,          // numpy.dtype(typestr, align, copy) + BUILD(state)
  kCodecsEncode,   // _codecs.encode(str, 'latin1'): bytes in protocols < 3
  kBytes,          // builtins.bytes(): empty bytes in protocols < 3
  kByteArray,      // builtins.bytearray(bytes)
  kOrderedDict,    // collections.OrderedDict(): a dict that SETITEMS fills
  kReconstructor,  // copyreg._reconstructor(cls, object, None): protocols 0 and 1 for cls.__new__(cls)
  kNewObjFn,       // copyreg.__newobj__(cls, *args)
  kObjectBase,     // builtins.object: only _reconstructor's argument
};

struct Allowed {
  std::string_view module, name;
  Role role;
};

constexpr Allowed kAllowed[] = {
    {"numpy.core.multiarray", "_reconstruct", Role::kReconstruct},
    {"numpy._core.multiarray", "_reconstruct", Role::kReconstruct},
    {"numpy.core.multiarray", "scalar", Role::kScalar},
    {"numpy._core.multiarray", "scalar", Role::kScalar},
    {"numpy.core.numeric", "_frombuffer", Role::kFromBuffer},
    {"numpy._core.numeric", "_frombuffer", Role::kFromBuffer},
    {"numpy", "ndarray", Role::kNdarray},
    {"numpy", "dtype", Role::kDtype},
    {"_codecs", "encode", Role::kCodecsEncode},
    {"builtins", "bytes", Role::kBytes},
    {"builtins", "bytearray", Role::kByteArray},
    {"builtins", "slice", Role::kKeep},
    {"builtins", "set", Role::kKeep},
    {"builtins", "frozenset", Role::kKeep},
    {"builtins", "object", Role::kObjectBase},
    {"collections", "OrderedDict", Role::kOrderedDict},
    {"copyreg", "_reconstructor", Role::kReconstructor},
    {"copyreg", "__newobj__", Role::kNewObjFn},
    {"pandas.core.frame", "DataFrame", Role::kKeep},
    {"pandas.core.internals.managers", "BlockManager", Role::kKeep},
    {"pandas._libs.internals", "_unpickle_block", Role::kKeep},
    {"pandas.core.indexes.base", "Index", Role::kKeep},
    {"pandas.core.indexes.base", "_new_Index", Role::kKeep},
    {"pandas.core.indexes.range", "RangeIndex", Role::kKeep},
    {"pandas.core.indexes.numeric", "Int64Index", Role::kKeep},
    {"pandas.core.indexes.numeric", "UInt64Index", Role::kKeep},
    {"pandas.core.indexes.numeric", "Float64Index", Role::kKeep},
};

// Protocols < 3 write Python 2 module names, which CPython's unpickler maps back (fix_imports).
std::string_view ModernModule(std::string_view module) {
  if (module == "__builtin__") return "builtins";
  if (module == "copy_reg") return "copyreg";
  return module;
}

const Allowed* FindAllowed(std::string_view module, std::string_view name) {
  module = ModernModule(module);
  for (const Allowed& a : kAllowed)
    if (a.module == module && a.name == name) return &a;
  return nullptr;
}

struct DtypeInfo {
  DType dtype;
  int itemsize;
  bool big_endian;
};

// ---------------------------------------------------------------------------------------------------------------
// The loader: CPython's pickle virtual machine (Lib/pickle.py, _Unpickler) over Values.

namespace op {
enum : uint8_t {
  MARK = '(', STOP = '.', POP = '0', POP_MARK = '1', DUP = '2', FLOAT = 'F', INT = 'I', BININT = 'J',
  BININT1 = 'K', LONG = 'L', BININT2 = 'M', NONE = 'N', PERSID = 'P', BINPERSID = 'Q', REDUCE = 'R',
  STRING = 'S', BINSTRING = 'T', SHORT_BINSTRING = 'U', UNICODE = 'V', BINUNICODE = 'X', APPEND = 'a',
  BUILD = 'b', GLOBAL = 'c', DICT = 'd', EMPTY_DICT = '}', APPENDS = 'e', GET = 'g', BINGET = 'h', INST = 'i',
  LONG_BINGET = 'j', LIST = 'l', EMPTY_LIST = ']', OBJ = 'o', PUT = 'p', BINPUT = 'q', LONG_BINPUT = 'r',
  SETITEM = 's', TUPLE = 't', EMPTY_TUPLE = ')', SETITEMS = 'u', BINFLOAT = 'G',
  PROTO = 0x80, NEWOBJ = 0x81, EXT1 = 0x82, EXT2 = 0x83, EXT4 = 0x84, TUPLE1 = 0x85, TUPLE2 = 0x86,
  TUPLE3 = 0x87, NEWTRUE = 0x88, NEWFALSE = 0x89, LONG1 = 0x8a, LONG4 = 0x8b,
  BINBYTES = 'B', SHORT_BINBYTES = 'C',
  SHORT_BINUNICODE = 0x8c, BINUNICODE8 = 0x8d, BINBYTES8 = 0x8e, EMPTY_SET = 0x8f, ADDITEMS = 0x90,
  FROZENSET = 0x91, NEWOBJ_EX = 0x92, STACK_GLOBAL = 0x93, MEMOIZE = 0x94, FRAME = 0x95,
  BYTEARRAY8 = 0x96, NEXT_BUFFER = 0x97, READONLY_BUFFER = 0x98,
};
}  // namespace op

class Machine {
 public:
  Machine(std::string_view in, const fs::path& file, const LoadOptions& options)
      : in_(in), file_(file), max_depth_(static_cast<uint32_t>(std::max(1, options.max_depth))),
        max_memo_(options.max_memo) {}

  Value Run();

 private:
  [[noreturn]] void Fail(const std::string& what) const {
    throw InputError(file_, Msg() << "byte " << op_ << ": " << what);
  }

  // --- input
  size_t Left() const { return in_.size() - pos_; }
  std::string_view Take(uint64_t n, const char* what) {
    if (n > Left())
      Fail(Msg() << "truncated: " << what << " needs " << n << " bytes, " << Left() << " left");
    const std::string_view s = in_.substr(pos_, static_cast<size_t>(n));
    pos_ += static_cast<size_t>(n);
    return s;
  }
  uint64_t LittleEndian(int bytes, const char* what) {
    const std::string_view s = Take(static_cast<uint64_t>(bytes), what);
    uint64_t v = 0;
    for (int k = bytes - 1; k >= 0; --k) v = (v << 8) | static_cast<unsigned char>(s[static_cast<size_t>(k)]);
    return v;
  }
  std::string_view Line(const char* what) {
    const size_t nl = in_.find('\n', pos_);
    if (nl == std::string_view::npos) Fail(Msg() << "truncated: " << what << " has no end of line");
    const std::string_view s = in_.substr(pos_, nl - pos_);
    pos_ = nl + 1;
    return s;
  }

  // --- stack (CPython keeps values below the last MARK out of reach; so do we)
  size_t Base() const { return marks_.empty() ? 0 : marks_.back(); }
  void Push(Value v) { stack_.push_back(std::move(v)); }
  Value Pop() {
    if (stack_.size() <= Base()) Fail("stack underflow");
    Value v = std::move(stack_.back());
    stack_.pop_back();
    return v;
  }
  Value& Top() {
    if (stack_.size() <= Base()) Fail("stack underflow");
    return stack_.back();
  }
  std::vector<Value> PopMark() {
    if (marks_.empty()) Fail("no MARK to pop to");
    const size_t base = marks_.back();
    marks_.pop_back();
    std::vector<Value> items(std::make_move_iterator(stack_.begin() + static_cast<ptrdiff_t>(base)),
                             std::make_move_iterator(stack_.end()));
    stack_.resize(base);
    return items;
  }

  // --- tree building
  Value NewContainer(Kind kind) {
    Value v = Access::Make(kind);
    Access::NodeOf(v).height = 1;
    return v;
  }
  // `child` goes inside `parent`: it is frozen from now on, and the parent's height grows to cover it.
  void Adopt(Value::Node& parent, const Value& child) {
    if (Value::Node* c = Access::NodePtr(child)) {
      if (c == &parent) Fail("a value inside itself (cyclic pickles are not supported)");
      c->inserted = true;
      parent.height = std::max(parent.height, c->height + 1);
    } else {
      parent.height = std::max(parent.height, 1u);
    }
    if (parent.height > max_depth_) Fail(Msg() << "nesting deeper than " << max_depth_ << " levels");
  }
  Value::Node& Mutable(const Value& target, const char* what) {
    Value::Node* n = Access::NodePtr(target);
    if (!n) Fail(Msg() << what << " on a " << KindName(target.kind()));
    if (n->inserted)
      Fail(Msg() << what << " on a " << KindName(target.kind())
                 << " that is already inside another value (self-referencing or cyclic pickles are not supported)");
    return *n;
  }
  Value MakeSequence(Kind kind, std::vector<Value> items) {
    Value v = NewContainer(kind);
    Value::Node& n = Access::NodeOf(v);
    for (const Value& e : items) Adopt(n, e);
    n.elements = std::move(items);
    return v;
  }
  void AppendTo(Value& target, Value item) {
    if (target.kind() != Kind::kList) Fail(Msg() << "APPEND to a " << KindName(target.kind()) << ", not a list");
    Value::Node& n = Mutable(target, "APPEND");
    Adopt(n, item);
    n.elements.push_back(std::move(item));
  }
  void SetItemOf(Value& target, Value key, Value value) {
    if (target.kind() != Kind::kDict) Fail(Msg() << "SETITEM on a " << KindName(target.kind()) << ", not a dict");
    Value::Node& n = Mutable(target, "SETITEM");
    if (!Hashable(key)) Fail(Msg() << "unhashable dict key (a " << KindName(key.kind()) << ")");
    Adopt(n, key);
    Adopt(n, value);
    DictInsert(n, std::move(key), std::move(value));
  }
  void Memo(uint64_t index) {
    if (memo_.size() >= max_memo_ && !memo_.count(index)) Fail(Msg() << "more than " << max_memo_ << " memo entries");
    memo_[index] = Top();
  }
  void Get(uint64_t index) {
    const auto it = memo_.find(index);
    if (it == memo_.end()) Fail(Msg() << "memo key " << index << " is not defined");
    Push(it->second);
  }

  // --- text and numbers
  Value Text(std::string_view utf8) {
    if (!ValidUtf8(utf8)) Fail("invalid UTF-8 in a str (lone surrogates are not supported)");
    Value v = Access::Make(Kind::kStr);
    Access::NodeOf(v).text.assign(utf8);
    return v;
  }
  Value RawBytes(std::string_view bytes) {
    Value v = Access::Make(Kind::kBytes);
    Access::NodeOf(v).text.assign(bytes);
    return v;
  }
  int64_t DecimalInt(std::string_view s, const char* what) {
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    int64_t v = 0;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    if (r.ec == std::errc::result_out_of_range) Fail(Msg() << what << " " << s << " is outside int64");
    if (r.ec != std::errc() || r.ptr != s.data() + s.size() || s.empty())
      Fail(Msg() << what << " argument '" << s << "' is not a decimal integer");
    return v;
  }
  int64_t TwosComplement(std::string_view b) {
    if (b.empty()) return 0;
    const bool negative = static_cast<unsigned char>(b.back()) & 0x80;
    // Bytes beyond the eighth may only extend the sign (CPython writes the fewest bytes, but any are valid).
    for (size_t k = 8; k < b.size(); ++k)
      if (static_cast<unsigned char>(b[k]) != (negative ? 0xff : 0x00)) Fail("int is outside int64");
    if (b.size() > 8 && ((static_cast<unsigned char>(b[7]) & 0x80) != 0) != negative) Fail("int is outside int64");
    uint64_t v = negative ? ~uint64_t(0) : 0;
    for (size_t k = std::min<size_t>(b.size(), 8); k-- > 0;) v = (v << 8) | static_cast<unsigned char>(b[k]);
    return static_cast<int64_t>(v);
  }
  Value StringOpcode(std::string_view line);
  Value RawUnicodeEscape(std::string_view s);

  // --- globals and calls
  Value Global(std::string_view module, std::string_view name);
  const Allowed& RoleOf(const Value& callable, const char* opcode);
  Value Call(const Value& callable, const Value& args, Object::Via via, const char* opcode);
  void Build(Value& target, Value state);
  DtypeInfo InterpretDtype(const Value& dtype);
  std::string DataBytes(const Value& data, const char* what);
  void FillArray(Array* a, const DtypeInfo& info, const std::vector<int64_t>& shape, std::string data);
  std::vector<int64_t> Shape(const Value& shape);

  std::string_view in_;
  const fs::path& file_;
  const uint32_t max_depth_;
  const size_t max_memo_;
  size_t pos_ = 0, op_ = 0;
  std::vector<Value> stack_;
  std::vector<size_t> marks_;
  std::unordered_map<uint64_t, Value> memo_;
};

Value Machine::Run() {
  for (;;) {
    op_ = pos_;
    if (pos_ >= in_.size()) Fail("truncated: no STOP opcode");
    const uint8_t code = static_cast<uint8_t>(in_[pos_++]);
    switch (code) {
      case op::PROTO: {
        const uint64_t p = LittleEndian(1, "PROTO");
        if (p > 5) Fail(Msg() << "unsupported pickle protocol " << p);
        break;
      }
      case op::FRAME: {
        // Frames only group opcodes for buffered reading; the length must still fit what is left.
        const uint64_t n = LittleEndian(8, "FRAME");
        if (n > Left()) Fail(Msg() << "truncated: FRAME of " << n << " bytes, " << Left() << " left");
        break;
      }
      case op::STOP: {
        if (!marks_.empty()) Fail("STOP with an open MARK");
        if (stack_.size() != 1) Fail(Msg() << "STOP with " << stack_.size() << " values on the stack (want 1)");
        if (pos_ != in_.size()) {
          op_ = pos_;
          Fail(Msg() << in_.size() - pos_ << " bytes after STOP");
        }
        return std::move(stack_.back());
      }

      // --- stack and memo
      case op::MARK: marks_.push_back(stack_.size()); break;
      case op::POP:
        if (stack_.size() > Base()) stack_.pop_back();
        else PopMark();  // CPython: POP with nothing above the mark pops the mark
        break;
      case op::POP_MARK: PopMark(); break;
      case op::DUP: Push(Top()); break;
      case op::PUT: {
        const int64_t i = DecimalInt(Line("PUT"), "PUT");
        if (i < 0) Fail("negative PUT index");
        Memo(static_cast<uint64_t>(i));
        break;
      }
      case op::BINPUT: Memo(LittleEndian(1, "BINPUT")); break;
      case op::LONG_BINPUT: Memo(LittleEndian(4, "LONG_BINPUT")); break;
      case op::MEMOIZE: Memo(memo_.size()); break;
      case op::GET: {
        const int64_t i = DecimalInt(Line("GET"), "GET");
        if (i < 0) Fail("negative GET index");
        Get(static_cast<uint64_t>(i));
        break;
      }
      case op::BINGET: Get(LittleEndian(1, "BINGET")); break;
      case op::LONG_BINGET: Get(LittleEndian(4, "LONG_BINGET")); break;

      // --- atoms
      case op::NONE: Push(Value::None()); break;
      case op::NEWTRUE: Push(Value::Bool(true)); break;
      case op::NEWFALSE: Push(Value::Bool(false)); break;
      case op::INT: {
        const std::string_view s = Line("INT");
        if (s == "01" || s == "00") Push(Value::Bool(s == "01"));  // protocols 0/1 spell True and False so
        else Push(Value::Int(DecimalInt(s, "INT")));
        break;
      }
      case op::BININT: Push(Value::Int(static_cast<int32_t>(LittleEndian(4, "BININT")))); break;
      case op::BININT1: Push(Value::Int(static_cast<int64_t>(LittleEndian(1, "BININT1")))); break;
      case op::BININT2: Push(Value::Int(static_cast<int64_t>(LittleEndian(2, "BININT2")))); break;
      case op::LONG: {
        std::string_view s = Line("LONG");
        if (!s.empty() && s.back() == 'L') s.remove_suffix(1);
        Push(Value::Int(DecimalInt(s, "LONG")));
        break;
      }
      case op::LONG1: {
        const uint64_t n = LittleEndian(1, "LONG1");
        Push(Value::Int(TwosComplement(Take(n, "LONG1"))));
        break;
      }
      case op::LONG4: {
        const int32_t n = static_cast<int32_t>(LittleEndian(4, "LONG4"));
        if (n < 0) Fail("LONG4 with a negative length");
        Push(Value::Int(TwosComplement(Take(static_cast<uint64_t>(n), "LONG4"))));
        break;
      }
      case op::FLOAT: {
        const std::string_view s = Line("FLOAT");
        double d = 0;
        std::string_view t = s;
        if (!t.empty() && t[0] == '+') t.remove_prefix(1);
        const auto r = std::from_chars(t.data(), t.data() + t.size(), d);
        if (r.ec != std::errc() || r.ptr != t.data() + t.size() || t.empty())
          Fail(Msg() << "FLOAT argument '" << s << "' is not a number");
        Push(Value::Float(d));
        break;
      }
      case op::BINFLOAT: {
        const std::string_view s = Take(8, "BINFLOAT");
        uint64_t bits = 0;
        for (char c : s) bits = (bits << 8) | static_cast<unsigned char>(c);  // big-endian
        double d;
        std::memcpy(&d, &bits, 8);
        Push(Value::Float(d));
        break;
      }
      case op::STRING: Push(StringOpcode(Line("STRING"))); break;
      case op::BINSTRING: {
        const int32_t n = static_cast<int32_t>(LittleEndian(4, "BINSTRING"));
        if (n < 0) Fail("BINSTRING with a negative length");
        Push(Text(Utf8FromLatin1(Take(static_cast<uint64_t>(n), "BINSTRING"))));
        break;
      }
      case op::SHORT_BINSTRING:
        Push(Text(Utf8FromLatin1(Take(LittleEndian(1, "SHORT_BINSTRING"), "SHORT_BINSTRING"))));
        break;
      case op::UNICODE: Push(RawUnicodeEscape(Line("UNICODE"))); break;
      case op::SHORT_BINUNICODE: Push(Text(Take(LittleEndian(1, "SHORT_BINUNICODE"), "SHORT_BINUNICODE"))); break;
      case op::BINUNICODE: Push(Text(Take(LittleEndian(4, "BINUNICODE"), "BINUNICODE"))); break;
      case op::BINUNICODE8: Push(Text(Take(LittleEndian(8, "BINUNICODE8"), "BINUNICODE8"))); break;
      case op::SHORT_BINBYTES: Push(RawBytes(Take(LittleEndian(1, "SHORT_BINBYTES"), "SHORT_BINBYTES"))); break;
      case op::BINBYTES: Push(RawBytes(Take(LittleEndian(4, "BINBYTES"), "BINBYTES"))); break;
      case op::BINBYTES8: Push(RawBytes(Take(LittleEndian(8, "BINBYTES8"), "BINBYTES8"))); break;
      case op::BYTEARRAY8: Push(RawBytes(Take(LittleEndian(8, "BYTEARRAY8"), "BYTEARRAY8"))); break;
      case op::READONLY_BUFFER:
        if (Top().kind() != Kind::kBytes) Fail(Msg() << "READONLY_BUFFER on a " << KindName(Top().kind()));
        break;
      case op::NEXT_BUFFER: Fail("out-of-band buffers (NEXT_BUFFER) are not supported");
      case op::PERSID:
      case op::BINPERSID: Fail("persistent IDs (PERSID) are not supported");
      case op::EXT1:
      case op::EXT2:
      case op::EXT4: Fail("extension registry codes (EXT1/EXT2/EXT4) are not supported");

      // --- containers
      case op::EMPTY_LIST: Push(NewContainer(Kind::kList)); break;
      case op::LIST: Push(MakeSequence(Kind::kList, PopMark())); break;
      case op::APPEND: {
        Value item = Pop();
        AppendTo(Top(), std::move(item));
        break;
      }
      case op::APPENDS: {
        std::vector<Value> items = PopMark();
        Value& target = Top();
        if (target.kind() != Kind::kList) Fail(Msg() << "APPENDS to a " << KindName(target.kind()) << ", not a list");
        Mutable(target, "APPENDS").elements.reserve(target.elements().size() + items.size());
        for (Value& item : items) AppendTo(target, std::move(item));
        break;
      }
      case op::EMPTY_TUPLE: Push(NewContainer(Kind::kTuple)); break;
      case op::TUPLE: Push(MakeSequence(Kind::kTuple, PopMark())); break;
      case op::TUPLE1:
      case op::TUPLE2:
      case op::TUPLE3: {
        const size_t n = code - op::TUPLE1 + 1u;
        if (stack_.size() < Base() + n) Fail("stack underflow");
        std::vector<Value> items(std::make_move_iterator(stack_.end() - static_cast<ptrdiff_t>(n)),
                                 std::make_move_iterator(stack_.end()));
        stack_.resize(stack_.size() - n);
        Push(MakeSequence(Kind::kTuple, std::move(items)));
        break;
      }
      case op::EMPTY_DICT: Push(NewContainer(Kind::kDict)); break;
      case op::DICT: {
        std::vector<Value> items = PopMark();
        if (items.size() % 2) Fail("DICT with an odd number of items");
        Push(NewContainer(Kind::kDict));
        for (size_t i = 0; i < items.size(); i += 2) SetItemOf(Top(), std::move(items[i]), std::move(items[i + 1]));
        break;
      }
      case op::SETITEM: {
        Value value = Pop();
        Value key = Pop();
        SetItemOf(Top(), std::move(key), std::move(value));
        break;
      }
      case op::SETITEMS: {
        std::vector<Value> items = PopMark();
        if (items.size() % 2) Fail("SETITEMS with an odd number of items");
        Value& target = Top();
        for (size_t i = 0; i < items.size(); i += 2) SetItemOf(target, std::move(items[i]), std::move(items[i + 1]));
        break;
      }
      case op::EMPTY_SET:
      case op::FROZENSET: {
        // Sets stay objects: builtins.set / frozenset with their items as args[0], the form protocols < 4 write.
        Value items = MakeSequence(Kind::kList, code == op::FROZENSET ? PopMark() : std::vector<Value>{});
        Value args = MakeSequence(Kind::kTuple, {items});
        Value set = NewContainer(Kind::kObject);
        Adopt(Access::NodeOf(set), args);
        Access::NodeOf(set).object = std::make_unique<Object>(
            Object{"builtins", code == op::FROZENSET ? "frozenset" : "set", std::move(args), Value(), Object::Via::kReduce});
        Push(std::move(set));
        break;
      }
      case op::ADDITEMS: {
        std::vector<Value> items = PopMark();
        Value& target = Top();
        if (target.kind() != Kind::kObject || !target.object().Is("builtins", "set"))
          Fail(Msg() << "ADDITEMS to a " << KindName(target.kind()) << ", not a set");
        Value::Node& set = Mutable(target, "ADDITEMS");
        // The set's args tuple and item list were made for it and are reachable through it alone.
        Value::Node& args = Access::NodeOf(set.object->args);
        Value::Node& list = Access::NodeOf(args.elements[0]);
        for (Value& item : items) {
          if (Access::NodePtr(item) == &set) Fail("a set inside itself (cyclic pickles are not supported)");
          if (!Hashable(item)) Fail(Msg() << "unhashable set item (a " << KindName(item.kind()) << ")");
          Adopt(list, item);
          args.height = std::max(args.height, list.height + 1);
          Adopt(set, set.object->args);
          list.elements.push_back(std::move(item));
        }
        break;
      }

      // --- globals, calls, state
      case op::GLOBAL: {
        const std::string_view module = Line("GLOBAL module");
        const std::string_view name = Line("GLOBAL name");
        Push(Global(module, name));
        break;
      }
      case op::STACK_GLOBAL: {
        Value name = Pop();
        Value module = Pop();
        if (module.kind() != Kind::kStr || name.kind() != Kind::kStr) Fail("STACK_GLOBAL needs two str");
        Push(Global(module.AsString(), name.AsString()));
        break;
      }
      case op::INST: {
        const std::string_view module = Line("INST module");
        const std::string_view name = Line("INST name");
        Value cls = Global(module, name);
        Value args = MakeSequence(Kind::kTuple, PopMark());
        Push(Call(cls, args, Object::Via::kReduce, "INST"));
        break;
      }
      case op::OBJ: {
        std::vector<Value> items = PopMark();
        if (items.empty()) Fail("OBJ without a class");
        Value cls = std::move(items[0]);
        items.erase(items.begin());
        Push(Call(cls, MakeSequence(Kind::kTuple, std::move(items)), Object::Via::kReduce, "OBJ"));
        break;
      }
      case op::REDUCE: {
        Value args = Pop();
        Value callable = Pop();
        Push(Call(callable, args, Object::Via::kReduce, "REDUCE"));
        break;
      }
      case op::NEWOBJ: {
        Value args = Pop();
        Value cls = Pop();
        Push(Call(cls, args, Object::Via::kNewObj, "NEWOBJ"));
        break;
      }
      case op::NEWOBJ_EX: {
        Value kwargs = Pop();
        Value args = Pop();
        Value cls = Pop();
        if (kwargs.kind() != Kind::kDict || kwargs.size() != 0) Fail("NEWOBJ_EX with keyword arguments is not supported");
        Push(Call(cls, args, Object::Via::kNewObj, "NEWOBJ_EX"));
        break;
      }
      case op::BUILD: {
        Value state = Pop();
        Build(Top(), std::move(state));
        break;
      }
      default:
        Fail(Msg() << "unknown opcode 0x" << std::hex << static_cast<int>(code));
    }
  }
}

Value Machine::StringOpcode(std::string_view s) {
  // repr() of a Python 2 str: quoted, with Python's backslash escapes; read as latin-1 text (as pandas does).
  if (s.size() < 2 || s.front() != s.back() || (s.front() != '\'' && s.front() != '"'))
    Fail("STRING argument is not a quoted string");
  s = s.substr(1, s.size() - 2);
  std::string raw;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] != '\\' || i + 1 == s.size()) {
      raw.push_back(s[i]);
      continue;
    }
    const char c = s[++i];
    switch (c) {
      case 'n': raw.push_back('\n'); break;
      case 't': raw.push_back('\t'); break;
      case 'r': raw.push_back('\r'); break;
      case 'a': raw.push_back('\a'); break;
      case 'b': raw.push_back('\b'); break;
      case 'f': raw.push_back('\f'); break;
      case 'v': raw.push_back('\v'); break;
      case '\\': case '\'': case '"': raw.push_back(c); break;
      case '\n': break;
      case 'x': {
        int v = 0;
        if (i + 2 >= s.size()) Fail("STRING with a truncated \\x escape");
        const auto r = std::from_chars(s.data() + i + 1, s.data() + i + 3, v, 16);
        if (r.ptr != s.data() + i + 3) Fail("STRING with an invalid \\x escape");
        raw.push_back(static_cast<char>(v));
        i += 2;
        break;
      }
      default:
        if (c >= '0' && c <= '7') {
          int v = c - '0';
          for (int k = 0; k < 2 && i + 1 < s.size() && s[i + 1] >= '0' && s[i + 1] <= '7'; ++k) v = v * 8 + (s[++i] - '0');
          raw.push_back(static_cast<char>(v & 0xff));
        } else {
          raw.push_back('\\');
          raw.push_back(c);
        }
    }
  }
  return Text(Utf8FromLatin1(raw));
}

Value Machine::RawUnicodeEscape(std::string_view s) {
  // Python's raw-unicode-escape: bytes are latin-1 code points, except \uXXXX and \UXXXXXXXX after an odd
  // number of backslashes.
  std::string out;
  for (size_t i = 0; i < s.size();) {
    if (s[i] != '\\') {
      AppendUtf8(&out, static_cast<unsigned char>(s[i++]));
      continue;
    }
    size_t run = 0;
    while (i < s.size() && s[i] == '\\') ++run, ++i;
    const bool escape = (run % 2 == 1) && i < s.size() && (s[i] == 'u' || s[i] == 'U');
    out.append(escape ? run - 1 : run, '\\');
    if (!escape) continue;
    const size_t digits = s[i] == 'u' ? 4 : 8;
    if (i + 1 + digits > s.size()) Fail("UNICODE with a truncated \\u escape");
    uint32_t cp = 0;
    const auto r = std::from_chars(s.data() + i + 1, s.data() + i + 1 + digits, cp, 16);
    if (r.ptr != s.data() + i + 1 + digits || r.ec != std::errc()) Fail("UNICODE with an invalid \\u escape");
    if (!IsScalarValue(cp)) Fail("UNICODE escape of a surrogate or beyond U+10FFFF (not supported)");
    AppendUtf8(&out, cp);
    i += 1 + digits;
  }
  return Text(out);
}

Value Machine::Global(std::string_view module, std::string_view name) {
  const Allowed* a = FindAllowed(module, name);
  if (!a)
    Fail(Msg() << "refusing to load global '" << module << "." << name
               << "' (pickles are read as data; only numpy, pandas and container classes are allowed)");
  Value v = NewContainer(Kind::kObject);
  Access::NodeOf(v).object =
      std::make_unique<Object>(Object{std::string(a->module), std::string(a->name), Value(), Value(), Object::Via::kGlobal});
  return v;
}

const Allowed& Machine::RoleOf(const Value& callable, const char* opcode) {
  if (callable.kind() != Kind::kObject || callable.object().via != Object::Via::kGlobal)
    Fail(Msg() << opcode << " on a " << KindName(callable.kind()) << " (only allow-listed globals can be called)");
  const Allowed* a = FindAllowed(callable.object().module, callable.object().name);
  SD_CHECK(a, << "a kGlobal outside the allow-list");
  return *a;
}

std::string Machine::DataBytes(const Value& data, const char* what) {
  if (data.kind() == Kind::kBytes) return data.AsBytes();
  std::string out;
  if (data.kind() == Kind::kStr && Latin1FromUtf8(data.AsString(), &out)) return out;  // Python 2 str data
  Fail(Msg() << what << " is a " << KindName(data.kind()) << ", not bytes");
}

std::vector<int64_t> Machine::Shape(const Value& shape) {
  if (shape.kind() != Kind::kTuple && shape.kind() != Kind::kList) Fail("numpy shape is not a tuple");
  std::vector<int64_t> out;
  // The product of the non-zero dimensions is bounded by the input size: arrays with elements hold at least a
  // byte per element (object arrays an opcode), and a shape like (2^40, 0) would make readers of the empty array
  // loop over its outer dimension.
  const int64_t limit = std::max<int64_t>(1, static_cast<int64_t>(in_.size()));
  int64_t nonzero = 1;
  for (const Value& d : shape.elements()) {
    if (d.kind() != Kind::kInt || d.AsInt() < 0) Fail("numpy shape holds a negative or non-integer dimension");
    const int64_t n = d.AsInt();
    if (n != 0) {
      if (nonzero > limit / n) Fail("numpy shape has more elements than the pickle has bytes");
      nonzero *= n;
    }
    out.push_back(n);
  }
  return out;
}

DtypeInfo Machine::InterpretDtype(const Value& dtype) {
  if (dtype.kind() != Kind::kObject || !dtype.object().Is("numpy", "dtype") || dtype.object().via == Object::Via::kGlobal)
    Fail(Msg() << "numpy dtype expected, got a " << KindName(dtype.kind()));
  const Object& o = dtype.object();
  std::string typestr = o.args.size() > 0 && o.args[0].kind() == Kind::kStr ? o.args[0].AsString() : "";
  char byteorder = '=';
  if (!typestr.empty() && std::string_view("<>|=").find(typestr[0]) != std::string_view::npos) {
    byteorder = typestr[0];
    typestr.erase(0, 1);
  }
  int64_t elsize = -1;
  if (!o.state.is_none()) {
    // (version, byteorder, subarray, names, fields, elsize, alignment, flags[, metadata]), numpy's descr state.
    const Value& s = o.state;
    if (s.kind() != Kind::kTuple || s.size() < 8 || s[1].kind() != Kind::kStr || s[5].kind() != Kind::kInt)
      Fail("numpy dtype state is not (version, byteorder, ..., elsize, alignment, flags)");
    if (!s[2].is_none() || !s[3].is_none() || !s[4].is_none())
      Fail(Msg() << "structured or sub-array numpy dtype '" << typestr << "' is not supported");
    const std::string bo = s[1].AsString();
    if (bo.size() != 1 || std::string_view("<>|=").find(bo[0]) == std::string_view::npos)
      Fail(Msg() << "numpy dtype byte order '" << bo << "'");
    byteorder = bo[0];
    elsize = s[5].AsInt();
  }
  static constexpr struct { std::string_view code; DType dtype; } kCodes[] = {
      {"b1", DType::kBool}, {"i1", DType::kInt8}, {"i2", DType::kInt16}, {"i4", DType::kInt32},
      {"i8", DType::kInt64}, {"u1", DType::kUInt8}, {"u2", DType::kUInt16}, {"u4", DType::kUInt32},
      {"u8", DType::kUInt64}, {"f2", DType::kFloat16}, {"f4", DType::kFloat32}, {"f8", DType::kFloat64},
      {"O8", DType::kObject}, {"O4", DType::kObject}, {"O", DType::kObject}};
  for (const auto& c : kCodes)
    if (typestr == c.code) return {c.dtype, FixedItemSize(c.dtype), byteorder == '>'};
  if (!typestr.empty() && typestr[0] == 'U') {
    int64_t chars = 0;
    if (typestr.size() > 1) {
      const auto r = std::from_chars(typestr.data() + 1, typestr.data() + typestr.size(), chars);
      if (r.ec != std::errc() || r.ptr != typestr.data() + typestr.size() || chars < 0 || chars > (1 << 28))
        Fail(Msg() << "unsupported numpy dtype '" << typestr << "'");
    }
    const int64_t itemsize = elsize >= 0 ? elsize : 4 * chars;
    if (itemsize % 4 || itemsize > (int64_t(1) << 30)) Fail(Msg() << "numpy unicode dtype of " << itemsize << " bytes");
    return {DType::kUnicode, static_cast<int>(itemsize), byteorder == '>'};
  }
  Fail(Msg() << "unsupported numpy dtype '" << typestr << "' (bool, int, uint, float, object and unicode only)");
}

void Machine::FillArray(Array* a, const DtypeInfo& info, const std::vector<int64_t>& shape, std::string data) {
  a->dtype = info.dtype;
  a->itemsize = info.itemsize;
  a->shape = shape;
  const int64_t count = a->size();
  // count fits int64 (Shape checked); so does its product with itemsize only when it matches the data length.
  if (info.itemsize != 0 && count > static_cast<int64_t>(data.size()) / info.itemsize + 1)
    Fail(Msg() << "numpy data has " << data.size() << " bytes, too few for " << count << " elements");
  if (static_cast<int64_t>(data.size()) != count * info.itemsize)
    Fail(Msg() << "numpy data has " << data.size() << " bytes, " << count << " " << DTypeName(info.dtype)
               << " elements of " << info.itemsize << " bytes need " << count * info.itemsize);
  if (info.big_endian) SwapEach(&data, info.dtype == DType::kUnicode ? 4 : info.itemsize);
  if (info.dtype == DType::kUnicode) {
    for (size_t k = 0; k + 4 <= data.size(); k += 4) {
      uint32_t cp;
      std::memcpy(&cp, data.data() + k, 4);
      if (!IsScalarValue(cp)) Fail(Msg() << "numpy unicode data holds code point 0x" << std::hex << cp);
    }
  }
  if (info.dtype == DType::kBool) {
    for (char& c : data)
      if (c != 0 && c != 1) Fail("numpy bool data holds a byte other than 0 and 1");
  }
  a->data = std::move(data);
}

Value Machine::Call(const Value& callable, const Value& args, Object::Via via, const char* opcode) {
  const Allowed& role = RoleOf(callable, opcode);
  if (args.kind() != Kind::kTuple) Fail(Msg() << opcode << " arguments are a " << KindName(args.kind()) << ", not a tuple");
  const std::vector<Value>& a = args.elements();
  const std::string qualified = std::string(role.module) + "." + std::string(role.name);
  if (via == Object::Via::kNewObj && role.role != Role::kKeep) Fail(Msg() << opcode << " of '" << qualified << "' is not supported");
  const auto arity = [&](size_t lo, size_t hi) {
    if (a.size() < lo || a.size() > hi) Fail(Msg() << "'" << qualified << "' called with " << a.size() << " arguments");
  };
  switch (role.role) {
    case Role::kKeep: {
      Value v = NewContainer(Kind::kObject);
      Value::Node& n = Access::NodeOf(v);
      Adopt(n, args);
      n.object = std::make_unique<Object>(Object{std::string(role.module), std::string(role.name), args, Value(), via});
      return v;
    }
    case Role::kReconstruct: {
      arity(3, 3);
      if (a[0].kind() != Kind::kObject || !a[0].object().Is("numpy", "ndarray"))
        Fail("numpy _reconstruct of a class other than numpy.ndarray");
      // numpy always passes shape (0,): an empty array that BUILD fills. Anything larger would be uninitialised.
      const std::vector<int64_t> shape = Shape(a[1]);
      Array empty;
      empty.dtype = DType::kInt8;
      empty.itemsize = 1;
      empty.shape = shape;
      if (empty.size() != 0) Fail("numpy _reconstruct of a non-empty shape");
      Value v = NewContainer(Kind::kArray);
      Access::NodeOf(v).array = std::make_unique<Array>(std::move(empty));
      Access::NodeOf(v).pending = true;
      return v;
    }
    case Role::kScalar: {
      arity(1, 2);
      const DtypeInfo info = InterpretDtype(a[0]);
      if (info.dtype == DType::kObject || a.size() < 2) Fail("numpy object scalars are not supported");
      Array s;
      FillArray(&s, info, {}, DataBytes(a[1], "numpy scalar data"));
      s.scalar = true;
      Value v = NewContainer(Kind::kArray);
      Access::NodeOf(v).array = std::make_unique<Array>(std::move(s));
      return v;
    }
    case Role::kFromBuffer: {
      arity(4, 4);
      const DtypeInfo info = InterpretDtype(a[1]);
      if (info.dtype == DType::kObject) Fail("numpy _frombuffer of object dtype");
      if (a[3].kind() != Kind::kStr || (a[3].AsString() != "C" && a[3].AsString() != "F"))
        Fail("numpy _frombuffer order is not 'C' or 'F'");
      Array arr;
      FillArray(&arr, info, Shape(a[2]), DataBytes(a[0], "numpy _frombuffer buffer"));
      arr.fortran_order = a[3].AsString() == "F";
      Value v = NewContainer(Kind::kArray);
      Access::NodeOf(v).array = std::make_unique<Array>(std::move(arr));
      return v;
    }
    case Role::kDtype: {
      arity(1, 3);
      Value v = NewContainer(Kind::kObject);
      Value::Node& n = Access::NodeOf(v);
      Adopt(n, args);
      n.object = std::make_unique<Object>(Object{"numpy", "dtype", args, Value(), Object::Via::kReduce});
      InterpretDtype(v);  // refuse unsupported dtypes where they are named
      return v;
    }
    case Role::kCodecsEncode: {
      arity(1, 2);
      const std::string encoding = a.size() > 1 && a[1].kind() == Kind::kStr ? a[1].AsString() : "utf-8";
      if (encoding != "latin1" && encoding != "latin-1" && encoding != "iso-8859-1" && encoding != "iso8859-1")
        Fail(Msg() << "_codecs.encode to '" << encoding << "' (only latin-1 is supported)");
      std::string bytes;
      if (a[0].kind() != Kind::kStr || !Latin1FromUtf8(a[0].AsString(), &bytes))
        Fail("_codecs.encode of something other than a latin-1 str");
      return RawBytes(bytes);
    }
    case Role::kBytes:
    case Role::kByteArray: {
      arity(0, 2);
      if (a.empty()) return RawBytes("");
      if (a.size() == 1 && a[0].kind() == Kind::kBytes) return RawBytes(a[0].AsBytes());
      std::string bytes;
      if (a.size() == 2 && a[0].kind() == Kind::kStr && a[1].kind() == Kind::kStr &&
          (a[1].AsString() == "latin-1" || a[1].AsString() == "latin1") && Latin1FromUtf8(a[0].AsString(), &bytes))
        return RawBytes(bytes);
      Fail(Msg() << "'" << qualified << "' with unsupported arguments");
    }
    case Role::kOrderedDict: {
      arity(0, 1);
      Value d = NewContainer(Kind::kDict);
      if (a.size() == 1) {
        if (a[0].kind() != Kind::kList && a[0].kind() != Kind::kTuple) Fail("OrderedDict of something other than pairs");
        for (const Value& pair : a[0].elements()) {
          if ((pair.kind() != Kind::kList && pair.kind() != Kind::kTuple) || pair.size() != 2)
            Fail("OrderedDict of something other than pairs");
          SetItemOf(d, pair[0], pair[1]);
        }
      }
      return d;
    }
    case Role::kReconstructor:
    case Role::kNewObjFn: {
      if (a.empty()) Fail(Msg() << "'" << qualified << "' without a class");
      const Allowed& cls = RoleOf(a[0], opcode);
      if (cls.role != Role::kKeep) Fail(Msg() << "'" << qualified << "' of '" << cls.module << "." << cls.name << "'");
      std::vector<Value> rest;
      if (role.role == Role::kReconstructor) {
        arity(3, 3);
        if (a[1].kind() != Kind::kObject || RoleOf(a[1], opcode).role != Role::kObjectBase || !a[2].is_none())
          Fail("copyreg._reconstructor with a base other than object");
      } else {
        rest.assign(a.begin() + 1, a.end());
      }
      Value v = NewContainer(Kind::kObject);
      Value cls_args = MakeSequence(Kind::kTuple, std::move(rest));
      Adopt(Access::NodeOf(v), cls_args);
      Access::NodeOf(v).object = std::make_unique<Object>(
          Object{std::string(cls.module), std::string(cls.name), std::move(cls_args), Value(), Object::Via::kNewObj});
      return v;
    }
    case Role::kNdarray:
    case Role::kObjectBase:
      break;
  }
  Fail(Msg() << opcode << " of '" << qualified << "' is not supported");
}

void Machine::Build(Value& target, Value state) {
  Value::Node& n = Mutable(target, "BUILD");
  if (target.kind() == Kind::kArray && n.pending) {
    // numpy's ndarray.__setstate__: (version, shape, dtype, is_fortran, data), or the 4-tuple without version.
    if (state.kind() != Kind::kTuple || (state.size() != 5 && state.size() != 4))
      Fail("numpy array state is not (version, shape, dtype, is_fortran, data)");
    const size_t k = state.size() - 4;
    const std::vector<int64_t> shape = Shape(state[k]);
    const DtypeInfo info = InterpretDtype(state[k + 1]);
    if (state[k + 2].kind() != Kind::kBool && state[k + 2].kind() != Kind::kInt) Fail("numpy is_fortran is not a bool");
    const Value& data = state[k + 3];
    Array& a = *n.array;
    a.fortran_order = state[k + 2].AsBool();
    if (info.dtype == DType::kObject) {
      // Object arrays carry a list of their elements in C order (numpy's _getlist_pkl), whatever the layout.
      if (data.kind() != Kind::kList) Fail("numpy object array data is not a list");
      a.dtype = DType::kObject;
      a.itemsize = 8;
      a.shape = shape;
      if (static_cast<int64_t>(data.size()) != a.size())
        Fail(Msg() << "numpy object array holds " << data.size() << " elements, its shape " << a.size());
      for (const Value& e : data.elements()) Adopt(n, e);
      a.objects = data.elements();
    } else {
      FillArray(&a, info, shape, DataBytes(data, "numpy array data"));
    }
    n.pending = false;
    return;
  }
  if (target.kind() != Kind::kObject || n.object->via == Object::Via::kGlobal)
    Fail(Msg() << "BUILD on a " << KindName(target.kind()) << (target.kind() == Kind::kObject ? " class" : ""));
  if (!n.object->state.is_none()) Fail("BUILD on an object that has state already");
  Adopt(n, state);
  n.object->state = std::move(state);
  if (n.object->Is("numpy", "dtype")) InterpretDtype(target);
}

// ---------------------------------------------------------------------------------------------------------------
// The writer

class Writer {
 public:
  explicit Writer(int protocol) : proto_(protocol) {}

  std::string Finish(const Value& v) {
    out_.push_back(static_cast<char>(op::PROTO));
    out_.push_back(static_cast<char>(proto_));
    Save(v);
    out_.push_back(op::STOP);
    return std::move(out_);
  }

 private:
  void Op(uint8_t c) { out_.push_back(static_cast<char>(c)); }
  void LE(uint64_t v, int bytes) {
    for (int k = 0; k < bytes; ++k) out_.push_back(static_cast<char>((v >> (8 * k)) & 0xff));
  }
  void Put() {
    const uint32_t i = next_memo_++;
    if (proto_ >= 4) {
      Op(op::MEMOIZE);
    } else if (i < 256) {
      Op(op::BINPUT), LE(i, 1);
    } else {
      Op(op::LONG_BINPUT), LE(i, 4);
    }
  }
  void GetMemo(uint32_t i) {
    if (i < 256) Op(op::BINGET), LE(i, 1);
    else Op(op::LONG_BINGET), LE(i, 4);
  }
  // Memoised by a name, for the globals and the constants every array repeats.
  bool Recall(const std::string& key) {
    const auto it = named_.find(key);
    if (it == named_.end()) return false;
    GetMemo(it->second);
    return true;
  }
  void Remember(const std::string& key) {
    named_[key] = next_memo_;
    Put();
  }

  void Int(int64_t v) {
    if (v >= 0 && v <= 0xff) {
      Op(op::BININT1), LE(static_cast<uint64_t>(v), 1);
    } else if (v >= 0 && v <= 0xffff) {
      Op(op::BININT2), LE(static_cast<uint64_t>(v), 2);
    } else if (v >= INT32_MIN && v <= INT32_MAX) {
      Op(op::BININT), LE(static_cast<uint32_t>(static_cast<int32_t>(v)), 4);
    } else {
      // LONG1: the fewest little-endian two's-complement bytes that keep the sign (CPython's encode_long).
      int n = 8;
      while (n > 1) {
        const int64_t top = v >> (8 * (n - 1) - 1);  // the sign-relevant bits above n-1 bytes
        if (top != 0 && top != -1) break;
        --n;
      }
      Op(op::LONG1), LE(static_cast<uint64_t>(n), 1), LE(static_cast<uint64_t>(v), n);
    }
  }
  void Float(double d) {
    uint64_t bits;
    std::memcpy(&bits, &d, 8);
    Op(op::BINFLOAT);
    for (int k = 7; k >= 0; --k) out_.push_back(static_cast<char>((bits >> (8 * k)) & 0xff));
  }
  void Str(std::string_view s) {
    if (proto_ >= 4 && s.size() < 256) {
      Op(op::SHORT_BINUNICODE), LE(s.size(), 1);
    } else if (s.size() <= 0xffffffffu) {
      Op(op::BINUNICODE), LE(s.size(), 4);
    } else {
      SD_CHECK(proto_ >= 4, << "a str over 4 GiB needs protocol 4");
      Op(op::BINUNICODE8), LE(s.size(), 8);
    }
    out_.append(s);
  }
  void NamedStr(const std::string& s) {
    if (Recall("str:" + s)) return;
    Str(s);
    Remember("str:" + s);
  }
  void Bytes(std::string_view b) {
    if (proto_ >= 4) {
      if (b.size() < 256) Op(op::SHORT_BINBYTES), LE(b.size(), 1);
      else if (b.size() <= 0xffffffffu) Op(op::BINBYTES), LE(b.size(), 4);
      else Op(op::BINBYTES8), LE(b.size(), 8);
      out_.append(b);
      return;
    }
    // Protocol 2 has no bytes opcode: _codecs.encode(<the bytes as a latin-1 str>, 'latin1'), as CPython writes.
    Global("_codecs", "encode");
    Str(Utf8FromLatin1(b));
    NamedStr("latin1");
    Op(op::TUPLE2);
    Op(op::REDUCE);
  }
  void Global(std::string_view module, std::string_view name) {
    const std::string key = "global:" + std::string(module) + "." + std::string(name);
    if (Recall(key)) return;
    if (proto_ >= 4) {
      Str(module), Str(name), Op(op::STACK_GLOBAL);
    } else {
      Op(op::GLOBAL);
      out_.append(module), out_.push_back('\n'), out_.append(name), out_.push_back('\n');
    }
    Remember(key);
  }

  // numpy.dtype(typestr, False, True) + BUILD((3, byteorder, None, None, None, elsize, alignment, flags)), the
  // descr state numpy 1.x writes; one per distinct dtype (later arrays reference it through the memo).
  void Dtype(const Array& a) {
    std::string typestr;
    char byteorder = '<';
    int64_t elsize = -1, alignment = -1, flags = 0;
    switch (a.dtype) {
      case DType::kBool: typestr = "b1", byteorder = '|'; break;
      case DType::kInt8: typestr = "i1", byteorder = '|'; break;
      case DType::kUInt8: typestr = "u1", byteorder = '|'; break;
      case DType::kObject: typestr = "O8", byteorder = '|', flags = 63; break;
      case DType::kUnicode:
        typestr = "U" + std::to_string(a.itemsize / 4), elsize = a.itemsize, alignment = 4, flags = 8;
        break;
      default: {
        const char kind = IsFloat(a.dtype) ? 'f' : (a.dtype >= DType::kUInt8 && a.dtype <= DType::kUInt64 ? 'u' : 'i');
        typestr = std::string(1, kind) + std::to_string(a.itemsize);
      }
    }
    const std::string key = "dtype:" + typestr;
    if (Recall(key)) return;
    Global("numpy", "dtype");
    NamedStr(typestr);
    Op(op::NEWFALSE), Op(op::NEWTRUE), Op(op::TUPLE3), Op(op::REDUCE);
    Op(op::MARK);
    Int(3);
    NamedStr(std::string(1, byteorder));
    Op(op::NONE), Op(op::NONE), Op(op::NONE);
    Int(elsize), Int(alignment), Int(flags);
    Op(op::TUPLE), Op(op::BUILD);
    Remember(key);
  }

  void SaveArray(const Array& a) {
    SD_CHECK(a.itemsize == (a.dtype == DType::kUnicode ? a.itemsize : FixedItemSize(a.dtype)) && a.itemsize >= 0 &&
                 (a.dtype != DType::kUnicode || a.itemsize % 4 == 0),
             << "Dump: a " << DTypeName(a.dtype) << " array with itemsize " << a.itemsize);
    if (a.scalar) {
      SD_CHECK(a.dtype != DType::kObject && a.shape.empty(), << "Dump: a numpy scalar of object dtype or with a shape");
      Global("numpy.core.multiarray", "scalar");
      Dtype(a);
      Bytes(a.data);
      Op(op::TUPLE2), Op(op::REDUCE);
      return;
    }
    // numpy's ndarray.__reduce__: _reconstruct(ndarray, (0,), b'b') + BUILD((1, shape, dtype, is_fortran, data)).
    Global("numpy.core.multiarray", "_reconstruct");
    Global("numpy", "ndarray");
    Int(0), Op(op::TUPLE1);
    if (!Recall("bytes:b")) {
      Bytes("b");
      Remember("bytes:b");
    }
    Op(op::TUPLE3), Op(op::REDUCE);
    Op(op::MARK);
    Int(1);
    if (a.shape.empty()) {
      Op(op::EMPTY_TUPLE);
    } else {
      if (a.shape.size() > 3) Op(op::MARK);
      for (int64_t d : a.shape) Int(d);
      Op(a.shape.size() == 1 ? op::TUPLE1 : a.shape.size() == 2 ? op::TUPLE2 : a.shape.size() == 3 ? op::TUPLE3 : op::TUPLE);
    }
    Dtype(a);
    Op(a.fortran_order ? op::NEWTRUE : op::NEWFALSE);
    if (a.dtype == DType::kObject) {
      SaveSequence(a.objects, op::EMPTY_LIST);
    } else {
      Bytes(a.data);
    }
    Op(op::TUPLE), Op(op::BUILD);
  }

  void SaveSequence(const std::vector<Value>& items, uint8_t empty) {
    Op(empty);
    // Batches of 1000 as CPython writes them (its unpickler reads any size; this bounds the mark's stack).
    for (size_t i = 0; i < items.size(); i += 1000) {
      const size_t end = std::min(items.size(), i + 1000);
      if (end - i == 1) {
        Save(items[i]);
        Op(op::APPEND);
        continue;
      }
      Op(op::MARK);
      for (size_t k = i; k < end; ++k) Save(items[k]);
      Op(op::APPENDS);
    }
  }

  void Save(const Value& v) {
    const Value::Node* node = Access::NodePtr(v);
    // Nodes that are referenced more than once are written once and then recalled from the memo, so shared
    // values stay shared in Python too. Node addresses are stable: every node belongs to `v`'s tree, alive
    // throughout Dump, and the writer makes no Values of its own.
    const bool shared = node && Access::UseCount(v) > 1;
    if (shared) {
      const auto it = nodes_.find(node);
      if (it != nodes_.end()) {
        GetMemo(it->second);
        return;
      }
    }
    switch (v.kind()) {
      case Kind::kNone: Op(op::NONE); break;
      case Kind::kBool: Op(v.AsBool() ? op::NEWTRUE : op::NEWFALSE); break;
      case Kind::kInt: Int(v.AsInt()); break;
      case Kind::kFloat: Float(v.AsDouble()); break;
      case Kind::kStr: Str(node->text); break;
      case Kind::kBytes: Bytes(node->text); break;
      case Kind::kList: SaveSequence(node->elements, op::EMPTY_LIST); break;
      case Kind::kTuple: {
        const std::vector<Value>& e = node->elements;
        if (e.empty()) {
          Op(op::EMPTY_TUPLE);
          break;
        }
        if (e.size() > 3) Op(op::MARK);
        for (const Value& x : e) Save(x);
        Op(e.size() == 1 ? op::TUPLE1 : e.size() == 2 ? op::TUPLE2 : e.size() == 3 ? op::TUPLE3 : op::TUPLE);
        break;
      }
      case Kind::kDict: {
        Op(op::EMPTY_DICT);
        const auto& entries = node->entries;
        for (size_t i = 0; i < entries.size(); i += 1000) {
          const size_t end = std::min(entries.size(), i + 1000);
          if (end - i == 1) {
            Save(entries[i].first), Save(entries[i].second), Op(op::SETITEM);
            continue;
          }
          Op(op::MARK);
          for (size_t k = i; k < end; ++k) Save(entries[k].first), Save(entries[k].second);
          Op(op::SETITEMS);
        }
        break;
      }
      case Kind::kArray: SaveArray(*node->array); break;
      case Kind::kObject: {
        const Object& o = *node->object;
        SD_CHECK(FindAllowed(o.module, o.name), << "Dump: '" << o.module << "." << o.name
                                                << "' is not in the allow-list (we would refuse to load it)");
        Global(o.module, o.name);
        if (o.via != Object::Via::kGlobal) {
          SD_CHECK(o.args.kind() == Kind::kTuple, << "Dump: '" << o.name << "' arguments are not a tuple");
          Save(o.args);
          Op(o.via == Object::Via::kNewObj ? op::NEWOBJ : op::REDUCE);
          if (!o.state.is_none()) {
            Save(o.state);
            Op(op::BUILD);
          }
        }
        break;
      }
    }
    if (shared) {
      nodes_[node] = next_memo_;
      Put();
    }
  }

  const int proto_;
  std::string out_;
  uint32_t next_memo_ = 0;
  std::unordered_map<const Value::Node*, uint32_t> nodes_;
  std::unordered_map<std::string, uint32_t> named_;
};

std::string GzipBytes(std::string_view data) {
  z_stream z{};
  SD_CHECK(deflateInit2(&z, 6, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) == Z_OK, << "deflateInit2");
  std::string out(deflateBound(&z, static_cast<uLong>(data.size())) + 64, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = static_cast<uInt>(data.size());
  SD_CHECK(z.avail_in == data.size(), << "gzip input over 4 GiB");
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  SD_CHECK(deflate(&z, Z_FINISH) == Z_STREAM_END, << "deflate");
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

// --- ToJson

nlohmann::json ElementJson(const Array& a, int64_t i, std::string& path);
nlohmann::json Json(const Value& v, std::string& path);

nlohmann::json FloatJson(double d) { return std::isfinite(d) ? nlohmann::json(d) : nlohmann::json(nullptr); }

nlohmann::json ElementJson(const Array& a, int64_t i, std::string& path) {
  switch (a.dtype) {
    case DType::kBool: return a.At<bool>(i);
    case DType::kUInt64: return a.At<uint64_t>(i);
    case DType::kFloat16:
    case DType::kFloat32:
    case DType::kFloat64: return FloatJson(a.AsDouble(i));
    case DType::kUnicode: return a.StringAt(i);
    case DType::kObject: {
      const size_t len = path.size();
      path += "/" + std::to_string(i);
      nlohmann::json j = Json(a.ObjectAt(i), path);
      path.resize(len);
      return j;
    }
    default: return a.AsInt(i);
  }
}

nlohmann::json NestedJson(const Array& a, size_t dim, int64_t* next, std::string& path) {
  if (dim == a.shape.size()) return ElementJson(a, (*next)++, path);
  nlohmann::json j = nlohmann::json::array();
  for (int64_t k = 0; k < a.shape[dim]; ++k) j.push_back(NestedJson(a, dim + 1, next, path));
  return j;
}

std::string KeyJson(const Value& k, const std::string& path) {
  Number n;
  if (IsStringLike(k)) return k.AsString();
  if (k.kind() == Kind::kBool || (IsNumericScalar(k) && k.array().dtype == DType::kBool)) return k.AsBool() ? "true" : "false";
  if (k.kind() == Kind::kNone) return "null";
  if (AsNumber(k, &n)) {
    const bool is_float = k.kind() == Kind::kFloat || (k.kind() == Kind::kArray && IsFloat(k.array().dtype));
    if (!is_float) {
      if (k.kind() == Kind::kArray && k.array().dtype == DType::kUInt64) return std::to_string(k.array().At<uint64_t>(0));
      return std::to_string(n.i);
    }
    return PythonFloatRepr(k.AsDouble());
  }
  throw InputError({}, Msg() << (path.empty() ? "/" : path) << ": a " << KindName(k.kind())
                             << " dict key has no JSON form");
}

nlohmann::json Json(const Value& v, std::string& path) {
  const auto fail = [&](const std::string& what) -> nlohmann::json {
    throw InputError({}, Msg() << (path.empty() ? "/" : path) << ": " << what);
  };
  switch (v.kind()) {
    case Kind::kNone: return nullptr;
    case Kind::kBool: return v.AsBool();
    case Kind::kInt: return v.AsInt();
    case Kind::kFloat: return FloatJson(v.AsDouble());
    case Kind::kStr: return v.AsString();
    case Kind::kBytes: return fail("bytes have no JSON form");
    case Kind::kList:
    case Kind::kTuple: {
      nlohmann::json j = nlohmann::json::array();
      const size_t len = path.size();
      for (size_t i = 0; i < v.size(); ++i) {
        path += "/" + std::to_string(i);
        j.push_back(Json(v[i], path));
        path.resize(len);
      }
      return j;
    }
    case Kind::kDict: {
      nlohmann::json j = nlohmann::json::object();
      const size_t len = path.size();
      for (const auto& [k, x] : v.items()) {
        const std::string key = KeyJson(k, path);
        path += "/" + key;
        j[key] = Json(x, path);
        path.resize(len);
      }
      return j;
    }
    case Kind::kArray: {
      const Array& a = v.array();
      int64_t next = 0;
      return NestedJson(a, 0, &next, path);
    }
    case Kind::kObject: {
      const Object& o = v.object();
      return fail("a pickled '" + o.module + "." + o.name + "' has no JSON form");
    }
  }
  return nullptr;
}

// Argument sizes of every opcode, for ProtocolOf's scan (pickletools' table).
enum class Arg { kNone, kLine, kTwoLines, kFixed, kLen1, kLen4, kLen8, kUnknown };
struct OpInfo {
  Arg arg;
  int size;   // kFixed
  int proto;  // the protocol that introduced the opcode
};
OpInfo InfoOf(uint8_t c) {
  switch (c) {
    case op::MARK: case op::STOP: case op::POP: case op::DUP: case op::NONE: case op::REDUCE: case op::APPEND:
    case op::BUILD: case op::DICT: case op::LIST: case op::SETITEM: case op::TUPLE:
      return {Arg::kNone, 0, 0};
    case op::POP_MARK: case op::BINPERSID: case op::EMPTY_DICT: case op::APPENDS: case op::EMPTY_LIST: case op::OBJ:
    case op::EMPTY_TUPLE: case op::SETITEMS:
      return {Arg::kNone, 0, 1};
    case op::FLOAT: case op::INT: case op::LONG: case op::PERSID: case op::STRING: case op::UNICODE: case op::GET:
    case op::PUT:
      return {Arg::kLine, 0, 0};
    case op::GLOBAL: case op::INST: return {Arg::kTwoLines, 0, 0};
    case op::BININT: case op::LONG_BINGET: case op::LONG_BINPUT: return {Arg::kFixed, 4, 1};
    case op::BININT1: case op::BINGET: case op::BINPUT: return {Arg::kFixed, 1, 1};
    case op::BININT2: return {Arg::kFixed, 2, 1};
    case op::BINFLOAT: return {Arg::kFixed, 8, 1};
    case op::SHORT_BINSTRING: return {Arg::kLen1, 0, 1};
    case op::BINSTRING: case op::BINUNICODE: return {Arg::kLen4, 0, 1};
    case op::PROTO: case op::EXT1: return {Arg::kFixed, 1, 2};
    case op::EXT2: return {Arg::kFixed, 2, 2};
    case op::EXT4: return {Arg::kFixed, 4, 2};
    case op::NEWOBJ: case op::TUPLE1: case op::TUPLE2: case op::TUPLE3: case op::NEWTRUE: case op::NEWFALSE:
      return {Arg::kNone, 0, 2};
    case op::LONG1: return {Arg::kLen1, 0, 2};
    case op::LONG4: return {Arg::kLen4, 0, 2};
    case op::SHORT_BINBYTES: return {Arg::kLen1, 0, 3};
    case op::BINBYTES: return {Arg::kLen4, 0, 3};
    case op::SHORT_BINUNICODE: return {Arg::kLen1, 0, 4};
    case op::BINUNICODE8: case op::BINBYTES8: return {Arg::kLen8, 0, 4};
    case op::EMPTY_SET: case op::ADDITEMS: case op::FROZENSET: case op::NEWOBJ_EX: case op::STACK_GLOBAL:
    case op::MEMOIZE:
      return {Arg::kNone, 0, 4};
    case op::FRAME: return {Arg::kFixed, 8, 4};
    case op::BYTEARRAY8: return {Arg::kLen8, 0, 5};
    case op::NEXT_BUFFER: case op::READONLY_BUFFER: return {Arg::kNone, 0, 5};
    default: return {Arg::kUnknown, 0, 0};
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Entry points

Value Load(std::string_view bytes, const fs::path& file, const LoadOptions& options) {
  return Machine(bytes, file, options).Run();
}

Value LoadFile(const fs::path& file, const LoadOptions& options) {
  return Load(ReadMaybeGzipFile(file, options.max_bytes_decompressed), file, options);
}

int ProtocolOf(std::string_view bytes) {
  if (bytes.size() >= 2 && static_cast<uint8_t>(bytes[0]) == op::PROTO) return static_cast<uint8_t>(bytes[1]);
  int proto = 0;
  for (size_t pos = 0; pos < bytes.size();) {
    const uint8_t c = static_cast<uint8_t>(bytes[pos++]);
    const OpInfo info = InfoOf(c);
    if (info.arg == Arg::kUnknown) break;
    proto = std::max(proto, info.proto);
    if (c == op::STOP) break;
    const auto skip_len = [&](int width) {
      uint64_t n = 0;
      if (pos + width > bytes.size()) return false;
      for (int k = width - 1; k >= 0; --k) n = (n << 8) | static_cast<uint8_t>(bytes[pos + k]);
      pos += width;
      if (n > bytes.size() - pos) return false;
      pos += n;
      return true;
    };
    bool ok = true;
    switch (info.arg) {
      case Arg::kNone: break;
      case Arg::kLine:
      case Arg::kTwoLines:
        for (int line = 0; line < (info.arg == Arg::kLine ? 1 : 2) && ok; ++line) {
          const size_t nl = bytes.find('\n', pos);
          ok = nl != std::string_view::npos;
          pos = ok ? nl + 1 : bytes.size();
        }
        break;
      case Arg::kFixed: pos += info.size; break;
      case Arg::kLen1: ok = skip_len(1); break;
      case Arg::kLen4: ok = skip_len(4); break;
      case Arg::kLen8: ok = skip_len(8); break;
      case Arg::kUnknown: break;
    }
    if (!ok) break;
  }
  return std::min(proto, 1);
}

std::string Dump(const Value& v, int protocol) {
  SD_CHECK(protocol == 2 || protocol == 4, << "pickle::Dump writes protocols 2 and 4, not " << protocol);
  return Writer(protocol).Finish(v);
}

void DumpFile(const fs::path& file, const Value& v, int protocol, bool gzip) {
  const std::string bytes = Dump(v, protocol);
  WriteFileAtomic(file, gzip ? GzipBytes(bytes) : bytes);
}

nlohmann::json ToJson(const Value& v) {
  std::string path;
  return Json(v, path);
}

}  // namespace sd::pickle
