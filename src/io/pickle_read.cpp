// The unpickling machine's opcodes (CPython's pickle virtual machine over Values); Load, LoadFile and ProtocolOf.
#include "io/pickle_internal.h"

#include <algorithm>
#include <charconv>
#include <cstring>

#include "io/gzip.h"

namespace sd::pickle {
using namespace internal;

namespace internal {

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
      AppendUtf8(static_cast<unsigned char>(s[i++]), &out);
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
    AppendUtf8(cp, &out);
    i += 1 + digits;
  }
  return Text(out);
}

}  // namespace internal

namespace {

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

}  // namespace sd::pickle
