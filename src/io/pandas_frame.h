#pragma once
// pandas DataFrames in pickles (PandaSet's lidar/*.pkl.gz and annotations/*/*.pkl.gz) as plain columns, read
// and written without Python or pandas, on top of io/pickle.h (namespace sd::pandas).
//
// What a pickled DataFrame is: DataFrame (NEWOBJ, or copyreg._reconstructor in protocols 0/1) whose BUILD state
// is a dict holding the BlockManager under "_mgr" (pandas >= 1.1) or "_data". The manager comes in two layouts,
// both read here:
//   - pandas 0.14.1 - 1.2 (PandaSet's files): NEWOBJ BlockManager + BUILD((axes, values, items,
//     {"0.14.1": {"axes": axes, "blocks": [{"values": 2-D array, "mgr_locs": slice or int array}, ...]}}))
//   - pandas >= 1.3 (what Debian's pandas 1.5 writes): BlockManager(blocks, axes) by REDUCE, each block
//     pandas._libs.internals._unpickle_block(values, placement, ndim=2).
// axes[0] is the column labels, an Index (pandas' _new_Index(Index, {"data": object array, "name": ...})),
// axes[1] the row labels, a RangeIndex (_new_Index(RangeIndex, {"name", "start", "stop", "step"})) or an Index.
// A block holds the columns of one dtype as a (columns x rows) array; its placement says which columns.
//
// Supported: column labels that are str; numpy columns of pickle.h's dtypes (numbers, bool, object); row index
// a RangeIndex or an Index of int / uint / float / object (str) labels. Extension types (Categorical,
// datetime64, nullable Int64, Series-level attrs, MultiIndex) are refused by the pickle reader or here, with
// a located InputError.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "io/pickle.h"

namespace sd::pandas {

// One column: a 1-D C-order array of `rows` elements. Numeric and bool columns keep their numpy dtype (PandaSet
// lidar: x, y, z, i, t float64, d int64); object columns (strings, None, NaN, mixed) are DType::kObject arrays
// holding pickle Values (a missing string is usually the float NaN, as pandas stores it).
struct Column {
  std::string name;
  pickle::Array values;
};

// The row labels. A RangeIndex(start, stop, step) unless `is_range` is false; then `labels` holds them (1-D,
// rows long; int64 / uint64 / float64 / object).
struct RowIndex {
  bool is_range = true;
  int64_t start = 0, stop = 0, step = 1;
  pickle::Array labels;
  pickle::Value name;  // None or a str (PandaSet's lidar frames name theirs "index")

  int64_t size() const;  // len(range(start, stop, step)) or labels.size()
};

struct DataFrame {
  std::vector<Column> columns;  // in the frame's column order (df.columns)
  int64_t rows = 0;
  RowIndex index;
  pickle::Value columns_name;   // df.columns.name (None usually)

  // The first column named `name`, or nullptr.
  const Column* Find(std::string_view name) const;
};

// The frame a DataFrame pickle holds, columns in df.columns order with pandas.read_pickle's values. InputError
// naming `file` when `v` is not a DataFrame in one of the layouts above.
DataFrame DataFrameFromPickle(const pickle::Value& v, const std::filesystem::path& file);
// pickle::LoadFile + DataFrameFromPickle (PandaSet's .pkl.gz included).
DataFrame LoadDataFrameFile(const std::filesystem::path& file);

enum class Layout {
  kPandas15,  // what pandas 1.3 - 2.x write themselves (BlockManager by REDUCE, _unpickle_block per block)
  kLegacy,    // pandas 0.14.1 - 1.2's BlockManager state, as PandaSet's files; read by every pandas since 0.14.1
};

// A DataFrame pickle pandas.read_pickle loads to a frame equal to `df` (df.equals, same dtypes, column names,
// index type, values and names): one block per dtype in the order the dtypes first appear among the columns,
// placements as slices where they are evenly spaced. kUnicode columns are written as object columns of str
// (pandas has no fixed-width string blocks). SD_CHECK: every column is 1-D with `rows` elements and the index
// has `rows` labels.
pickle::Value DataFrameToPickle(const DataFrame& df, Layout layout = Layout::kPandas15);

}  // namespace sd::pandas
