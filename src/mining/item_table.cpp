#include "mining/item_table.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <map>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "io/files.h"
#include "io/json.h"

namespace sd::mining {

namespace fs = std::filesystem;

namespace {

constexpr char kTableMagic[8] = {'S', 'D', 'I', 'T', 'E', 'M', 'S', '1'};
constexpr size_t kTableHeader = 32;
constexpr size_t kRecordBytes = 40;

template <typename T>
void Put(std::string* out, T value) {
  out->append(reinterpret_cast<const char*>(&value), sizeof value);
}

template <typename T>
T Get(const std::string& bytes, size_t at) {
  T value;
  std::memcpy(&value, bytes.data() + at, sizeof value);
  return value;
}

}  // namespace

// The table's row for `item`, whose JSON line is [offset, offset + length) and line `line` of items.jsonl: one
// definition for the table written with the lines and the one rebuilt from them.
ItemTable::Record ItemTable::MakeRecord(const MinedItem& item, uint64_t offset, uint32_t length, uint32_t line,
                                        std::map<std::string, uint32_t>* category_ids, std::vector<std::string>* categories) {
  auto [it, added] = category_ids->emplace(item.category, static_cast<uint32_t>(categories->size()));
  if (added) categories->push_back(item.category);
  Record rec;
  rec.offset = offset;
  rec.length = length;
  rec.line = line;
  rec.category = it->second;
  rec.object_size_px = static_cast<float>(ObjectSizePx(item));
  rec.truncation = static_cast<float>(item.truncation);
  rec.occlusion = static_cast<float>(item.occlusion);
  rec.sharpness = static_cast<float>(item.sharpness);
  return rec;
}

// A read-only map of items.jsonl: the records are parsed from it on demand.
class ItemTable::MappedText {
 public:
  explicit MappedText(const fs::path& path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw InputError(path, Msg() << "cannot open: " << std::strerror(errno));
    struct stat st {};
    if (::fstat(fd_, &st) != 0) {
      ::close(fd_);
      throw InputError(path, Msg() << "cannot stat: " << std::strerror(errno));
    }
    size_ = static_cast<size_t>(st.st_size);
    if (size_ > 0) {
      map_ = ::mmap(nullptr, size_, PROT_READ, MAP_SHARED, fd_, 0);
      if (map_ == MAP_FAILED) {
        ::close(fd_);
        throw InputError(path, Msg() << "cannot map: " << std::strerror(errno));
      }
    }
  }
  ~MappedText() {
    if (map_ && map_ != MAP_FAILED) ::munmap(map_, size_);
    if (fd_ >= 0) ::close(fd_);
  }
  MappedText(const MappedText&) = delete;
  MappedText& operator=(const MappedText&) = delete;

  std::string_view bytes() const { return map_ ? std::string_view(static_cast<const char*>(map_), size_) : std::string_view(); }

