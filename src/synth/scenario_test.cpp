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
  EXPECT_FALSE(s.world_fixed);
  EXPECT_TRUE(ReadScenario(Write(dir, R"({"objects":[{"asset":"a"}],"world_fixed":true})")).world_fixed);
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

TEST(Scenario, ArrangementsWithDefaultsAndNormalisedCategories) {
  testing::TempDir dir;
  const Scenario s = ReadScenario(Write(dir, R"({"seed": 4, "arrangements": [
      {"type": "lane_closure", "count": 8, "spacing_m": 2.5, "side": "left", "lane_offset_m": 3.5},
      {"type": "ego_lane_object", "category": "movable_object.debris", "distance_m": [40, 80]},
      {"type": "roadside_clutter", "categories": ["traffic_cone", "TrafficCone", {"asset": "crate_7"}], "count": 3},
      {"type": "breakdown", "vehicle": {"asset": "torcs_p406"}, "position": "lane", "setting": "highway"},
      {"type": "breakdown", "warning_distance_m": [15, 20], "yaw": 5}]})"));
  EXPECT_TRUE(s.objects.empty());
  ASSERT_EQ(s.arrangements.size(), 5u);
  const Arrangement& closure = s.arrangements[0];
  EXPECT_EQ(closure.kind, Arrangement::Kind::kLaneClosure);
  EXPECT_STREQ(ToString(closure.kind), "lane_closure");
  EXPECT_EQ(closure.objects[0].category, "traffic_cone");
  EXPECT_EQ(closure.count, 8);
  EXPECT_DOUBLE_EQ(closure.spacing_m, 2.5);
  EXPECT_DOUBLE_EQ(closure.lane_width_m, 3.5);
  EXPECT_DOUBLE_EQ(closure.lane_offset_m, 3.5);
  EXPECT_EQ(closure.side, Arrangement::Side::kLeft);
  EXPECT_DOUBLE_EQ(closure.distance_min, 20);
  EXPECT_FALSE(closure.allow_shoulder);
  const Arrangement& obj = s.arrangements[1];
  EXPECT_EQ(obj.objects[0].category, "debris");
  EXPECT_DOUBLE_EQ(obj.distance_max, 80);
  EXPECT_DOUBLE_EQ(obj.lateral_min, -0.5);
  EXPECT_EQ(obj.yaw_mode, ObjectRequest::Yaw::kAligned);
  const Arrangement& clutter = s.arrangements[2];
  ASSERT_EQ(clutter.objects.size(), 3u);
  EXPECT_EQ(clutter.objects[1].category, "traffic_cone");
  EXPECT_EQ(clutter.objects[2].asset_id, "crate_7");
  EXPECT_EQ(clutter.side, Arrangement::Side::kBoth);
  EXPECT_DOUBLE_EQ(clutter.lateral_min, 2.5);
  EXPECT_TRUE(clutter.allow_shoulder);
  EXPECT_EQ(clutter.yaw_mode, ObjectRequest::Yaw::kRandom);
  const Arrangement& highway = s.arrangements[3];
  EXPECT_EQ(highway.objects[0].asset_id, "torcs_p406");
  EXPECT_EQ(highway.objects[1].category, "warning_tripod");
  EXPECT_TRUE(highway.in_lane);
  EXPECT_FALSE(highway.allow_shoulder);
  EXPECT_DOUBLE_EQ(highway.warning_distance_min, 30);
  EXPECT_DOUBLE_EQ(highway.warning_distance_max, 100);
  const Arrangement& city = s.arrangements[4];
  EXPECT_EQ(city.objects[0].category, "car");
  EXPECT_FALSE(city.in_lane);
  EXPECT_EQ(city.side, Arrangement::Side::kRight);
  EXPECT_DOUBLE_EQ(city.warning_distance_min, 15);
  EXPECT_DOUBLE_EQ(city.warning_distance_max, 20);
  EXPECT_EQ(city.yaw_mode, ObjectRequest::Yaw::kFixed);
  EXPECT_DOUBLE_EQ(city.yaw_deg, 5);
}

