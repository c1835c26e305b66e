#include "io/pandas_frame.h"

#include <algorithm>
#include <cstring>
#include <limits>

#include "core/error.h"

namespace sd::pandas {
namespace fs = std::filesystem;
using pickle::Array;
using pickle::DType;
using pickle::Kind;
using pickle::Object;
using pickle::Value;

namespace {

constexpr std::string_view kIndexModule = "pandas.core.indexes.base";
constexpr std::string_view kRangeModule = "pandas.core.indexes.range";
constexpr std::string_view kNumericModule = "pandas.core.indexes.numeric";
constexpr std::string_view kManagerModule = "pandas.core.internals.managers";
constexpr std::string_view kBlockModule = "pandas._libs.internals";

// len(range(start, stop, step)) without overflow; -1 for step 0.
int64_t RangeLength(int64_t start, int64_t stop, int64_t step) {
  if (step == 0) return -1;
  if (step > 0 ? stop <= start : stop >= start) return 0;
  // Differences of int64s in uint64 arithmetic are exact here (the larger minus the smaller).
  const uint64_t span = step > 0 ? uint64_t(stop) - uint64_t(start) : uint64_t(start) - uint64_t(stop);
  const uint64_t s = step > 0 ? uint64_t(step) : uint64_t(0) - uint64_t(step);
  const uint64_t n = (span - 1) / s + 1;
  return n > uint64_t(std::numeric_limits<int64_t>::max()) ? -1 : static_cast<int64_t>(n);
}

class Reader {
 public:
  explicit Reader(const fs::path& file) : file_(file) {}

  [[noreturn]] void Fail(const std::string& what) const { throw InputError(file_, "pandas DataFrame: " + what); }

  const Object& ObjectOf(const Value& v, const char* what) const {
    if (v.kind() != Kind::kObject) Fail(Msg() << what << " is a " << pickle::KindName(v.kind()) << ", not an object");
    return v.object();
  }
  const Value& Key(const Value& dict, std::string_view key, const char* what) const {
    if (dict.kind() != Kind::kDict) Fail(Msg() << what << " is not a dict");
    const Value* v = dict.Find(key);
    if (!v) Fail(Msg() << what << " has no '" << key << "'");
    return *v;
  }
  int64_t Int(const Value& v, const char* what) const {
    if (v.kind() != Kind::kInt && !(v.kind() == Kind::kArray && v.array().ndim() == 0 && pickle::IsInteger(v.array().dtype)))
      Fail(Msg() << what << " is a " << pickle::KindName(v.kind()) << ", not an int");
    return v.AsInt();
  }
  const Array& Array1D(const Value& v, const char* what) const {
    if (v.kind() != Kind::kArray || v.array().scalar || v.array().ndim() != 1) Fail(Msg() << what << " is not a 1-D numpy array");
    return v.array();
  }

  // _new_Index(cls, {...}): a RangeIndex or an Index of labels.
  RowIndex Index(const Value& v, const char* what) const {
    const Object& o = ObjectOf(v, what);
    if (!o.Is(kIndexModule, "_new_Index") || o.args.kind() != Kind::kTuple || o.args.size() != 2)
      Fail(Msg() << what << " is a '" << o.module << "." << o.name << "', not pandas' _new_Index(cls, state)");
    const Object& cls = ObjectOf(o.args[0], what);
    const Value& d = o.args[1];
    RowIndex index;
    const Value* name = d.kind() == Kind::kDict ? d.Find("name") : nullptr;
    index.name = name ? *name : Value();
    if (cls.Is(kRangeModule, "RangeIndex")) {
      const Value* step = d.Find("step");
      index.start = Int(Key(d, "start", what), "RangeIndex start");
      index.stop = Int(Key(d, "stop", what), "RangeIndex stop");
      index.step = step && !step->is_none() ? Int(*step, "RangeIndex step") : 1;
      if (RangeLength(index.start, index.stop, index.step) < 0) Fail(Msg() << what << ": RangeIndex with step 0");
      return index;
    }
    if (cls.Is(kIndexModule, "Index") || (cls.module == kNumericModule && (cls.name == "Int64Index" ||
                                                                           cls.name == "UInt64Index" ||
                                                                           cls.name == "Float64Index"))) {
      index.is_range = false;
      index.labels = Array1D(Key(d, "data", what), "index data").ToCOrder();
      return index;
    }
    Fail(Msg() << what << " is a '" << cls.module << "." << cls.name << "' (RangeIndex and Index only)");
  }