 private:
  int fd_ = -1;
  void* map_ = nullptr;
  size_t size_ = 0;
};

void WriteItemTable(const fs::path& shard_dir, const std::vector<MinedItem>& items) {
  using Record = ItemTable::Record;
  std::string lines;
  std::string records;
  std::map<std::string, uint32_t> category_ids;
  std::vector<std::string> categories;
  for (size_t i = 0; i < items.size(); ++i) {
    const std::string line = ToJson(items[i]).dump();
    SD_CHECK(line.size() < UINT32_MAX, << "a record of " << line.size() << " bytes");
    const Record rec = ItemTable::MakeRecord(items[i], lines.size(), static_cast<uint32_t>(line.size()), static_cast<uint32_t>(i + 1),
                                  &category_ids, &categories);
    Put<uint64_t>(&records, rec.offset);
    Put<uint32_t>(&records, rec.length);
    Put<uint32_t>(&records, rec.line);
    Put<uint32_t>(&records, rec.category);
    Put<float>(&records, rec.object_size_px);
    Put<float>(&records, rec.truncation);
    Put<float>(&records, rec.occlusion);
    Put<float>(&records, rec.sharpness);
    Put<uint32_t>(&records, 0);
    lines += line;
    lines += '\n';
  }
  std::string table(kTableMagic, 8);
  Put<uint64_t>(&table, items.size());
  Put<uint64_t>(&table, lines.size());
  Put<uint32_t>(&table, static_cast<uint32_t>(categories.size()));
  Put<uint32_t>(&table, 0);
  for (const std::string& c : categories) {
    Put<uint32_t>(&table, static_cast<uint32_t>(c.size()));
    table += c;
  }
  table.resize((table.size() + 7) / 8 * 8, '\0');
  table += records;
  WriteFileAtomic(shard_dir / "items.jsonl", lines);
  WriteFileAtomic(shard_dir / "items.bin", table);
}

ItemTable::ItemTable() = default;
ItemTable::ItemTable(ItemTable&&) noexcept = default;
ItemTable& ItemTable::operator=(ItemTable&&) noexcept = default;
ItemTable::~ItemTable() = default;

ItemTable ItemTable::Open(const fs::path& shard_dir) {
  ItemTable t;
  t.jsonl_ = shard_dir / "items.jsonl";
  if (!fs::is_regular_file(t.jsonl_)) throw InputError(t.jsonl_, "missing: the shard is corrupt (delete it and run `mine index` again)");
  t.text_ = std::make_unique<MappedText>(t.jsonl_);
  const std::string_view text = t.text_->bytes();

  const fs::path bin = shard_dir / "items.bin";
  if (fs::is_regular_file(bin)) {
    const std::string bytes = ReadFileToString(bin);
    auto fail = [&](const std::string& what) -> void {
      throw InputError(bin, what + ": the shard is corrupt (delete it and run `mine index` again)");
    };
    if (bytes.size() < kTableHeader || std::memcmp(bytes.data(), kTableMagic, 8) != 0) fail("not a SynthDrive item table");
    const uint64_t rows = Get<uint64_t>(bytes, 8), described = Get<uint64_t>(bytes, 16);
    const uint32_t ncat = Get<uint32_t>(bytes, 24);
    // A table describes one exact items.jsonl; a shard whose JSON lines changed size is read from them instead.
    if (described == text.size()) {
      size_t at = kTableHeader;
      for (uint32_t c = 0; c < ncat; ++c) {
        if (at + 4 > bytes.size()) fail("its category list is cut short");
        const uint32_t len = Get<uint32_t>(bytes, at);
        at += 4;
        if (len > bytes.size() - at) fail("its category list is cut short");
        t.categories_.emplace_back(bytes.data() + at, len);
        at += len;
      }
      at = (at + 7) / 8 * 8;
      if (at > bytes.size() || (bytes.size() - at) / kRecordBytes != rows || (bytes.size() - at) % kRecordBytes != 0)
        fail(Msg() << "holds " << (bytes.size() - std::min(at, bytes.size())) << " bytes of records where its header says "
                   << rows << " rows of " << kRecordBytes);
      t.records_.resize(rows);
      for (uint64_t r = 0; r < rows; ++r, at += kRecordBytes) {
        Record& rec = t.records_[r];
        rec.offset = Get<uint64_t>(bytes, at);
        rec.length = Get<uint32_t>(bytes, at + 8);
        rec.line = Get<uint32_t>(bytes, at + 12);
        rec.category = Get<uint32_t>(bytes, at + 16);
        rec.object_size_px = Get<float>(bytes, at + 20);
        rec.truncation = Get<float>(bytes, at + 24);
        rec.occlusion = Get<float>(bytes, at + 28);
        rec.sharpness = Get<float>(bytes, at + 32);
        if (rec.offset > text.size() || rec.length > text.size() - rec.offset || rec.category >= ncat)
          fail(Msg() << "row " << r << " points outside items.jsonl or its category list");
      }
      t.from_table_ = true;
      return t;
    }
  }

  // No table (or a stale one): every line parsed, as the table would have recorded it.
  std::map<std::string, uint32_t> category_ids;
  size_t begin = 0;
  for (uint32_t line = 1; begin < text.size(); ++line) {
    size_t end = text.find('\n', begin);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view s = text.substr(begin, end - begin);
    if (s.find_first_not_of(" \t\r") != std::string_view::npos) {
      const std::string where = t.jsonl_.string() + ":" + std::to_string(line);
      const MinedItem item = ItemFromJson(ParseJsonText(s, where), where);
      const Record rec = MakeRecord(item, begin, static_cast<uint32_t>(s.size()), line, &category_ids, &t.categories_);
      t.records_.push_back(rec);
    }
    begin = end + 1;
  }
  return t;
}

ItemSummary ItemTable::summary(size_t row) const {
  const Record& r = records_.at(row);
  return {categories_[r.category], r.object_size_px, r.truncation, r.occlusion, r.sharpness};
}

MinedItem ItemTable::item(size_t row) const {
  const Record& r = records_.at(row);
  const std::string where = jsonl_.string() + ":" + std::to_string(r.line);
  MinedItem item = ItemFromJson(ParseJsonText(text_->bytes().substr(r.offset, r.length), where), where);
  if (item.category != categories_[r.category])
    throw InputError(where, "disagrees with items.bin (category '" + item.category + "', the table says '" +
                                categories_[r.category] + "'): the shard is corrupt (delete it and run `mine index` again)");
  return item;
}

}  // namespace sd::mining
