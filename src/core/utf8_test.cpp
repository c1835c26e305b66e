#include "core/utf8.h"

#include <gtest/gtest.h>

#include <string>

namespace sd {
namespace {

std::string Encoded(char32_t cp) {
  std::string s;
  AppendUtf8(cp, &s);
  return s;
}

// Each length's first and last code point, against the bytes of the same characters in this source file.
TEST(Utf8, EncodesEveryLength) {
  EXPECT_EQ(Encoded(U'\0'), std::string(1, '\0'));
  EXPECT_EQ(Encoded(U'a'), "a");
  EXPECT_EQ(Encoded(0x7F), "\x7F");
  EXPECT_EQ(Encoded(0x80), "\xC2\x80");
  EXPECT_EQ(Encoded(U'é'), "é");
  EXPECT_EQ(Encoded(0x7FF), "\xDF\xBF");
  EXPECT_EQ(Encoded(0x800), "\xE0\xA0\x80");
  EXPECT_EQ(Encoded(U'€'), "€");
  EXPECT_EQ(Encoded(0xFFFD), "\xEF\xBF\xBD");
  EXPECT_EQ(Encoded(0x10000), "\xF0\x90\x80\x80");
  EXPECT_EQ(Encoded(U'😀'), "😀");
  EXPECT_EQ(Encoded(0x10FFFF), "\xF4\x8F\xBF\xBF");
  std::string s = "x";
  AppendUtf8(U'ß', &s);
  EXPECT_EQ(s, "xß") << "appends, keeping what is there";
}

}  // namespace
}  // namespace sd
