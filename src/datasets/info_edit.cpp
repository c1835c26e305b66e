// WriteInfoEdit (datasets/internal.h): a frame edit's additions applied to the mmdet3d info the log was read
// from, for every info layout (nuScenes-like v1/v0 in mmdet3d.cpp, KITTI-flavoured in mmdet3d_kitti.cpp). A
// JSON info keeps its bytes: the additions are spliced into its text, so every record they do not extend is
// unchanged. A pickle info gets them added to its value tree, typed like their neighbours (numpy dtypes, string
// widths), so mmdet3d's loaders read them as they read the originals.
#include <algorithm>
#include <cstring>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "core/error.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/gzip.h"
#include "io/json.h"
#include "io/pickle.h"
#include "io/raw_json.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

using namespace datasets_internal;


namespace {

fs::path InfoOutPath(const Log& log, const fs::path& out_dir) {
  return out_dir / RelativePath(fs::absolute(log.annotation_path), fs::absolute(log.data_root));
}

Items AsItems(const std::vector<ojson>& values) {
  Items items;
  for (const ojson& v : values) items.push_back({"", v});
  return items;
}

// The lists of a record edit, grouped: each entry is one list of the record (path size 1) or all lists under
// one parent (path size 2), in order of first use; empty lists dropped (nothing to add, nothing created).
std::vector<std::vector<const InfoListEdit*>> Groups(const InfoRecordEdit& re) {
  std::vector<std::vector<const InfoListEdit*>> groups;
  std::map<std::string, size_t> parent_group;
  for (const InfoListEdit& le : re.lists) {
    SD_CHECK(le.path.size() == 1 || le.path.size() == 2, << "InfoListEdit paths are 1 or 2 keys long");
    if (le.items.empty()) continue;
    if (le.path.size() == 1) {
      groups.push_back({&le});
      continue;
    }
    auto [it, added] = parent_group.emplace(le.path[0], groups.size());
    if (added) groups.emplace_back();
    groups[it->second].push_back(&le);
  }
  return groups;
}

// --- JSON text

// The record list's elements; InputError unless there is one per frame of the log (the readers keep them 1:1).
std::vector<Span> TextRecords(const Log& log, const RawJson& raw, const char* key, Span* list) {
  if (*key == '\0') {
    if (!raw.IsArray(raw.Root())) throw InputError(log.annotation_path, "the info is not a list of records");
    *list = raw.Root();
  } else {
    const std::optional<RawMember> m = raw.IsObject(raw.Root()) ? raw.Member(raw.Root(), key) : std::nullopt;
    if (!m || !raw.IsArray(m->value)) throw InputError(log.annotation_path, Msg() << key << " is not an array");
    *list = m->value;
  }
  std::vector<Span> records = raw.Elements(*list);
  const char* what = *key ? key : "the info";
  if (records.size() != log.frames.size())
    throw InputError(log.annotation_path,
                     Msg() << what << " has " << records.size() << " records, the log " << log.frames.size() << " frames");
  for (const Span& r : records)
    if (!raw.IsObject(r)) throw InputError(log.annotation_path, Msg() << what << " holds a record that is not an object");
  return records;
}

// `items` inserted before element `at` (< its size) of the array `arr`, separated and indented like the
// elements already there.
Splice InsertItems(const RawJson& raw, Span arr, size_t at, const Items& items, const JsonStyle& s) {
  const std::vector<Span> have = raw.Elements(arr);
  const std::string lead(raw.Text({arr.begin + 1, have[0].begin}));
  const std::string sep = have.size() >= 2 ? std::string(raw.Text({have[0].end, have[1].begin}))
                          : lead.find('\n') != std::string::npos ? "," + lead
                          : s.unit.empty() ? s.item_sep : ",";
  const size_t nl = sep.rfind('\n');
  const std::string indent = nl == std::string::npos ? raw.LineIndent(have[at].begin) : sep.substr(nl + 1);
  std::string text;
  for (const auto& kv : items) text += Serialize(kv.second, s, indent) + sep;
  return {have[at].begin, have[at].begin, text};
}

// ExtendMember for one list edit, or an insertion where it asks for one inside the existing list.
void ExtendList(const RawJson& raw, Span obj, const std::string& key, const InfoListEdit& le, const JsonStyle& s,
                std::vector<Splice>* splices, Items* new_members) {
  if (le.insert_at) {
    const std::optional<RawMember> m = raw.Member(obj, key);
    if (m && raw.IsArray(m->value) && *le.insert_at < raw.Elements(m->value).size()) {
      splices->push_back(InsertItems(raw, m->value, *le.insert_at, AsItems(le.items), s));
      return;
    }
  }
  ExtendMember(raw, obj, key, AsItems(le.items), false, s, splices, new_members);
}

std::string EditedRecordText(const RawJson& raw, Span rec, const InfoRecordEdit& re, const JsonStyle& style) {
  std::vector<Splice> splices;
  Items new_members;
  for (const std::vector<const InfoListEdit*>& group : Groups(re)) {
    const InfoListEdit& first = *group[0];
    if (first.path.size() == 1) {
      ExtendList(raw, rec, first.path[0], first, style, &splices, &new_members);
      continue;
    }
    const std::optional<RawMember> m = raw.Member(rec, first.path[0]);
    if (m && raw.IsObject(m->value)) {
      Items new_children;
      for (const InfoListEdit* le : group) ExtendList(raw, m->value, le->path[1], *le, style, &splices, &new_children);
      if (!new_children.empty()) splices.push_back(AppendItems(raw, m->value, new_children, style));
    } else {
      Items by_child;
      for (const InfoListEdit* le : group) by_child.push_back({le->path[1], ArrayOf(AsItems(le->items))});
      ExtendMember(raw, rec, first.path[0], by_child, true, style, &splices, &new_members);
    }
  }
  if (!new_members.empty()) splices.push_back(AppendItems(raw, rec, new_members, style));
  return ApplySplices(raw, rec, splices);
}

// New class names go where the metainfo keeps its class list (categories {name: index}, classes, CLASSES).
void AddV1Classes(const RawJson& raw, const std::vector<std::string>& new_names, size_t first_index, const JsonStyle& s,
                  std::vector<Splice>* splices) {
  if (new_names.empty()) return;
  Items by_index, names;
  for (size_t k = 0; k < new_names.size(); ++k) {
    by_index.push_back({new_names[k], static_cast<int>(first_index + k)});
    names.push_back({"", new_names[k]});
  }
  const Span root = raw.Root();
  const std::optional<RawMember> meta = raw.Member(root, "metainfo");
  Items top;
  if (!meta || !raw.IsObject(meta->value)) {
    ExtendMember(raw, root, "metainfo", {{"categories", ObjectOf(by_index)}}, true, s, splices, &top);
    if (!top.empty()) splices->push_back(AppendItems(raw, root, top, s));
    return;
  }
  const std::optional<RawMember> cats = raw.Member(meta->value, "categories");
  Items added;
  if (cats && raw.IsObject(cats->value)) splices->push_back(AppendItems(raw, cats->value, by_index, s));
  else if (raw.Member(meta->value, "classes")) ExtendMember(raw, meta->value, "classes", names, false, s, splices, &added);
  else if (raw.Member(meta->value, "CLASSES")) ExtendMember(raw, meta->value, "CLASSES", names, false, s, splices, &added);
  else ExtendMember(raw, meta->value, "categories", by_index, true, s, splices, &added);
  if (!added.empty()) splices->push_back(AppendItems(raw, meta->value, added, s));
}

void WriteInfoText(const Log& log, const InfoEdit& edit, const fs::path& dst) {
  const RawJson raw(ReadFileToString(log.annotation_path), log.annotation_path);
  const JsonStyle style = raw.Style();
  Span list;
  const std::vector<Span> records = TextRecords(log, raw, edit.list_key, &list);
  std::vector<std::string> kept;
  for (const InfoRecordEdit& re : edit.records) kept.push_back(EditedRecordText(raw, records.at(re.record), re, style));
  std::vector<Splice> splices;
  if (raw.IsObject(raw.Root())) AddV1Classes(raw, edit.new_classes, edit.first_class_index, style, &splices);
  splices.push_back({list.begin, list.end, ArrayWith(raw, list, records, kept, style)});
  WriteFileAtomic(dst, ApplySplices(raw, {0, raw.text().size()}, splices));
}

// --- pickle

using pickle::Array;
using pickle::DType;
using pickle::Kind;
using pickle::Value;

Value PlainValue(const ojson& v) {
  switch (v.type()) {
    case ojson::value_t::null: return Value::None();
    case ojson::value_t::boolean: return Value::Bool(v.get<bool>());
    case ojson::value_t::number_integer:
    case ojson::value_t::number_unsigned: return Value::Int(v.get<int64_t>());
    case ojson::value_t::number_float: return Value::Float(v.get<double>());
    case ojson::value_t::string: return Value::Str(v.get<std::string>());
    case ojson::value_t::array: {
      std::vector<Value> elements;
      for (const ojson& e : v) elements.push_back(PlainValue(e));
      return Value::List(std::move(elements));
    }
    case ojson::value_t::object: {
      Value d = Value::Dict();
      for (auto it = v.begin(); it != v.end(); ++it) d.Set(it.key(), PlainValue(it.value()));
      return d;
    }
    default: break;
  }
  SD_CHECK(false, << "an added value has no pickle form: " << v.dump());
  return {};
}

// Number of code points of a UTF-8 string (what a numpy unicode element holds).
int64_t CodePoints(const std::string& utf8) {
  int64_t n = 0;
  for (unsigned char c : utf8) n += (c & 0xC0) != 0x80;
  return n;
}

// Writes `v` as element i of the C-order array `a`, in a's dtype (unicode: a is wide enough).
void PutElement(Array* a, int64_t i, const ojson& v, const fs::path& file) {
  const auto put = [&](auto x) { std::memcpy(a->data.data() + i * a->itemsize, &x, sizeof(x)); };
  const auto integer = [&]() -> int64_t {
    if (v.is_boolean()) return v.get<bool>() ? 1 : 0;
    if (v.is_number_integer()) return v.get<int64_t>();
    if (v.is_number_float()) return std::llround(v.get<double>());
    throw InputError(file, Msg() << "a " << pickle::DTypeName(a->dtype) << " numpy value cannot hold " << v.dump());
  };
  const auto real = [&]() -> double {
    if (v.is_number()) return v.get<double>();
    if (v.is_boolean()) return v.get<bool>() ? 1 : 0;
    throw InputError(file, Msg() << "a " << pickle::DTypeName(a->dtype) << " numpy value cannot hold " << v.dump());
  };
  switch (a->dtype) {
    case DType::kBool: a->data[static_cast<size_t>(i)] = integer() != 0; return;
    case DType::kInt8: put(static_cast<int8_t>(integer())); return;
    case DType::kInt16: put(static_cast<int16_t>(integer())); return;
    case DType::kInt32: put(static_cast<int32_t>(integer())); return;
    case DType::kInt64: put(static_cast<int64_t>(integer())); return;
    case DType::kUInt8: put(static_cast<uint8_t>(integer())); return;
    case DType::kUInt16: put(static_cast<uint16_t>(integer())); return;
    case DType::kUInt32: put(static_cast<uint32_t>(integer())); return;
    case DType::kUInt64: put(static_cast<uint64_t>(integer())); return;
    case DType::kFloat32: put(static_cast<float>(real())); return;
    case DType::kFloat64: put(real()); return;
    case DType::kObject: a->objects[static_cast<size_t>(i)] = PlainValue(v); return;
    case DType::kUnicode: {
      if (!v.is_string()) throw InputError(file, Msg() << "a unicode numpy value cannot hold " << v.dump());
      const Array u = Array::Unicode({v.get<std::string>()});
      SD_CHECK(u.itemsize <= a->itemsize, << "unicode element wider than its array");
      std::memcpy(a->data.data() + i * a->itemsize, u.data.data(), static_cast<size_t>(u.itemsize));
      return;
    }
    case DType::kFloat16: break;
  }
  throw InputError(file, "adding to float16 numpy values is not supported");
}

// The leaves of a JSON value in C order and the shape of its nesting (a number: shape {}); false when ragged.
bool Flatten(const ojson& v, std::vector<const ojson*>* leaves, std::vector<int64_t>* shape, size_t depth = 0) {
  if (!v.is_array()) {
    if (depth == 0) shape->clear();
    leaves->push_back(&v);
    return depth == shape->size();
  }
  if (depth == shape->size()) shape->push_back(static_cast<int64_t>(v.size()));
  else if ((*shape)[depth] != static_cast<int64_t>(v.size())) return false;
  for (const ojson& e : v)
    if (!Flatten(e, leaves, shape, depth + 1)) return false;
  return !v.empty() || depth + 1 == shape->size();
}

int64_t LongestString(const std::vector<const ojson*>& leaves) {
  int64_t n = 0;
  for (const ojson* l : leaves)
    if (l->is_string()) n = std::max(n, CodePoints(l->get<std::string>()));
  return n;
}

// An added value typed like `like`, an existing value in the same place of a neighbouring element: a numpy
// scalar or array of its dtype, a list / tuple / dict whose elements are typed like its elements, a float where
// it is a float; anything else (no neighbour, another kind) as plain Python values.
Value ValueLike(const ojson& v, const Value* like, const fs::path& file) {
  if (!like) return PlainValue(v);
  switch (like->kind()) {
    case Kind::kArray: {
      const Array& l = like->array();
      std::vector<const ojson*> leaves;
      std::vector<int64_t> shape;
      const bool nested = v.is_array();
      if ((l.scalar || l.ndim() == 0) == nested || !Flatten(v, &leaves, &shape)) return PlainValue(v);
      if (l.dtype == DType::kObject) {
        std::vector<Value> objects;
        for (const ojson* x : leaves) objects.push_back(PlainValue(*x));
        Array a = Array::Objects(std::move(objects), shape.empty() ? std::vector<int64_t>{1} : shape);
        if (!nested) a.shape.clear(), a.scalar = l.scalar;
        return Value::FromArray(std::move(a));
      }
      const int chars = static_cast<int>(std::max<int64_t>(l.itemsize / 4, LongestString(leaves)));
      Array a = Array::Zeros(l.dtype, shape, l.dtype == DType::kUnicode ? chars : 0);
      a.scalar = l.scalar;
      for (size_t i = 0; i < leaves.size(); ++i) PutElement(&a, static_cast<int64_t>(i), *leaves[i], file);
      return Value::FromArray(std::move(a));
    }
    case Kind::kList:
    case Kind::kTuple: {
      if (!v.is_array()) return PlainValue(v);
      const std::vector<Value>& le = like->elements();
      std::vector<Value> elements;
      for (size_t i = 0; i < v.size(); ++i)
        elements.push_back(ValueLike(v[i], le.empty() ? nullptr : &le[std::min(i, le.size() - 1)], file));
      return like->kind() == Kind::kList ? Value::List(std::move(elements)) : Value::Tuple(std::move(elements));
    }
    case Kind::kDict: {
      if (!v.is_object()) return PlainValue(v);
      Value d = Value::Dict();
      for (auto it = v.begin(); it != v.end(); ++it) d.Set(it.key(), ValueLike(it.value(), like->Find(it.key()), file));
      return d;
    }
    case Kind::kFloat:
      if (v.is_number()) return Value::Float(v.get<double>());
      break;
    default: break;
  }
  return PlainValue(v);
}

// The numpy column `column` with `rows` inserted before row `at` (appended past the end), as np.insert along
// axis 0: dtype kept, unicode widened to the longest string. An empty 1-d column (np.array([])) takes the rows'
// shape.
Array InsertRows(const Array& column, size_t at, const std::vector<ojson>& rows, const fs::path& file, const std::string& what) {
  const Array col = column.ToCOrder();
  if (col.scalar || col.ndim() == 0) throw InputError(file, what + ": a numpy scalar, not a column");
  std::vector<int64_t> row_shape(col.shape.begin() + 1, col.shape.end());
  const int64_t n = col.shape[0];
  std::vector<const ojson*> leaves;
  for (size_t r = 0; r < rows.size(); ++r) {
    std::vector<const ojson*> row_leaves;
    std::vector<int64_t> shape;
    if (!Flatten(rows[r], &row_leaves, &shape)) throw InputError(file, what + ": an added row is ragged");
    if (r == 0 && n == 0 && col.ndim() == 1) row_shape = shape;
    if (shape != row_shape)
      throw InputError(file, Msg() << what << ": an added row's shape differs from the column's rows (" << shape.size()
                                   << " dimensions)");
    leaves.insert(leaves.end(), row_leaves.begin(), row_leaves.end());
  }
  int64_t row_size = 1;
  for (int64_t d : row_shape) row_size *= d;
  const int64_t k = static_cast<int64_t>(rows.size()), pos = static_cast<int64_t>(std::min(at, static_cast<size_t>(n)));
  std::vector<int64_t> shape = {n + k};
  shape.insert(shape.end(), row_shape.begin(), row_shape.end());
  const int chars = static_cast<int>(std::max<int64_t>(col.itemsize / 4, LongestString(leaves)));
  Array out = Array::Zeros(col.dtype, shape, col.dtype == DType::kUnicode ? chars : 0);
  // Old element e goes to e (before the insertion) or e + k rows (after); unicode elements keep their code
  // points in the (maybe) wider slot, the rest NUL as numpy pads.
  for (int64_t e = 0; e < n * row_size; ++e) {
    const int64_t to = e < pos * row_size ? e : e + k * row_size;
    if (col.dtype == DType::kObject) out.objects[static_cast<size_t>(to)] = col.objects[static_cast<size_t>(e)];
    else std::memcpy(out.data.data() + to * out.itemsize, col.data.data() + e * col.itemsize, static_cast<size_t>(col.itemsize));
  }
  for (size_t i = 0; i < leaves.size(); ++i) PutElement(&out, pos * row_size + static_cast<int64_t>(i), *leaves[i], file);
  return out;
}

const Value* At(const Value& v, const std::string& key) { return v.kind() == Kind::kDict ? v.Find(key) : nullptr; }

// The first element of the list at `path` of a record, nullptr when there is none.
const Value* FirstElement(const Value& rec, const std::vector<std::string>& path) {
  const Value* v = &rec;
  for (const std::string& key : path)
    if (!(v = At(*v, key))) return nullptr;
  if ((v->kind() == Kind::kList || v->kind() == Kind::kTuple) && v->size() > 0) return &(*v)[0];
  return nullptr;
}

// What an added element is typed like: the first element of the same list in this record, else in another
// record, else (cam_instances.<CAM>) of a sibling list under the same parent.
const Value* Neighbour(const Value& rec, const std::vector<Value>& records, const std::vector<std::string>& path) {
  if (const Value* n = FirstElement(rec, path)) return n;
  for (const Value& r : records)
    if (const Value* n = FirstElement(r, path)) return n;
  if (path.size() != 2) return nullptr;
  const auto sibling = [&](const Value& r) -> const Value* {
    const Value* parent = At(r, path[0]);
    if (!parent || parent->kind() != Kind::kDict) return nullptr;
    for (const auto& [key, child] : parent->items())
      if ((child.kind() == Kind::kList || child.kind() == Kind::kTuple) && child.size() > 0) return &child[0];
    return nullptr;
  };
  if (const Value* n = sibling(rec)) return n;
  for (const Value& r : records)
    if (const Value* n = sibling(r)) return n;
  return nullptr;
}

// `container` (a list, tuple or numpy column; nullptr or None when the record lacks it) with the edit's items.
Value ExtendedList(const Value* container, const InfoListEdit& le, const Value* neighbour, const fs::path& file) {
  std::string what;
  for (const std::string& p : le.path) what += (what.empty() ? "" : ".") + p;
  if (!container || container->is_none()) {
    if (le.column_dtype)
      return Value::FromArray(InsertRows(Array::Zeros(*le.column_dtype, {0}, 0), 0, le.items, file, what));
    std::vector<Value> elements;
    for (const ojson& v : le.items) elements.push_back(ValueLike(v, neighbour, file));
    return Value::List(std::move(elements));
  }
  if (container->kind() == Kind::kArray)
    return Value::FromArray(InsertRows(container->array(), le.insert_at.value_or(SIZE_MAX), le.items, file, what));
  if (container->kind() != Kind::kList && container->kind() != Kind::kTuple)
    throw InputError(file, Msg() << what << " is a " << pickle::KindName(container->kind()) << ", not a list or numpy column");
  std::vector<Value> elements = container->elements();
  std::vector<Value> added;
  for (const ojson& v : le.items) added.push_back(ValueLike(v, neighbour, file));
  const size_t pos = std::min(le.insert_at.value_or(SIZE_MAX), elements.size());
  elements.insert(elements.begin() + static_cast<std::ptrdiff_t>(pos), added.begin(), added.end());
  return container->kind() == Kind::kList ? Value::List(std::move(elements)) : Value::Tuple(std::move(elements));
}

Value EditedRecordValue(const Value& in, const std::vector<Value>& records, const InfoRecordEdit& re, const fs::path& file) {
  Value rec = in;
  for (const std::vector<const InfoListEdit*>& group : Groups(re)) {
    const InfoListEdit& first = *group[0];
    if (first.path.size() == 1) {
      rec.Set(first.path[0], ExtendedList(At(in, first.path[0]), first, Neighbour(in, records, first.path), file));
      continue;
    }
    const Value* parent_in = At(in, first.path[0]);
    const bool have = parent_in && parent_in->kind() == Kind::kDict;
    Value parent = have ? *parent_in : Value::Dict();
    for (const InfoListEdit* le : group)
      parent.Set(le->path[1], ExtendedList(have ? parent_in->Find(le->path[1]) : nullptr, *le, Neighbour(in, records, le->path), file));
    rec.Set(first.path[0], std::move(parent));
  }
  return rec;
}

Value StrList(const Value* existing, const std::vector<std::string>& names) {
  std::vector<Value> elements;
  if (existing && (existing->kind() == Kind::kList || existing->kind() == Kind::kTuple)) elements = existing->elements();
  for (const std::string& n : names) elements.push_back(Value::Str(n));
  return existing && existing->kind() == Kind::kTuple ? Value::Tuple(std::move(elements)) : Value::List(std::move(elements));
}

// AddV1Classes on the value tree, with the same choices.
void AddPickleClasses(Value* root, const std::vector<std::string>& names, size_t first_index) {
  if (names.empty()) return;
  Value by_index = Value::Dict();
  for (size_t k = 0; k < names.size(); ++k) by_index.Set(names[k], Value::Int(static_cast<int64_t>(first_index + k)));
  const Value* meta_in = At(*root, "metainfo");
  if (!meta_in || meta_in->kind() != Kind::kDict) {
    root->Set("metainfo", Value::Dict({{Value::Str("categories"), by_index}}));
    return;
  }
  Value meta = *meta_in;
  const Value* cats = meta_in->Find("categories");
  if (cats && cats->kind() == Kind::kDict) {
    Value c = *cats;
    for (const auto& [name, index] : by_index.items()) c.Set(name, index);
    meta.Set("categories", std::move(c));
  } else if (const Value* classes = meta_in->Find("classes")) {
    meta.Set("classes", StrList(classes, names));
  } else if (const Value* upper = meta_in->Find("CLASSES")) {
    meta.Set("CLASSES", StrList(upper, names));
  } else {
    meta.Set("categories", by_index);
  }
  root->Set("metainfo", std::move(meta));
}

void WriteInfoPickle(const Log& log, const InfoEdit& edit, const fs::path& dst) {
  const fs::path& file = log.annotation_path;
  const std::string stored = ReadFileToString(file);
  const bool gzip = IsGzip(stored);
  const pickle::LoadOptions load;
  const std::string bytes = gzip ? Gunzip(stored, file, load.max_bytes_decompressed) : stored;
  const Value root = pickle::Load(bytes, file, load);
  // Dump writes protocols 2 and 4: 2 keeps files of protocols 0-2 readable where they were (Python 2 too).
  const int protocol = pickle::ProtocolOf(bytes) <= 2 ? 2 : 4;
  try {
    const Value* list = *edit.list_key ? At(root, edit.list_key) : &root;
    const char* what = *edit.list_key ? edit.list_key : "the info";
    if (!list || (list->kind() != Kind::kList && list->kind() != Kind::kTuple))
      throw InputError(file, Msg() << what << " is not a list");
    const std::vector<Value>& records = list->elements();
    if (records.size() != log.frames.size())
      throw InputError(file, Msg() << what << " has " << records.size() << " records, the log " << log.frames.size() << " frames");
    std::vector<Value> kept;
    for (const InfoRecordEdit& re : edit.records) {
      if (records.at(re.record).kind() != Kind::kDict) throw InputError(file, Msg() << what << " holds a record that is not a dict");
      kept.push_back(EditedRecordValue(records[re.record], records, re, file));
    }
    Value kept_list = list->kind() == Kind::kList ? Value::List(std::move(kept)) : Value::Tuple(std::move(kept));
    Value out = *edit.list_key ? root : kept_list;
    if (*edit.list_key) {
      out.Set(edit.list_key, std::move(kept_list));
      AddPickleClasses(&out, edit.new_classes, edit.first_class_index);
    }
    pickle::DumpFile(dst, out, protocol, gzip);
  } catch (const InputError& e) {
    if (!e.where().empty()) throw;
    throw InputError(file, e.what());  // a Value accessor's error: the file is ours to name
  }
}

}  // namespace

namespace datasets_internal {

fs::path WriteInfoEdit(const Log& log, const InfoEdit& edit, const fs::path& out_dir) {
  const fs::path dst = InfoOutPath(log, out_dir);
  if (IsPickleInfo(log.annotation_path)) WriteInfoPickle(log, edit, dst);
  else WriteInfoText(log, edit, dst);
  return dst;
}

}  // namespace datasets_internal

}  // namespace sd
