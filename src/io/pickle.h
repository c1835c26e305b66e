#pragma once
// Python pickles as data, without Python: a reader of protocols 0-5 and a writer of protocols 2 and 4 over one
// value tree, for the dataset files Python tools leave behind (mmdet3d / OpenPCDet info .pkl, PandaSet's
// pandas .pkl.gz; pandas frames through io/pandas_frame.h).
//
// Globals are data, never code. A pickle names classes and functions (GLOBAL, STACK_GLOBAL, INST) and asks for
// them to be called (REDUCE, NEWOBJ, OBJ) or given state (BUILD); CPython imports and runs whatever is named,
// which is why unpickling an untrusted file can run `os.system`. Here nothing is ever imported or called: a
// fixed allow-list is recognised and interpreted as data, and any other global is an InputError
//   "x.pkl: byte 17: refusing to load global 'os.system' (pickles are read as data; ...)".
// The allow-list and what each entry becomes:
//   numpy.core.multiarray._reconstruct + BUILD, numpy.core.numeric._frombuffer (protocol 5)  -> kArray
//   numpy.core.multiarray.scalar                                                   -> kArray with `scalar` set
//   numpy.dtype (+ BUILD)            -> a kObject, read where an array or scalar names it (also standalone)
//   numpy.ndarray                    -> only as _reconstruct's first argument (or a bare kGlobal reference)
//   (numpy 2 spells the modules numpy._core.*; both are accepted)
//   _codecs.encode(str, 'latin1'), builtins.bytes, builtins.bytearray      -> kBytes (bytearray loses its type)
//   collections.OrderedDict                                                -> kDict
//   copyreg._reconstructor(cls, object, None), copyreg.__newobj__(cls, ...) -> kObject of cls via kNewObj
//   builtins.slice, builtins.set, builtins.frozenset                       -> kObject (set items: args[0], a list)
//   pandas: core.frame.DataFrame, core.internals.managers.BlockManager, _libs.internals._unpickle_block,
//           core.indexes.base.Index / _new_Index, core.indexes.range.RangeIndex,
//           core.indexes.numeric.Int64Index / UInt64Index / Float64Index  -> kObject (see io/pandas_frame.h)
// Protocol < 3 spellings (__builtin__, copy_reg) are mapped as CPython's fix_imports does. dtypes: bool, int8-64,
// uint8-64, float16/32/64, object ('O') and unicode ('U<n>'), any byte order; others (datetime64, complex,
// structured, bytes 'S') are refused with a located error.
//
// Untrusted input: every error is one InputError "<file>: byte <offset of the opcode>: <what>", never a crash, a
// hang or an allocation larger than the input (all declared lengths are checked against the bytes left; numpy
// data must match shape x itemsize exactly). Refused besides unknown globals: unknown opcodes, truncation, bytes
// after STOP, STOP with other than one value on the stack (or an open MARK), stack underflow and MARK misuse,
// undefined memo keys, more than LoadOptions::max_memo memo entries, nesting deeper than max_depth, ints outside
// int64, invalid UTF-8 (lone surrogates included), EXT / PERSID / NEXT_BUFFER, unhashable dict keys, and
// self-reference: a container may not be changed (APPEND, SETITEM(S), ADDITEMS, BUILD) once it has been put
// inside another value or into itself. CPython's pickler finishes every value before it is used again except in
// recursive (cyclic) structures, so this refuses exactly the cyclic pickles and keeps every loaded tree acyclic
// and at most max_depth deep (destruction, ToJson and Dump recurse safely).
//
// Value semantics: a Value behaves like an independent copy. Inside, strings, containers, arrays and objects are
// reference-counted nodes; a copy shares the node and an edit through a non-const member copies a node that is
// shared first (copy on write, one level: children stay shared). So the memo's shared references cost nothing
// and a loaded tree takes about the memory of its data. Do not store a value inside itself through
// mutable_elements() / mutable_array() / mutable_object() (the other editing calls are safe against that).
// Thread safety: like std::string (const access from many threads is fine).
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/error.h"

