#include "mining/item_table.h"

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "io/files.h"

namespace sd::mining {
namespace {

namespace fs = std::filesystem;

std::vector<MinedItem> SomeItems() {
  std::vector<MinedItem> items;
  const char* categories[] = {"traffic_cone", "barrier", "traffic_cone", "", "car"};
  for (int i = 0; i < 5; ++i) {
    MinedItem item;
    item.id = StableId("item" + std::to_string(i));
    item.kind = i == 3 ? SourceKind::kUrl : SourceKind::kLog;
    item.source = "/data/log";
    item.origin = "/data/log/img" + std::to_string(i) + ".jpg";
    item.category = categories[i];
    item.box2d = Box2{0, 0, 20.0 + 10 * i, 40};
    item.crop_rect = item.box2d;
    item.crop_width = 20 + 10 * i;
    item.crop_height = 40;
    item.truncation = i == 3 ? -1 : 0.1 * i;
    item.occlusion = 0.05 * i;
    item.sharpness = i == 3 ? -1 : 100 + i;
    item.crop_file = "crops/" + item.id + ".jpg";
    items.push_back(item);
  }
  return items;
}

class ItemTableTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("sd_item_table_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
                                        "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

void ExpectSameAs(const ItemTable& t, const std::vector<MinedItem>& items) {
  ASSERT_EQ(t.size(), items.size());
  for (size_t r = 0; r < items.size(); ++r) {
    EXPECT_EQ(ToJson(t.item(r)).dump(), ToJson(items[r]).dump()) << r;
    const ItemSummary s = t.summary(r);
    EXPECT_EQ(s.category, items[r].category);
    EXPECT_FLOAT_EQ(s.object_size_px, static_cast<float>(ObjectSizePx(items[r])));
    EXPECT_FLOAT_EQ(s.truncation, static_cast<float>(items[r].truncation));
    EXPECT_FLOAT_EQ(s.occlusion, static_cast<float>(items[r].occlusion));
    EXPECT_FLOAT_EQ(s.sharpness, static_cast<float>(items[r].sharpness));
  }
}

TEST_F(ItemTableTest, OpensFromTheTableWithoutParsingAndGivesEveryRecordBack) {
  const auto items = SomeItems();
  WriteItemTable(dir_, items);
  const ItemTable t = ItemTable::Open(dir_);
  EXPECT_TRUE(t.from_table());
  ExpectSameAs(t, items);
  EXPECT_THROW(t.item(items.size()), std::out_of_range);
}

TEST_F(ItemTableTest, AShardWithoutATableOrWithAStaleOneIsReadFromItsLines) {
  auto items = SomeItems();
  WriteItemTable(dir_, items);
  fs::remove(dir_ / "items.bin");
  const ItemTable old = ItemTable::Open(dir_);
  EXPECT_FALSE(old.from_table());
  ExpectSameAs(old, items);

  WriteItemTable(dir_, items);
  // One more line than the table describes (and a blank line): the lines are the truth.
  MinedItem extra = items[0];
  extra.id = StableId("extra");
  extra.category = "pedestrian";
  WriteFileAtomic(dir_ / "items.jsonl", ReadFileToString(dir_ / "items.jsonl") + "\n" + ToJson(extra).dump() + "\n");
  items.push_back(extra);
  const ItemTable stale = ItemTable::Open(dir_);
  EXPECT_FALSE(stale.from_table());
  ExpectSameAs(stale, items);
}

TEST_F(ItemTableTest, AMalformedLineIsNamedWithItsLineNumber) {
  WriteItemTable(dir_, SomeItems());
  WriteFileAtomic(dir_ / "items.jsonl", ReadFileToString(dir_ / "items.jsonl") + "{\"id\": 3\n");
  try {
    ItemTable::Open(dir_);
    FAIL() << "a broken line was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("items.jsonl:6"), std::string::npos) << e.what();
  }
}

TEST_F(ItemTableTest, ACorruptTableIsRefusedNamingIt) {
  WriteItemTable(dir_, SomeItems());
  const std::string bin = ReadFileToString(dir_ / "items.bin");
  for (const std::string& broken : {bin.substr(0, bin.size() - 7), std::string("NOTATABLE") + bin.substr(9), bin.substr(0, 20)}) {
    WriteFileAtomic(dir_ / "items.bin", broken);
    try {
      ItemTable::Open(dir_);
      FAIL() << "a corrupt table was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("items.bin"), std::string::npos) << e.what();
    }
  }
}

TEST_F(ItemTableTest, ALineThatNoLongerMatchesItsTableRowIsRefusedWhenRead) {
  WriteItemTable(dir_, SomeItems());
  // Same length, another category: the table cannot see it at open; reading the record does.
  std::string lines = ReadFileToString(dir_ / "items.jsonl");
  const size_t at = lines.find("\"barrier\"");
  ASSERT_NE(at, std::string::npos);
  lines.replace(at, 9, "\"bArrier\"");
  WriteFileAtomic(dir_ / "items.jsonl", lines);
  const ItemTable t = ItemTable::Open(dir_);
  EXPECT_TRUE(t.from_table());
  EXPECT_NO_THROW(t.item(0));
  try {
    t.item(1);
    FAIL() << "a record that disagrees with its table row was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("items.jsonl:2"), std::string::npos) << e.what();
  }
}

TEST_F(ItemTableTest, AnEmptyShardHasNoRows) {
  WriteItemTable(dir_, {});
  const ItemTable t = ItemTable::Open(dir_);
  EXPECT_TRUE(t.from_table());
  EXPECT_EQ(t.size(), 0u);
  fs::remove(dir_ / "items.jsonl");
  EXPECT_THROW(ItemTable::Open(dir_), InputError);
}

}  // namespace
}  // namespace sd::mining