  // A block's placement: slice(start, stop, step), an integer array or a list of ints.
  std::vector<int64_t> Placement(const Value& v, int64_t columns) const {
    std::vector<int64_t> out;
    if (v.kind() == Kind::kObject && v.object().Is("builtins", "slice")) {
      const Value& a = v.object().args;
      if (a.kind() != Kind::kTuple || a.size() != 3 || a[1].is_none()) Fail("block placement slice without a stop");
      const int64_t start = a[0].is_none() ? 0 : Int(a[0], "slice start");
      const int64_t stop = Int(a[1], "slice stop");
      const int64_t step = a[2].is_none() ? 1 : Int(a[2], "slice step");
      const int64_t n = RangeLength(start, stop, step);
      if (n < 0 || n > columns) Fail(Msg() << "block placement slice(" << start << ", " << stop << ", " << step << ")");
      for (int64_t k = 0; k < n; ++k) out.push_back(start + k * step);
    } else if (v.kind() == Kind::kArray) {
      const Array& a = Array1D(v, "block placement");
      if (!pickle::IsInteger(a.dtype)) Fail("block placement is not an integer array");
      for (int64_t k = 0; k < a.size(); ++k) out.push_back(a.AsInt(k));
    } else if (v.kind() == Kind::kList || v.kind() == Kind::kTuple) {
      for (const Value& e : v.elements()) out.push_back(Int(e, "block placement"));
    } else {
      Fail(Msg() << "block placement is a " << pickle::KindName(v.kind()));
    }
    return out;
  }

