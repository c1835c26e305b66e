// ParseJsonText and JsonReader: what they refuse, and that each refusal is one line naming the file and where.
#include "io/json.h"

#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "testing/input_error.h"

namespace sd {
namespace {

using nlohmann::json;

// The InputError message of `fn`, or "" when it did not throw one.
using testing::InputErrorOf;

TEST(Json, AByteOrderMarkIsNamedNotMisread) {
  const std::string message = InputErrorOf([] { ParseJsonText("\xEF\xBB\xBF{\"data_list\": []}", "info.json"); });
  EXPECT_NE(message.find("info.json"), std::string::npos) << message;
  EXPECT_NE(message.find("UTF-8 byte-order mark"), std::string::npos) << message;
  EXPECT_EQ(ParseJsonText("{\"a\": \"\xEF\xBB\xBF\"}", "x.json")["a"].get<std::string>(), "\xEF\xBB\xBF");
}

TEST(Json, NestingIsBoundedBeforeParsing) {
  const std::string deep(100000, '[');
  const std::string message = InputErrorOf([&] { ParseJsonText(deep, "scenario.json"); });
  EXPECT_NE(message.find("scenario.json"), std::string::npos) << message;
  EXPECT_NE(message.find("nest"), std::string::npos) << message;
  // Brackets inside strings do not count; the limit itself parses.
  EXPECT_NO_THROW(ParseJsonText("{\"comment\": \"" + deep + "\"}", "x.json"));
  const std::string at_limit = std::string(kMaxJsonDepth, '[') + std::string(kMaxJsonDepth, ']');
  EXPECT_NO_THROW(ParseJsonText(at_limit, "x.json"));
  EXPECT_NE(InputErrorOf([&] { CheckJsonNesting("[" + at_limit + "]", "model.gltf"); }).find("model.gltf"), std::string::npos);
}

TEST(Json, NumbersOutOfRangeNameTheFile) {
  const std::string message = InputErrorOf([] { ParseJsonText("{\"cam2img\": [1e999]}", "info.json"); });
  EXPECT_NE(message.find("info.json"), std::string::npos) << message;
  EXPECT_EQ(message.find("json.exception"), std::string::npos) << message;
}

TEST(Json, IntegersAreRangeCheckedBeforeAnyCast) {
  const json j = ParseJsonText(R"({"a": 3, "b": 3.0, "c": 3.5, "d": 1e300, "e": 18446744073709551615, "f": -7})", "r.json");
  const JsonReader r(j, "r.json");
  EXPECT_EQ(r["a"].Integer(), 3);
  EXPECT_EQ(r["b"].Integer(), 3);
  EXPECT_NE(InputErrorOf([&] { r["c"].Integer(); }).find("r.json: .c: expected an integer, found 3.5"), std::string::npos)
      << InputErrorOf([&] { r["c"].Integer(); });
  EXPECT_NE(InputErrorOf([&] { r["d"].Integer(); }).find("expected an integer"), std::string::npos);
  EXPECT_NE(InputErrorOf([&] { r["e"].Integer(); }).find("out of range"), std::string::npos);
  EXPECT_EQ(r["f"].IntegerIn(-10, 10), -7);
  const std::string outside = InputErrorOf([&] { r["a"].IntegerIn(4, 100); });
  EXPECT_NE(outside.find("r.json: .a: integer 3 outside [4, 100]"), std::string::npos) << outside;
}

}  // namespace
}  // namespace sd
