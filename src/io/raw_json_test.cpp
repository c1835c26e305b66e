#include "io/raw_json.h"

#include <gtest/gtest.h>

#include <random>

#include "core/error.h"

namespace sd {
namespace {

// A file laid out the way Python's json.dump(indent=4) lays out an mmdet3d info.
const char* kIndented = R"({
    "metainfo": {
        "categories": {
            "car": 0
        }
    },
    "data_list": [
        {
            "token": "a",
            "instances": [
                {
                    "bbox_3d": [1.5, NaN],
                    "label": 0
                }
            ]
        },
        {
            "token": "b\"q",
            "instances": []
        }
    ]
}
)";

TEST(RawJson, WalksMembersAndElementsAndReadsTheLayout) {
  const RawJson j(kIndented, "info.json");
  const Span root = j.Root();
  ASSERT_TRUE(j.IsObject(root));
  const std::optional<RawMember> list = j.Member(root, "data_list");
  ASSERT_TRUE(list && j.IsArray(list->value));
  const std::vector<Span> records = j.Elements(list->value);
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(j.Member(records[1], "token")->key, "token");
  EXPECT_EQ(j.Text(j.Member(records[1], "token")->value), "\"b\\\"q\"");
  // NaN is not JSON, but the scanner passes over it as an opaque value (Python writes it).
  const Span inst = j.Elements(j.Member(records[0], "instances")->value)[0];
  EXPECT_EQ(j.Text(j.Member(inst, "bbox_3d")->value), "[1.5, NaN]");
  const JsonStyle s = j.Style();
  EXPECT_EQ(s.unit, "    ");
  EXPECT_EQ(s.key_sep, ": ");
  EXPECT_EQ(j.LineIndent(inst.begin), "                ");
  EXPECT_FALSE(j.Member(root, "nope"));
}

TEST(RawJson, SplicesKeepEveryUntouchedByte) {
  const RawJson j(kIndented, "info.json");
  const JsonStyle s = j.Style();
  const Span rec0 = j.Elements(j.Member(j.Root(), "data_list")->value)[0];
  const Span rec1 = j.Elements(j.Member(j.Root(), "data_list")->value)[1];
  std::vector<Splice> splices;
  Items fresh;
  ExtendMember(j, rec0, "instances", {{"", ojson{{"label", 1}}}}, false, s, &splices, &fresh);
  ExtendMember(j, rec1, "instances", {{"", ojson{{"label", 2}}}}, false, s, &splices, &fresh);
  ExtendMember(j, rec1, "cam_instances", {{"CAM", ojson::array()}}, true, s, &splices, &fresh);
  ASSERT_EQ(fresh.size(), 1u);
  splices.push_back(AppendItems(j, rec1, fresh, s));
  const std::string out = ApplySplices(j, {0, j.text().size()}, splices);
  // The result parses, holds the additions, and starts and ends with the input's own bytes.
  const nlohmann::json parsed = nlohmann::json::parse(std::string(out).replace(out.find("NaN"), 3, "null"));
  EXPECT_EQ(parsed["data_list"][0]["instances"].size(), 2u);
  EXPECT_EQ(parsed["data_list"][1]["instances"][0]["label"], 2);
  EXPECT_TRUE(parsed["data_list"][1]["cam_instances"]["CAM"].is_array());
  const std::string text = kIndented;
  const size_t head = text.find("\"label\": 0");
  EXPECT_EQ(out.substr(0, head), text.substr(0, head));
  EXPECT_EQ(out.substr(out.size() - 8), text.substr(text.size() - 8));
  // Added records are indented like their neighbours.
  EXPECT_NE(out.find("},\n                {\n                    \"label\": 1\n                }"), std::string::npos) << out;
}

TEST(RawJson, OneLineFilesStayOnOneLine) {
  const RawJson j(R"([{"a": 1}, {"a": 2}])", "t.json");
  const JsonStyle s = j.Style();
  EXPECT_EQ(s.unit, "");
  EXPECT_EQ(s.item_sep, ", ");
  const std::string out = ApplySplices(j, {0, j.text().size()}, {AppendItems(j, j.Root(), {{"", ojson{{"a", 3}}}}, s)});
  EXPECT_EQ(out, R"([{"a": 1}, {"a": 2}, {"a": 3}])");
  const std::vector<Span> e = j.Elements(j.Root());
  EXPECT_EQ(ArrayWith(j, j.Root(), e, {std::string(j.Text(e[1]))}, s), R"([{"a": 2}])");
}

TEST(RawJson, MalformedTextIsALocatedErrorNeverACrash) {
  for (const char* bad : {"", "   ", "[", "[1,", "{\"a\"", "{\"a\": }", "{\"a\" 1}", "[1 2]", "\"abc", "{\"\\u12\": 1}", "{1: 2}"}) {
    const RawJson j(bad, "bad.json");
    try {
      const Span r = j.Root();
      if (j.IsArray(r)) j.Elements(r);
      if (j.IsObject(r)) j.Members(r);
      j.Style();
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()).rfind("bad.json: byte ", 0), 0u) << e.what();
    }
  }
  // Deep nesting costs no stack: containers are matched by counting.
  const RawJson deep(std::string(1000000, '[') + std::string(1000000, ']'), "deep.json");
  EXPECT_EQ(deep.Root().end, 2000000u);
  EXPECT_NO_THROW(deep.Style());
  // Truncations and byte flips of a real layout: an InputError or a result, never a crash (run under ASan in CI).
  const std::string text = kIndented;
  std::mt19937 rng(7);
  for (int trial = 0; trial < 2000; ++trial) {
    std::string t = text;
    if (trial % 2) t.resize(rng() % t.size());
    else
      for (int k = 0; k < 3; ++k) t[rng() % t.size()] = static_cast<char>(rng() % 256);
    const RawJson j(t, "x.json");
    try {
      const Span r = j.Root();
      if (j.IsObject(r))
        for (const RawMember& m : j.Members(r))
          if (j.IsArray(m.value)) j.Elements(m.value);
      j.Style();
    } catch (const InputError&) {
    }
  }
}

}  // namespace
}  // namespace sd