  DataFrame Read(const Value& v) const {
    if (v.kind() != Kind::kObject || !v.object().Is("pandas.core.frame", "DataFrame") ||
        v.object().via == Object::Via::kGlobal)
      Fail(Msg() << "the pickle holds a " << (v.kind() == Kind::kObject ? "'" + v.object().module + "." + v.object().name + "'"
                                                                         : std::string(pickle::KindName(v.kind())))
                 << ", not a DataFrame");
    const Value& state = v.object().state;
    if (state.kind() != Kind::kDict) Fail("DataFrame state is not a dict");
    const Value* mgr_value = state.Find("_mgr");
    if (!mgr_value) mgr_value = state.Find("_data");
    if (!mgr_value) Fail("DataFrame state has no '_mgr' or '_data'");
    const Object& mgr = ObjectOf(*mgr_value, "the block manager");
    if (!mgr.Is(kManagerModule, "BlockManager"))
      Fail(Msg() << "the block manager is a '" << mgr.module << "." << mgr.name << "'");

    // Both layouts come down to the axes and (values, placement) per block.
    const Value* axes = nullptr;
    std::vector<std::pair<const Value*, const Value*>> blocks;
    if (mgr.state.kind() == Kind::kTuple && mgr.state.size() >= 4 && mgr.state[3].kind() == Kind::kDict &&
        mgr.state[3].Find("0.14.1")) {
      const Value& s = *mgr.state[3].Find("0.14.1");
      axes = &Key(s, "axes", "BlockManager state");
      const Value& list = Key(s, "blocks", "BlockManager state");
      if (list.kind() != Kind::kList && list.kind() != Kind::kTuple) Fail("BlockManager blocks are not a list");
      for (const Value& b : list.elements())
        blocks.emplace_back(&Key(b, "values", "block"), &Key(b, "mgr_locs", "block"));
    } else if (mgr.via == Object::Via::kReduce && mgr.args.kind() == Kind::kTuple && mgr.args.size() == 2) {
      axes = &mgr.args[1];
      const Value& list = mgr.args[0];
      if (list.kind() != Kind::kList && list.kind() != Kind::kTuple) Fail("BlockManager blocks are not a tuple");
      for (const Value& b : list.elements()) {
        const Object& o = ObjectOf(b, "a block");
        if (!o.Is(kBlockModule, "_unpickle_block") || o.args.kind() != Kind::kTuple || o.args.size() < 2)
          Fail(Msg() << "a block is a '" << o.module << "." << o.name << "', not _unpickle_block(values, placement, ndim)");
        blocks.emplace_back(&o.args[0], &o.args[1]);
      }
    } else {
      Fail("BlockManager in neither the 0.14.1 state layout nor the pandas >= 1.3 REDUCE layout");
    }
    if ((axes->kind() != Kind::kList && axes->kind() != Kind::kTuple) || axes->size() != 2)
      Fail("BlockManager axes are not [columns, index]");

    DataFrame df;
    const RowIndex columns = Index((*axes)[0], "the column index");
    if (columns.is_range) Fail("column labels are a RangeIndex (str labels only)");
    df.columns_name = columns.name;
    df.index = Index((*axes)[1], "the row index");
    df.rows = df.index.size();
    const int64_t ncols = columns.labels.size();
    df.columns.resize(static_cast<size_t>(ncols));
    for (int64_t c = 0; c < ncols; ++c) {
      const bool is_str = columns.labels.dtype == DType::kUnicode ||
                          (columns.labels.dtype == DType::kObject && columns.labels.ObjectAt(c).kind() == Kind::kStr);
      if (!is_str) Fail(Msg() << "column label " << c << " is not a str (str labels only)");
      df.columns[static_cast<size_t>(c)].name = columns.labels.StringAt(c);
    }

    std::vector<bool> filled(static_cast<size_t>(ncols), false);
    for (const auto& [values_value, placement_value] : blocks) {
      if (values_value->kind() != Kind::kArray || values_value->array().scalar)
        Fail(Msg() << "block values are a " << pickle::KindName(values_value->kind()) << ", not a numpy array");
      const Array& values = values_value->array();
      const std::vector<int64_t> placement = Placement(*placement_value, ncols);
      // pandas keeps numpy blocks 2-D (columns x rows); 1-D values are one column (ensure_block_shape).
      const bool one_d = values.ndim() == 1 && placement.size() == 1;
      if (!one_d && (values.ndim() != 2 || values.shape[0] != static_cast<int64_t>(placement.size())))
        Fail(Msg() << "a " << pickle::DTypeName(values.dtype) << " block's values do not have one row per placed column");
      const int64_t n = one_d ? values.shape[0] : values.shape[1];
      if (n != df.rows) Fail(Msg() << "a block has " << n << " rows, the index " << df.rows);
      const int64_t k = static_cast<int64_t>(placement.size());
      for (int64_t r = 0; r < k; ++r) {
        const int64_t c = placement[static_cast<size_t>(r)];
        if (c < 0 || c >= ncols || filled[static_cast<size_t>(c)]) Fail(Msg() << "block placement of column " << c);
        filled[static_cast<size_t>(c)] = true;
        Array& col = df.columns[static_cast<size_t>(c)].values;
        col.dtype = values.dtype;
        col.itemsize = values.itemsize;
        col.shape = {n};
        if (values.dtype == DType::kObject) {
          col.objects.assign(values.objects.begin() + r * n, values.objects.begin() + (r + 1) * n);
        } else if (!values.fortran_order || one_d) {
          col.data.assign(values.data, static_cast<size_t>(r * n * values.itemsize), static_cast<size_t>(n * values.itemsize));
        } else {
          // Column-major (columns x rows) values: element (r, i) sits at (r + i * k).
          col.data.resize(static_cast<size_t>(n * values.itemsize));
          for (int64_t i = 0; i < n; ++i)
            std::memcpy(col.data.data() + i * values.itemsize, values.data.data() + (r + i * k) * values.itemsize,
                        static_cast<size_t>(values.itemsize));
        }
      }
    }
    for (int64_t c = 0; c < ncols; ++c)
      if (!filled[static_cast<size_t>(c)]) Fail(Msg() << "column '" << df.columns[static_cast<size_t>(c)].name << "' is in no block");
    if (!df.index.is_range && df.index.labels.size() != df.rows) Fail("index length");
    return df;
  }

