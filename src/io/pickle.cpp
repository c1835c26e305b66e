// The pickle value model (io/pickle.h): Kind and DType names, Value (copy-on-write nodes) and the numpy Array.
#include "io/pickle.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "io/pickle_internal.h"

namespace sd::pickle {
using namespace internal;

namespace {

uint32_t HeightOf(const Value& v) {
  const Value::Node* n = Access::NodePtr(v);
  return n ? n->height : 0;
}

[[noreturn]] void WrongKind(const Value& v, const char* wanted) {
  throw InputError({}, Msg() << "pickle value is a " << KindName(v.kind()) << ", not " << wanted);
}

// --- float16

double HalfToDouble(uint16_t h) {
  const int sign = h >> 15, exp = (h >> 10) & 0x1f, frac = h & 0x3ff;
  double v;
  if (exp == 0) v = std::ldexp(frac, -24);                                   // subnormal
  else if (exp == 31) v = frac ? std::numeric_limits<double>::quiet_NaN() : std::numeric_limits<double>::infinity();
  else v = std::ldexp(frac + 1024, exp - 25);
  return sign ? -v : v;
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
    AppendUtf8(IsScalarValue(cp) ? cp : 0xfffd, &out);
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

}  // namespace sd::pickle