namespace sd::pickle {

enum class Kind { kNone, kBool, kInt, kFloat, kStr, kBytes, kList, kTuple, kDict, kArray, kObject };
enum class DType {
  kBool, kInt8, kInt16, kInt32, kInt64, kUInt8, kUInt16, kUInt32, kUInt64,
  kFloat16, kFloat32, kFloat64, kObject, kUnicode
};

const char* KindName(Kind kind);      // "list", "numpy array", ...
const char* DTypeName(DType dtype);   // numpy's names: "float64", "bool", "object", "unicode"
// Bytes per element of a fixed-size dtype; kObject: 8 (a pointer in numpy); kUnicode: 0 (4 per character).
int FixedItemSize(DType dtype);
bool IsInteger(DType dtype);          // signed or unsigned integer (not bool)
bool IsFloat(DType dtype);

class Value;
struct Array;
struct Object;

// A value tree. Kinds hold: kBool/kInt (int64)/kFloat (double) inline; kStr (UTF-8), kBytes; kList, kTuple
// (elements); kDict (entries in insertion order, keys of any hashable kind, unique by Python's equality:
// 1 == 1.0 == True); kArray (numpy ndarray or numpy scalar); kObject (an allow-listed class kept as data).
// Accessors of the wrong kind throw InputError without a file (the caller knows the file: check kind() first or
// catch and rethrow with it).
class Value {
 public:
  Value() = default;  // None
  static Value None() { return Value(); }
  static Value Bool(bool b);
  static Value Int(int64_t i);
  static Value Float(double d);
  static Value Str(std::string utf8);  // SD_CHECK: valid UTF-8
  static Value Bytes(std::string bytes);
  static Value List(std::vector<Value> elements = {});
  static Value Tuple(std::vector<Value> elements = {});
  // Later duplicates of a key replace the value and keep the first position, as a Python dict literal does.
  static Value Dict(std::vector<std::pair<Value, Value>> entries = {});  // SD_CHECK: hashable keys
  static Value FromArray(Array array);
  static Value FromObject(Object object);

  Kind kind() const { return kind_; }
  bool is_none() const { return kind_ == Kind::kNone; }
  // Numbers: AsBool takes bool, int (!= 0) and numpy bool scalars; AsInt takes int, bool and integer or bool
  // numpy scalars (and 0-d arrays; uint64 above int64 is refused); AsDouble takes all of those and floats.
  bool AsBool() const;
  int64_t AsInt() const;
  double AsDouble() const;
  // str, or a numpy unicode scalar / 0-d array (trailing NULs removed, as numpy does).
  std::string AsString() const;
  const std::string& AsBytes() const;  // bytes (and bytearray)

  // List / tuple elements, or dict entries for size().
  size_t size() const;
  const Value& operator[](size_t i) const;  // list / tuple; SD_CHECK in range
  const std::vector<Value>& elements() const;  // list / tuple
  // Dicts: the value of the str key `key`, or nullptr when absent. Hashed above a few entries.
  const Value* Find(std::string_view key) const;
  const Value* Find(const Value& key) const;  // any key kind, by Python's equality
  const std::vector<std::pair<Value, Value>>& items() const;  // insertion order

  const Array& array() const;
  const Object& object() const;

  // Editing (copy on write; all SD_CHECK the kind).
  void Append(Value v);                     // list
  void SetItem(size_t i, Value v);          // list / tuple element i
  void Set(std::string key, Value v);       // dict: replace the str key's value, or append the entry
  void Set(Value key, Value v);             // dict, any hashable key
  std::vector<Value>& mutable_elements();   // list / tuple
  Array& mutable_array();
  Object& mutable_object();

  // The shared node's address: equal for two values that share one node (a memo reference), nullptr for None,
  // bool, int and float. Only meaningful while both values are alive.
  const void* identity() const { return node_.get(); }

  // Structural equality of kind and content; floats compare bit for bit (so NaN == NaN, 0.0 != -0.0); arrays by
  // dtype, shape, scalar flag and elements in C order (memory order does not matter).
  friend bool operator==(const Value& a, const Value& b);

  struct Node;  // defined in pickle_internal.h

 private:
  friend struct Access;  // pickle_internal.h: the loader's in-place construction
  explicit Value(Kind kind) : kind_(kind) {}
  Node& MutableNode();   // copy on write

