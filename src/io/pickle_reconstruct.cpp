// The allow-list of globals and what the machine makes of them: GLOBAL, the calls and BUILD (numpy, bytes, pandas).
#include "io/pickle_internal.h"

#include <algorithm>
#include <charconv>
#include <cstring>

namespace sd::pickle::internal {

// ---------------------------------------------------------------------------------------------------------------
// The allow-list

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

namespace {

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

}  // namespace

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

namespace {

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

// --- byte order

void SwapEach(std::string* data, int unit) {
  if (unit <= 1) return;
  for (size_t i = 0; i + unit <= data->size(); i += unit) std::reverse(data->begin() + i, data->begin() + i + unit);
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Globals, calls and BUILD: the machine's side of the allow-list

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

}  // namespace sd::pickle::internal
