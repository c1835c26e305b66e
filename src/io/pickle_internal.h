#pragma once
// Internals shared by the pickle implementation files; not part of the public interface (that is io/pickle.h).
//   pickle.cpp              the value model: Kind / DType names, Value, Array
//   pickle_internal.cpp     the text and dict-key helpers below (UTF-8, latin-1; Python's key equality and hash)
//   pickle_read.cpp         the unpickling machine's opcodes; Load, LoadFile, ProtocolOf
//   pickle_reconstruct.cpp  the allow-list of globals and what the machine makes of them (calls and BUILD)
//   pickle_write.cpp        the writer; Dump, DumpFile; ToJson
#include <algorithm>
#include <charconv>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/utf8.h"
#include "io/pickle.h"

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

namespace internal {

// --- UTF-8 and the other text encodings pickles use (pickle_internal.cpp)

inline bool IsScalarValue(uint32_t cp) { return cp <= 0x10ffff && (cp < 0xd800 || cp > 0xdfff); }
bool NextCodePoint(std::string_view s, size_t* i, uint32_t* cp);  // false for invalid UTF-8
bool ValidUtf8(std::string_view s);
std::string Utf8FromLatin1(std::string_view s);

// --- dict keys: Python's equality and a hash consistent with it (pickle_internal.cpp)

bool IsNumericScalar(const Value& v);  // a numpy bool / number scalar or 0-d array
bool IsStringLike(const Value& v);     // a str or a numpy unicode scalar / 0-d array

// A number as Python compares it: an exact int64 when integral and in range, else a double.
struct Number {
  bool integral;
  int64_t i;
  double d;
};

bool AsNumber(const Value& v, Number* n);  // false for values that are not numbers
bool Hashable(const Value& k);
ptrdiff_t DictFind(const Value::Node& n, const Value& key);  // the position of an equal key, or -1
void DictInsert(Value::Node& n, Value key, Value v);  // Python's d[key] = v; the key is hashable

// --- the allow-list (pickle_reconstruct.cpp)

struct Allowed;    // an allow-list entry: module, name and role
struct DtypeInfo;  // a numpy dtype as the loader reads it
const Allowed* FindAllowed(std::string_view module, std::string_view name);  // nullptr when not allowed

// ---------------------------------------------------------------------------------------------------------------
// The loader: CPython's pickle virtual machine (Lib/pickle.py, _Unpickler) over Values.
// Machine::Run and the opcodes are in pickle_read.cpp (the writer uses `op` too); Global, Call, Build and the
// numpy helpers in pickle_reconstruct.cpp.

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

}  // namespace internal
}  // namespace sd::pickle