  Kind kind_ = Kind::kNone;
  union {
    bool b_;
    int64_t i_ = 0;
    double f_;
  };
  std::shared_ptr<Node> node_;
};

// A numpy ndarray, or a numpy scalar (np.float32(1.5): `scalar` set, shape empty). Element i always means the
// flat index in C (row-major) order, whatever the memory layout.
struct Array {
  DType dtype = DType::kFloat64;
  int itemsize = 8;                   // bytes per element (kUnicode: 4 x characters, UCS-4; kObject: 8)
  std::vector<int64_t> shape;         // empty for 0-d arrays and scalars
  bool fortran_order = false;         // `data` is in column-major order (numpy's is_fortran)
  bool scalar = false;
  std::string data;                   // size() x itemsize bytes, little-endian (big-endian input is swapped)
  std::vector<Value> objects;         // kObject elements (str, None, ...), size() of them, C order; data empty

  int64_t size() const;               // product of shape (1 for 0-d and scalars)
  int ndim() const { return static_cast<int>(shape.size()); }
  int64_t ByteOffset(int64_t i) const;  // where element i starts in `data`
  double AsDouble(int64_t i) const;   // any bool / integer / float dtype (uint64 and int64 rounded to double)
  int64_t AsInt(int64_t i) const;     // bool and integer dtypes (uint64 above int64: InputError)
  std::string StringAt(int64_t i) const;  // kUnicode as UTF-8 (trailing NULs removed), kObject str elements
  const Value& ObjectAt(int64_t i) const;  // kObject
  std::vector<double> ToDoubles() const;   // all elements in C order, as AsDouble
  Array ToCOrder() const;             // the same array with `data` in C order
  // Element i as stored; T must be the dtype's C++ type (bool for kBool, int8_t ... double; uint16_t holds the
  // bits of a float16). SD_CHECK.
  template <typename T>
  T At(int64_t i) const;

  // Zero-filled C-order array; kUnicode takes `chars` characters per element, kObject holds None elements.
  static Array Zeros(DType dtype, std::vector<int64_t> shape, int chars = 0);
  // A C-order array of `values` (shape {n} when empty); T as for At (not kFloat16).
  template <typename T>
  static Array Of(const std::vector<T>& values, std::vector<int64_t> shape = {});
  static Array Objects(std::vector<Value> values, std::vector<int64_t> shape = {});
  static Array Unicode(const std::vector<std::string>& utf8, std::vector<int64_t> shape = {});  // chars: longest
  template <typename T>
  static Array Scalar(T value);      // np.float32(1.5) is Array::Scalar(1.5f)
};

// An instance (or, via kGlobal, the bare name) of an allow-listed class, kept as data: nothing is constructed.
struct Object {
  enum class Via {
    kReduce,   // module.name(*args), then BUILD(state) when state is not None
    kNewObj,   // cls.__new__(cls, *args) (NEWOBJ; also copyreg._reconstructor / __newobj__), then BUILD
    kGlobal,   // the class or function itself (e.g. pandas' _new_Index(Index, ...) names Index); args None
  };
  std::string module, name;  // e.g. "pandas.core.frame", "DataFrame"
  Value args;                // a tuple (None for kGlobal)
  Value state;               // what BUILD set; None when none
  Via via = Via::kReduce;

