#include "io/gzip.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include "core/error.h"
#include "io/files.h"
#include "testing/testing.h"

namespace sd {
namespace {

// gzip of `text` at the given level, by zlib's own gzip writer (an independent encoder of the format).
std::string GzipOf(const std::string& text, int level = 6) {
  z_stream z{};
  EXPECT_EQ(deflateInit2(&z, level, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(deflateBound(&z, text.size()) + 32, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(text.data()));
  z.avail_in = static_cast<uInt>(text.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

std::string ErrorOf(std::string_view data, size_t max_bytes) {
  try {
    Gunzip(data, "x.gz", max_bytes);
    return "";
  } catch (const InputError& e) {
    return e.what();
  }
}

TEST(Gzip, RoundTripsAndReadsConcatenatedMembers) {
  std::string text;
  for (int i = 0; i < 200000; ++i) text += static_cast<char>('a' + (i * 7919) % 26);
  EXPECT_EQ(Gunzip(GzipOf(text), "x.gz", text.size()), text);
  EXPECT_EQ(Gunzip(GzipOf("abc") + GzipOf("def"), "x.gz", 100), "abcdef");
  EXPECT_EQ(Gunzip(GzipOf(""), "x.gz", 0), "");
}

TEST(Gzip, RefusesCorruptTruncatedAndOversizedData) {
  const std::string text(100000, 'z');
  const std::string gz = GzipOf(text);
  EXPECT_NE(ErrorOf("plain text", 100).find("not gzip"), std::string::npos);
  EXPECT_NE(ErrorOf(gz.substr(0, gz.size() / 2), 1 << 20).find("truncated"), std::string::npos);
  std::string flipped = gz;
  flipped[flipped.size() - 6] ^= 0x40;  // inside the CRC-32 trailer
  EXPECT_NE(ErrorOf(flipped, 1 << 20).find("corrupt"), std::string::npos);
  // 100 kB of one letter compresses to a few hundred bytes: the limit, not the file size, bounds memory.
  EXPECT_NE(ErrorOf(gz, text.size() - 1).find("more than"), std::string::npos);
  EXPECT_NE(ErrorOf(gz + "junk", 1 << 20).find("trailing bytes"), std::string::npos);
  EXPECT_EQ(ErrorOf(gz + "junk", 1 << 20).rfind("x.gz: ", 0), 0u);
}

TEST(Gzip, ReadsFilesByMagicNotName) {
  testing::TempDir tmp;
  WriteFileAtomic(tmp / "a.bin", GzipOf("hello"));
  WriteFileAtomic(tmp / "b.gz", "plain");
  EXPECT_EQ(ReadMaybeGzipFile(tmp / "a.bin", 100), "hello");
  EXPECT_EQ(ReadMaybeGzipFile(tmp / "b.gz", 100), "plain");
  EXPECT_THROW(ReadMaybeGzipFile(tmp / "b.gz", 3), InputError);
}

}  // namespace
}  // namespace sd