TEST(Scenario, BadArrangementsNameTheProblem) {
  ExpectError(R"({"arrangements":[{"type":"parade"}]})", "unknown arrangement type");
  ExpectError(R"({"objects":[{"asset":"a"}],"world_fixed":"yes"})", "world_fixed");
  ExpectError(R"({"arrangements":[{"type":"lane_closure","count":1}]})", "count must be between 2");
  ExpectError(R"({"arrangements":[{"type":"lane_closure","side":"both"}]})", "\"left\" or \"right\"");
  ExpectError(R"({"arrangements":[{"type":"lane_closure","spacing_m":0}]})", "must be positive");
  ExpectError(R"({"arrangements":[{"type":"ego_lane_object","category":"unicorn"}]})", "unknown category 'unicorn'");
  ExpectError(R"({"arrangements":[{"type":"roadside_clutter"}]})", "exactly one of \"categories\"");
  ExpectError(R"({"arrangements":[{"type":"roadside_clutter","categories":[]}]})", "empty list");
  ExpectError(R"({"arrangements":[{"type":"roadside_clutter","categories":["debris"],"lateral_m":[-3,3]}]})", ">= 0");
  ExpectError(R"({"arrangements":[{"type":"breakdown","position":"roof"}]})", "position");
  ExpectError(R"({"arrangements":[{"type":"breakdown","setting":"moon"}]})", "setting");
  ExpectError(R"({"arrangements":[{"type":"breakdown","warning_distance_m":[50,10]}]})", "min must not exceed max");
  ExpectError(R"({"arrangements":[]})", "no objects");
  ExpectError(R"({"seed": 1})", "no objects");
}

TEST(Scenario, BadInputNamesTheFileAndTheProblem) {
  ExpectError("{\"objects\": [", "malformed JSON");
  ExpectError(R"({"objects":[]})", "no objects");
  ExpectError(R"({"objects":[{"category":"car","count":0}]})", "count");
  ExpectError(R"({"objects":[{"category":"car","asset":"x"}]})", "exactly one");
  ExpectError(R"({"objects":[{"category":"car","distance_m":[30,10]}]})", "min must not exceed max");
  ExpectError(R"({"objects":[{"category":"car","yaw":"sideways"}]})", "yaw");
  // 1e308 m used to reach placement and come back as an "impossible scenario".
  ExpectError(R"({"objects":[{"category":"car","distance_m":[10,1e308]}]})",
              ".objects[0].distance_m: [10, 1e+308] m: a range must lie within 1000 m of the ego");
  ExpectError(R"({"location":{"latitude_deg":95,"longitude_deg":0},"objects":[{"category":"car"}]})", "latitude_deg");
  ExpectError(R"({"seed":-1,"objects":[{"category":"car"}]})", "seed");
  ExpectError(R"({"margin_m":"wide","objects":[{"category":"car"}]})", "expected a number");
  // Placement never returned with a margin of 1e6 m.
  ExpectError(R"({"margin_m":1e6,"objects":[{"category":"car"}]})", ".margin_m: margin must be between 0 and 10 m");
  // A misspelt key was ignored and the default used instead.
  ExpectError(R"({"objects":[{"category":"car","cuont":3}]})", ".objects[0].cuont: unknown key (read here: asset, category, count");
  ExpectError(R"({"sead":3,"objects":[{"category":"car"}]})", ".sead: unknown key");
  ExpectError(R"({"arrangements":[{"type":"lane_closure","spaceing_m":2}]})", ".arrangements[0].spaceing_m: unknown key");
  ExpectError(R"({"sun":{"azimuth_deg":0,"elevation":30},"objects":[{"category":"car"}]})", ".sun.elevation: unknown key");
  testing::TempDir dir;
  EXPECT_NO_THROW(ReadScenario(Write(dir, R"({"_comment":"keys starting with _ are comments","objects":[{"category":"car","_why":"x"}]})")));
}

}  // namespace
}  // namespace sd
