// Helpers shared by the pickle files (pickle_internal.h): UTF-8 and latin-1 text, dict keys by Python's equality.
#include "io/pickle_internal.h"

#include <cmath>
#include <cstring>
#include <functional>

namespace sd::pickle::internal {

// --- UTF-8 and the other text encodings pickles use

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
  for (unsigned char c : s) AppendUtf8(c, &out);
  return out;
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

namespace {

constexpr size_t kIndexFrom = 16;

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

}  // namespace

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

}  // namespace sd::pickle::internal
