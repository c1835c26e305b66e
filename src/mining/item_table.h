#pragma once
// One index shard's records: items.jsonl (one MinedItem per line, the readable truth) and items.bin, a
// fixed-width table derived from it (each row's byte range in items.jsonl, its category and the quality figures
// label mode ranks by). Opening a shard reads the table and maps the JSON lines; a record is parsed only when
// asked for, so opening a million-item index costs milliseconds, not a parse of every line (docs/mining.md).
//
// items.bin: "SDITEMS1", rows u64, bytes of the items.jsonl it describes u64, category count u32, reserved u32,
// the categories (u32 length + bytes each), zero padding to 8 bytes, then rows x 40-byte records (offset u64,
// length u32, line u32, category u32, object size px f32, truncation f32, occlusion f32, sharpness f32,
// reserved u32), little-endian. A shard without it (written before it existed), or whose items.jsonl no longer
// has the size it records, is read from the JSON lines as before.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "mining/item.h"

namespace sd::mining {

// What label mode reads of every row.
struct ItemSummary {
  std::string_view category;
  float object_size_px = 0;  // ObjectSizePx
  float truncation = -1, occlusion = -1, sharpness = -1;
};

// Writes items.jsonl and items.bin into `shard_dir` (each atomically; a shard is staged and renamed whole).
void WriteItemTable(const std::filesystem::path& shard_dir, const std::vector<MinedItem>& items);

class ItemTable {
 public:
  // InputError naming the file for a missing items.jsonl, a malformed items.bin, or (when the JSON lines must be
  // read) a malformed record.
  static ItemTable Open(const std::filesystem::path& shard_dir);

  ItemTable();  // no rows
  ItemTable(ItemTable&&) noexcept;
  ItemTable& operator=(ItemTable&&) noexcept;
  ~ItemTable();

  size_t size() const { return records_.size(); }
  ItemSummary summary(size_t row) const;
  // Parses the row's JSON line; InputError naming items.jsonl and the line when it is malformed or disagrees
  // with the table.
  MinedItem item(size_t row) const;
  // True when the table came from items.bin (false: the JSON lines were parsed at open).
  bool from_table() const { return from_table_; }

 private:
  struct Record {
    uint64_t offset = 0;
    uint32_t length = 0, line = 0, category = 0;
    float object_size_px = 0, truncation = -1, occlusion = -1, sharpness = -1;
  };
  class MappedText;
  friend void WriteItemTable(const std::filesystem::path& shard_dir, const std::vector<MinedItem>& items);
  static Record MakeRecord(const MinedItem& item, uint64_t offset, uint32_t length, uint32_t line,
                           std::map<std::string, uint32_t>* category_ids, std::vector<std::string>* categories);
  std::filesystem::path jsonl_;
  std::unique_ptr<MappedText> text_;
  std::vector<std::string> categories_;
  std::vector<Record> records_;
  bool from_table_ = false;
};

}  // namespace sd::mining
