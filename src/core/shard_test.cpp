#include "core/shard.h"

#include <gtest/gtest.h>

#include "core/error.h"

namespace sd {
namespace {

TEST(Shard, ParsesAndDealsEveryItemToExactlyOneShard) {
  const ShardSpec s = ParseShard("2/5");
  EXPECT_EQ(s.index, 2);
  EXPECT_EQ(s.count, 5);
  EXPECT_EQ(s.ToString(), "2/5");
  for (size_t item = 0; item < 100; ++item) {
    int owners = 0;
    for (int k = 0; k < 5; ++k) owners += ShardSpec{k, 5}.Owns(item);
    EXPECT_EQ(owners, 1) << item;
  }
  EXPECT_TRUE(ParseShard("0/1").Owns(12345));
}

TEST(Shard, RejectsMalformedSpecs) {
  for (const char* bad : {"", "3", "5/5", "-1/4", "1/0", "a/b", "1/2/3", "1 /2", "0/"})
    EXPECT_THROW(ParseShard(bad), InputError) << bad;
}

}  // namespace
}  // namespace sd
