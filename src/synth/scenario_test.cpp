#include "synth/scenario.h"

#include <fstream>

#include <gtest/gtest.h>

#include "core/error.h"
#include "testing/testing.h"

namespace sd {
namespace {

std::filesystem::path Write(const testing::TempDir& dir, const std::string& text) {
  const auto p = dir / "scenario.json";
  std::ofstream(p) << text;
  return p;
}

TEST(Scenario, ParsesTheShippedDemoScenario) {
  const Scenario s = ReadScenario(testing::RepoData("scenarios/demo.json"));
  EXPECT_EQ(s.seed, 7u);
  ASSERT_EQ(s.objects.size(), 3u);
  EXPECT_EQ(s.objects[0].category, "traffic_cone");
  EXPECT_EQ(s.objects[0].count, 3);
  EXPECT_EQ(s.objects[0].yaw_mode, ObjectRequest::Yaw::kRandom);
  EXPECT_DOUBLE_EQ(s.objects[2].distance_max, 30.0);
  ASSERT_TRUE(s.location.has_value());  // nuScenes' singapore-onenorth: the demo's sun comes from the ephemeris
  EXPECT_NEAR(s.location->latitude_deg, 1.2966, 0.01);
}

TEST(Scenario, FixedYawAndSun) {
  testing::TempDir dir;
  const Scenario s = ReadScenario(Write(dir, R"({"objects":[{"asset":"a","yaw":90}],"sun":{"azimuth_deg":10,"elevation_deg":40}})"));
  EXPECT_EQ(s.objects[0].asset_id, "a");
  EXPECT_EQ(s.objects[0].yaw_mode, ObjectRequest::Yaw::kFixed);
  ASSERT_TRUE(s.sun.has_value());
  EXPECT_DOUBLE_EQ(s.sun->elevation_deg, 40.0);
}

void ExpectError(const std::string& text, const std::string& fragment) {
  testing::TempDir dir;
  const auto p = Write(dir, text);
  try {
    ReadScenario(p);
    FAIL() << "no error for " << text;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(p.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find(fragment), std::string::npos) << msg;
  }
}

TEST(Scenario, BankQueriesAreKeptForThePipeline) {
  testing::TempDir dir;
  Scenario s = ReadScenario(Write(dir, R"({"assets_from_bank": {"bank": "b.sqlite", "category": "barrier"},
                                           "objects": [{"category": "barrier"}]})"));
  ASSERT_EQ(s.bank_queries.size(), 1u);
  EXPECT_EQ(s.bank_queries[0]["category"], "barrier");
  s = ReadScenario(Write(dir, R"({"assets_from_bank": [{"category": "barrier"}, {"category": "car", "limit": 2}],
                                  "objects": [{"category": "car"}]})"));
  ASSERT_EQ(s.bank_queries.size(), 2u);
  EXPECT_EQ(s.bank_queries[1]["limit"], 2);
  EXPECT_TRUE(ReadScenario(testing::RepoData("scenarios/demo.json")).bank_queries.empty());
  for (const char* bad : {R"({"assets_from_bank": "b.sqlite", "objects": []})",
                          R"({"assets_from_bank": [], "objects": []})", R"({"assets_from_bank": [3], "objects": []})"})
    EXPECT_THROW(ReadScenario(Write(dir, bad)), InputError) << bad;
}

TEST(Scenario, BadInputNamesTheFileAndTheProblem) {
  ExpectError("{\"objects\": [", "malformed JSON");
  ExpectError(R"({"objects":[]})", "no objects");
  ExpectError(R"({"objects":[{"category":"car","count":0}]})", "count");
  ExpectError(R"({"objects":[{"category":"car","asset":"x"}]})", "exactly one");
  ExpectError(R"({"objects":[{"category":"car","distance_m":[30,10]}]})", "min must not exceed max");
  ExpectError(R"({"objects":[{"category":"car","yaw":"sideways"}]})", "yaw");
  ExpectError(R"({"location":{"latitude_deg":95,"longitude_deg":0},"objects":[{"category":"car"}]})", "latitude_deg");
  ExpectError(R"({"seed":-1,"objects":[{"category":"car"}]})", "seed");
  ExpectError(R"({"margin_m":"wide","objects":[{"category":"car"}]})", "expected a number");
}

}  // namespace
}  // namespace sd