  bool Is(std::string_view module_name, std::string_view class_name) const {
    return module == module_name && name == class_name;
  }
};

struct LoadOptions {
  int max_depth = 200;               // container nesting (a list of lists is 2 deep)
  size_t max_memo = size_t(1) << 24;  // memo entries
  size_t max_bytes_decompressed = size_t(2) << 30;  // LoadFile: size of the pickle once gunzipped
};

// Parses one pickle (all of `bytes`). `file` only names errors.
Value Load(std::string_view bytes, const std::filesystem::path& file, const LoadOptions& options = {});
// The file's pickle, gunzipped first when it starts with the gzip magic (PandaSet's .pkl.gz).
Value LoadFile(const std::filesystem::path& file, const LoadOptions& options = {});
// The PROTO opcode's number; without one (protocols 0 and 1 have none) 1 when any opcode is binary, else 0.
int ProtocolOf(std::string_view bytes);

// A pickle of `v` in protocol 2 or 4 (others: SD_CHECK) that CPython's pickle.load reads to an equal value:
// numpy arrays as numpy writes them (_reconstruct + BUILD; raw data through _codecs.encode in protocol 2 and
// BINBYTES in 4), numpy scalars through numpy.core.multiarray.scalar with their dtype, objects by REDUCE or
// NEWOBJ as recorded (SD_CHECK: the class is in the allow-list, so we never write what we would refuse), shared
// nodes once plus memo references. No FRAME opcodes (optional in protocol 4).
std::string Dump(const Value& v, int protocol);
// Dump to a file atomically (io/files.h WriteFileAtomic), gzip-compressed when `gzip`.
void DumpFile(const std::filesystem::path& file, const Value& v, int protocol, bool gzip);

// The JSON twin of a pickle, as the repo's .json copies of .pkl files were made: dicts and lists kept, tuples ->
// lists, arrays -> nested lists of their shape (0-d arrays and scalars -> the number), numbers stay int / float /
// bool, NaN and +-Inf -> null, str stays str; dict keys as Python's json.dump writes them (str; int -> "12";
// float -> repr, "NaN", "Infinity"; bool -> "true"; None -> "null"). bytes, objects (DataFrames, sets, dtypes, ...)
// and other keys throw InputError naming the value's JSON pointer ("/infos/0/foo: bytes have no JSON form").
// Object keys come out in nlohmann::json's (sorted) order.
nlohmann::json ToJson(const Value& v);

// --- implementation of the templates

namespace detail {
template <typename T>
constexpr DType DTypeOf();
template <> constexpr DType DTypeOf<bool>() { return DType::kBool; }
template <> constexpr DType DTypeOf<int8_t>() { return DType::kInt8; }
template <> constexpr DType DTypeOf<int16_t>() { return DType::kInt16; }
template <> constexpr DType DTypeOf<int32_t>() { return DType::kInt32; }
template <> constexpr DType DTypeOf<int64_t>() { return DType::kInt64; }
template <> constexpr DType DTypeOf<uint8_t>() { return DType::kUInt8; }
template <> constexpr DType DTypeOf<uint16_t>() { return DType::kUInt16; }
template <> constexpr DType DTypeOf<uint32_t>() { return DType::kUInt32; }
template <> constexpr DType DTypeOf<uint64_t>() { return DType::kUInt64; }
template <> constexpr DType DTypeOf<float>() { return DType::kFloat32; }
template <> constexpr DType DTypeOf<double>() { return DType::kFloat64; }
}  // namespace detail

template <typename T>
T Array::At(int64_t i) const {
  SD_CHECK(detail::DTypeOf<T>() == dtype || (dtype == DType::kFloat16 && std::is_same_v<T, uint16_t>),
           << "Array::At<" << sizeof(T) << " bytes> of a " << DTypeName(dtype) << " array");
  if constexpr (std::is_same_v<T, bool>) {
    return data[static_cast<size_t>(ByteOffset(i))] != 0;
  } else {
    T v;
    std::memcpy(&v, data.data() + ByteOffset(i), sizeof(T));
    return v;
  }
}

template <typename T>
Array Array::Of(const std::vector<T>& values, std::vector<int64_t> shape) {
  Array a;
  a.dtype = detail::DTypeOf<T>();
  a.itemsize = static_cast<int>(sizeof(T));
  a.shape = shape.empty() ? std::vector<int64_t>{static_cast<int64_t>(values.size())} : std::move(shape);
  SD_CHECK(a.size() == static_cast<int64_t>(values.size()), << "Array::Of: shape does not hold the values");
  a.data.resize(values.size() * sizeof(T));
  for (size_t i = 0; i < values.size(); ++i) {
    const T v = values[i];
    std::memcpy(a.data.data() + i * sizeof(T), &v, sizeof(T));
  }
  return a;
}

template <typename T>
Array Array::Scalar(T value) {
  Array a = Of(std::vector<T>{value}, {1});
  a.shape.clear();
  a.scalar = true;
  return a;
}

}  // namespace sd::pickle