 private:
  const fs::path& file_;
};

Value Global(std::string_view module, std::string_view name) {
  return Value::FromObject(Object{std::string(module), std::string(name), Value(), Value(), Object::Via::kGlobal});
}

Value Call(std::string_view module, std::string_view name, std::vector<Value> args, Object::Via via = Object::Via::kReduce,
           Value state = Value()) {
  return Value::FromObject(Object{std::string(module), std::string(name), Value::Tuple(std::move(args)), std::move(state), via});
}

Value NewIndex(Value cls, std::vector<std::pair<Value, Value>> state) {
  return Call(kIndexModule, "_new_Index", {std::move(cls), Value::Dict(std::move(state))});
}

Value LabelsIndex(Array labels, const Value& name) {
  return NewIndex(Global(kIndexModule, "Index"),
                  {{Value::Str("data"), Value::FromArray(std::move(labels))}, {Value::Str("name"), name}});
}

// slice(first, last + step, step) when the columns are evenly spaced upwards, else an int64 array.
Value PlacementOf(const std::vector<int64_t>& cols) {
  const int64_t step = cols.size() > 1 ? cols[1] - cols[0] : 1;
  bool even = step > 0;
  for (size_t i = 1; i < cols.size() && even; ++i) even = cols[i] - cols[i - 1] == step;
  if (even)
    return Call("builtins", "slice", {Value::Int(cols.front()), Value::Int(cols.back() + step), Value::Int(step)});
  return Value::FromArray(Array::Of<int64_t>(cols));
}

}  // namespace

int64_t RowIndex::size() const { return is_range ? RangeLength(start, stop, step) : labels.size(); }

const Column* DataFrame::Find(std::string_view name) const {
  for (const Column& c : columns)
    if (c.name == name) return &c;
  return nullptr;
}

DataFrame DataFrameFromPickle(const Value& v, const fs::path& file) { return Reader(file).Read(v); }

DataFrame LoadDataFrameFile(const fs::path& file) { return DataFrameFromPickle(pickle::LoadFile(file), file); }

Value DataFrameToPickle(const DataFrame& df, Layout layout) {
  SD_CHECK(df.index.size() == df.rows, << "DataFrameToPickle: the index has " << df.index.size() << " labels, the frame "
                                       << df.rows << " rows");
  // Blocks: one per dtype, in the order the dtypes first appear (kUnicode columns join the object block).
  struct Block {
    DType dtype;
    int itemsize;
    std::vector<int64_t> cols;
  };
  std::vector<Block> blocks;
  const auto block_dtype = [](const Array& a) { return a.dtype == DType::kUnicode ? DType::kObject : a.dtype; };
  for (size_t c = 0; c < df.columns.size(); ++c) {
    const Array& a = df.columns[c].values;
    SD_CHECK(a.ndim() == 1 && a.shape[0] == df.rows && !a.scalar,
             << "DataFrameToPickle: column '" << df.columns[c].name << "' is not 1-D with " << df.rows << " rows");
    const DType d = block_dtype(a);
    const int itemsize = d == DType::kObject ? 8 : a.itemsize;
    auto it = std::find_if(blocks.begin(), blocks.end(), [&](const Block& b) { return b.dtype == d && b.itemsize == itemsize; });
    if (it == blocks.end()) it = blocks.insert(blocks.end(), Block{d, itemsize, {}});
    it->cols.push_back(static_cast<int64_t>(c));
  }

  std::vector<Value> block_values, block_placements, block_items;
  for (const Block& b : blocks) {
    const int64_t k = static_cast<int64_t>(b.cols.size());
    Array values;
    values.dtype = b.dtype;
    values.itemsize = b.itemsize;
    values.shape = {k, df.rows};
    std::vector<std::string> names;
    for (int64_t c : b.cols) {
      const Array& col = df.columns[static_cast<size_t>(c)].values;
      names.push_back(df.columns[static_cast<size_t>(c)].name);
      if (col.dtype == DType::kUnicode) {
        for (int64_t i = 0; i < df.rows; ++i) values.objects.push_back(Value::Str(col.StringAt(i)));
      } else if (b.dtype == DType::kObject) {
        values.objects.insert(values.objects.end(), col.objects.begin(), col.objects.end());
      } else {
        values.data += col.ToCOrder().data;
      }
    }
    std::vector<Value> name_values;
    for (std::string& n : names) name_values.push_back(Value::Str(std::move(n)));
    block_values.push_back(Value::FromArray(std::move(values)));
    block_placements.push_back(PlacementOf(b.cols));
    block_items.push_back(LabelsIndex(Array::Objects(std::move(name_values)), Value()));
  }

  std::vector<Value> column_names;
  for (const Column& c : df.columns) column_names.push_back(Value::Str(c.name));
  const Value columns = LabelsIndex(Array::Objects(std::move(column_names), {static_cast<int64_t>(df.columns.size())}),
                                    df.columns_name);
  const Value index =
      df.index.is_range
          ? NewIndex(Global(kRangeModule, "RangeIndex"), {{Value::Str("name"), df.index.name},
                                                          {Value::Str("start"), Value::Int(df.index.start)},
                                                          {Value::Str("stop"), Value::Int(df.index.stop)},
                                                          {Value::Str("step"), Value::Int(df.index.step)}})
          : LabelsIndex(df.index.labels.ToCOrder(), df.index.name);
  // One axes list, referenced twice in the legacy state as pandas does (the writer keeps it shared).
  const Value axes = Value::List({columns, index});

  Value mgr;
  std::vector<std::pair<Value, Value>> frame_state;
  if (layout == Layout::kPandas15) {
    std::vector<Value> reduced;
    for (size_t b = 0; b < blocks.size(); ++b)
      reduced.push_back(Call(kBlockModule, "_unpickle_block", {block_values[b], block_placements[b], Value::Int(2)}));
    mgr = Call(kManagerModule, "BlockManager", {Value::Tuple(std::move(reduced)), axes});
    frame_state = {{Value::Str("_mgr"), mgr},
                   {Value::Str("_typ"), Value::Str("dataframe")},
                   {Value::Str("_metadata"), Value::List()},
                   {Value::Str("attrs"), Value::Dict()},
                   {Value::Str("_flags"), Value::Dict({{Value::Str("allows_duplicate_labels"), Value::Bool(true)}})}};
  } else {
    std::vector<Value> dicts;
    for (size_t b = 0; b < blocks.size(); ++b)
      dicts.push_back(Value::Dict({{Value::Str("values"), block_values[b]}, {Value::Str("mgr_locs"), block_placements[b]}}));
    const Value extra = Value::Dict(
        {{Value::Str("0.14.1"), Value::Dict({{Value::Str("axes"), axes}, {Value::Str("blocks"), Value::List(std::move(dicts))}})}});
    const Value state = Value::Tuple({axes, Value::List(block_values), Value::List(block_items), extra});
    mgr = Call(kManagerModule, "BlockManager", {}, Object::Via::kNewObj, state);
    frame_state = {{Value::Str("_data"), mgr},
                   {Value::Str("_typ"), Value::Str("dataframe")},
                   {Value::Str("_metadata"), Value::List()},
                   {Value::Str("attrs"), Value::Dict()}};
  }
  return Call("pandas.core.frame", "DataFrame", {}, Object::Via::kNewObj, Value::Dict(std::move(frame_state)));
}

}  // namespace sd::pandas
