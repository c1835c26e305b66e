// The pickle writer (Dump, DumpFile: protocols 2 and 4, optionally gzipped) and ToJson, a value's JSON twin.
#include "io/pickle_internal.h"

#include <zlib.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <unordered_map>

#include "io/files.h"

namespace sd::pickle {
using namespace internal;

namespace {

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

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Entry points

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
