#include "synth/scenario.h"

#include <algorithm>

#include <cmath>
#include <initializer_list>

#include "core/error.h"
#include "datasets/categories.h"
#include "io/json.h"

namespace sd {
namespace {

// Every range of a scenario is in metres from the ego: beyond 1 km no sensor sees an object and placement would
// search a road it does not have (distance_m 1e308 used to end as an "impossible scenario", far from its cause).
constexpr double kMaxScenarioRangeM = 1000;

void ReadRange(const JsonReader& o, const std::string& key, double* lo, double* hi) {
  if (!o.Has(key)) return;
  const JsonReader r = o[key];
  if (r.Size() != 2) r.Fail("expected [min, max]");
  *lo = r[0].Number();
  *hi = r[1].Number();
  if (!(*lo <= *hi)) r.Fail("min must not exceed max");
  if (!(std::abs(*lo) <= kMaxScenarioRangeM && std::abs(*hi) <= kMaxScenarioRangeM))
    r.Fail(Msg() << "[" << *lo << ", " << *hi << "] m: a range must lie within " << kMaxScenarioRangeM << " m of the ego");
}

ObjectRequest::Yaw ReadYaw(const JsonReader& o, double* yaw_deg, ObjectRequest::Yaw fallback) {
  if (!o.Has("yaw")) return fallback;
  const auto& y = o["yaw"].raw();
  if (y.is_number()) {
    *yaw_deg = y.get<double>();
    return ObjectRequest::Yaw::kFixed;
  }
  if (y == "aligned") return ObjectRequest::Yaw::kAligned;
  if (y == "random") return ObjectRequest::Yaw::kRandom;
  o["yaw"].Fail("expected \"aligned\", \"random\" or degrees");
}

// "car" or {"category": "car"} or {"asset": "id"}; categories are normalised to the canonical name.
ObjectSpec ReadSpec(const JsonReader& r) {
  ObjectSpec spec;
  if (r.raw().is_string()) {
    spec.category = r.String();
  } else if (r.raw().is_object()) {
    spec.asset_id = r.StringOr("asset", "");
    spec.category = r.StringOr("category", "");
    if (spec.asset_id.empty() == spec.category.empty()) r.Fail("give exactly one of \"asset\" or \"category\"");
  } else {
    r.Fail("expected a category name or {\"category\": ...} / {\"asset\": ...}");
  }
  if (!spec.category.empty()) {
    const auto c = FindCategory(spec.category);
    if (!c) r.Fail("unknown category '" + spec.category + "' (see datasets/categories.cpp for the canonical list)");
    spec.category = c->name;
  }
  return spec;
}

Arrangement::Side ReadSide(const JsonReader& o, Arrangement::Side fallback, bool allow_both) {
  if (!o.Has("side")) return fallback;
  const std::string v = o["side"].String();
  if (v == "left") return Arrangement::Side::kLeft;
  if (v == "right") return Arrangement::Side::kRight;
  if (v == "both" && allow_both) return Arrangement::Side::kBoth;
  o["side"].Fail(allow_both ? "expected \"left\", \"right\" or \"both\"" : "expected \"left\" or \"right\"");
}

double PositiveOr(const JsonReader& o, const std::string& key, double fallback) {
  const double v = o.NumberOr(key, fallback);
  if (!(v > 0)) o[key].Fail("must be positive");
  return v;
}

// A misspelt key ("cuont") was silently ignored, and the run placed the default count: an unknown key is refused,
// naming the keys that are read there. Keys starting with '_' are comments.
void RefuseUnknownKeys(const JsonReader& o, std::initializer_list<const char*> known) {
  if (!o.raw().is_object()) return;
  for (const auto& [key, value] : o.raw().items()) {
    if (!key.empty() && key[0] == '_') continue;
    if (std::any_of(known.begin(), known.end(), [&](const char* k) { return key == k; })) continue;
    std::string list;
    for (const char* k : known) list += (list.empty() ? "" : ", ") + std::string(k);
    o[key].Fail("unknown key (read here: " + list + "; a key starting with '_' is a comment)");
  }
}

Arrangement ReadArrangement(const JsonReader& o) {
  RefuseUnknownKeys(o, {"type", "category", "asset", "count", "lane_width_m", "lane_offset_m", "spacing_m", "distance_m",
                        "lateral_m", "side", "categories", "assets", "vehicle", "warning", "position", "setting",
                        "warning_distance_m", "allow_shoulder", "yaw"});
  Arrangement a;
  const std::string type = o["type"].String();
  using K = Arrangement::Kind;
  if (type == "lane_closure") a.kind = K::kLaneClosure;
  else if (type == "ego_lane_object") a.kind = K::kEgoLaneObject;
  else if (type == "roadside_clutter") a.kind = K::kRoadsideClutter;
  else if (type == "breakdown") a.kind = K::kBreakdown;
  else o["type"].Fail("unknown arrangement type '" + type + "' (lane_closure, ego_lane_object, roadside_clutter, breakdown)");

  auto one_spec = [&](const std::string& fallback_category) {
    if (o.Has("asset") || o.Has("category")) return ReadSpec(o);
    return ObjectSpec{"", fallback_category};
  };
  auto read_count = [&](int fallback, int min) {
    a.count = fallback;
    if (o.Has("count")) {
      a.count = static_cast<int>(o["count"].Integer());
      if (a.count < min || a.count > 1000) o["count"].Fail(Msg() << "count must be between " << min << " and 1000");
    }
  };
  a.lane_width_m = PositiveOr(o, "lane_width_m", a.lane_width_m);
  a.lane_offset_m = o.NumberOr("lane_offset_m", 0.0);
  switch (a.kind) {
    case K::kLaneClosure:
      a.objects = {one_spec("traffic_cone")};
      read_count(6, 2);
      a.spacing_m = PositiveOr(o, "spacing_m", a.spacing_m);
      a.distance_min = 20, a.distance_max = 40;
      a.side = ReadSide(o, Arrangement::Side::kRight, false);
      a.yaw_mode = ObjectRequest::Yaw::kRandom;  // cones are round
      break;
    case K::kEgoLaneObject:
      a.objects = {one_spec("debris")};
      a.distance_min = 30, a.distance_max = 60;
      a.lateral_min = -0.5, a.lateral_max = 0.5;
      ReadRange(o, "lateral_m", &a.lateral_min, &a.lateral_max);
      break;
    case K::kRoadsideClutter:
      if (o.Has("categories") == o.Has("assets")) o.Fail("give exactly one of \"categories\" or \"assets\" (a non-empty list)");
      {
        const bool cats = o.Has("categories");
        const JsonReader list = o[cats ? "categories" : "assets"];
        if (list.Size() == 0) list.Fail("empty list");
        for (size_t i = 0; i < list.Size(); ++i) {
          if (cats) a.objects.push_back(ReadSpec(list[i]));
          else a.objects.push_back(ObjectSpec{list[i].String(), ""});
        }
      }
      read_count(5, 1);
      a.distance_min = 5, a.distance_max = 60;
      a.lateral_min = 2.5, a.lateral_max = 6;
      ReadRange(o, "lateral_m", &a.lateral_min, &a.lateral_max);
      if (a.lateral_min < 0) o["lateral_m"].Fail("roadside_clutter lateral_m is a distance from the path: must be >= 0");
      a.side = ReadSide(o, Arrangement::Side::kBoth, true);
      a.allow_shoulder = true;
      a.yaw_mode = ObjectRequest::Yaw::kRandom;
      break;
    case K::kBreakdown: {
      a.objects = {o.Has("vehicle") ? ReadSpec(o["vehicle"]) : ObjectSpec{"", "car"},
                   o.Has("warning") ? ReadSpec(o["warning"]) : ObjectSpec{"", "warning_tripod"}};
      a.distance_min = 30, a.distance_max = 60;
      const std::string position = o.Has("position") ? o["position"].String() : "shoulder";
      if (position != "shoulder" && position != "lane") o["position"].Fail("expected \"shoulder\" or \"lane\"");
      a.in_lane = position == "lane";
      a.side = ReadSide(o, Arrangement::Side::kRight, false);
      a.allow_shoulder = !a.in_lane;
      const std::string setting = o.Has("setting") ? o["setting"].String() : "city";
      if (setting == "city") a.warning_distance_min = 10, a.warning_distance_max = 50;
      else if (setting == "highway") a.warning_distance_min = 30, a.warning_distance_max = 100;
      else o["setting"].Fail("expected \"city\" (10..50 m) or \"highway\" (30..100 m)");
      ReadRange(o, "warning_distance_m", &a.warning_distance_min, &a.warning_distance_max);
      if (a.warning_distance_min < 0) o["warning_distance_m"].Fail("must be >= 0");
      break;
    }
  }
  ReadRange(o, "distance_m", &a.distance_min, &a.distance_max);
  if (o.Has("allow_shoulder")) a.allow_shoulder = o["allow_shoulder"].Bool();
  a.yaw_mode = ReadYaw(o, &a.yaw_deg, a.yaw_mode);
  return a;
}

}  // namespace

std::string ObjectSpec::Describe() const {
  return asset_id.empty() ? "category '" + category + "'" : "asset '" + asset_id + "'";
}

const char* ToString(Arrangement::Kind kind) {
  switch (kind) {
    case Arrangement::Kind::kLaneClosure: return "lane_closure";
    case Arrangement::Kind::kEgoLaneObject: return "ego_lane_object";
    case Arrangement::Kind::kRoadsideClutter: return "roadside_clutter";
    case Arrangement::Kind::kBreakdown: return "breakdown";
  }
  return "?";
}

constexpr double kMaxMarginM = 10;

Scenario ReadScenario(const std::filesystem::path& path) {
  const nlohmann::json j = ReadJsonFile(path);
  const JsonReader r(j, path);
  if (!j.is_object()) r.Fail("expected a JSON object");
  RefuseUnknownKeys(r, {"seed", "margin_m", "world_fixed", "sun", "location", "assets_from_bank", "arrangements",
                        "objects", "description"});
  Scenario s;
  if (r.Has("seed")) {
    const int64_t seed = r["seed"].Integer();
    if (seed < 0) r["seed"].Fail("seed must be non-negative");
    s.seed = static_cast<uint32_t>(seed);
  }
  s.margin_m = r.NumberOr("margin_m", s.margin_m);
  // Placement tests every candidate against the margin's area; a margin of kilometres leaves no room on any road
  // and made placement run for ever (1e6 m). 10 m is more than any clearance a scene asks for.
  if (!(s.margin_m >= 0 && s.margin_m <= kMaxMarginM))
    r["margin_m"].Fail(Msg() << "margin must be between 0 and " << kMaxMarginM << " m, not " << s.margin_m);
  if (r.Has("world_fixed")) s.world_fixed = r["world_fixed"].Bool();
  if (r.Has("sun") && !(j["sun"].is_string() && j["sun"] == "auto")) {
    RefuseUnknownKeys(r["sun"], {"azimuth_deg", "elevation_deg"});
    SunSpec sun;
    sun.azimuth_deg = r["sun"]["azimuth_deg"].Number();
    sun.elevation_deg = r["sun"]["elevation_deg"].Number();
    if (sun.elevation_deg <= 0 || sun.elevation_deg > 90) r["sun"]["elevation_deg"].Fail("must be in (0, 90]");
    s.sun = sun;
  }
  if (r.Has("location")) {
    RefuseUnknownKeys(r["location"], {"latitude_deg", "longitude_deg", "name"});
    GeoLocation loc;
    loc.latitude_deg = r["location"]["latitude_deg"].Number();
    loc.longitude_deg = r["location"]["longitude_deg"].Number();
    loc.name = r["location"].StringOr("name", "scenario location");
    if (std::abs(loc.latitude_deg) > 90) r["location"]["latitude_deg"].Fail("must be within [-90, 90]");
    if (std::abs(loc.longitude_deg) > 180) r["location"]["longitude_deg"].Fail("must be within [-180, 180]");
    s.location = loc;
  }
  if (r.Has("assets_from_bank")) {
    const nlohmann::json& q = j["assets_from_bank"];
    if (q.is_object()) s.bank_queries.push_back(q);
    else if (q.is_array() && !q.empty() && std::all_of(q.begin(), q.end(), [](const auto& e) { return e.is_object(); }))
      s.bank_queries.assign(q.begin(), q.end());
    else r["assets_from_bank"].Fail("expected a bank query object or a non-empty list of them");
  }
  if (r.Has("arrangements")) {
    const JsonReader arr = r["arrangements"];
    for (size_t i = 0; i < arr.Size(); ++i) s.arrangements.push_back(ReadArrangement(arr[i]));
  }
  if (s.arrangements.empty() && !r.Has("objects")) r.Fail("no objects requested (neither \"objects\" nor \"arrangements\")");
  const nlohmann::json empty = nlohmann::json::array();
  const JsonReader objects = r.Has("objects") ? r["objects"] : JsonReader(empty, path, ".objects");
  if (objects.Size() == 0 && s.arrangements.empty()) objects.Fail("no objects requested");
  for (size_t i = 0; i < objects.Size(); ++i) {
    const JsonReader o = objects[i];
    RefuseUnknownKeys(o, {"asset", "category", "count", "distance_m", "lateral_m", "yaw"});
    ObjectRequest req;
    req.asset_id = o.StringOr("asset", "");
    req.category = o.StringOr("category", "");
    if (req.asset_id.empty() == req.category.empty()) o.Fail("give exactly one of \"asset\" or \"category\"");
    if (o.Has("count")) {
      req.count = static_cast<int>(o["count"].Integer());
      if (req.count < 1 || req.count > 1000) o["count"].Fail("count must be between 1 and 1000");
    }
    ReadRange(o, "distance_m", &req.distance_min, &req.distance_max);
    ReadRange(o, "lateral_m", &req.lateral_min, &req.lateral_max);
    req.yaw_mode = ReadYaw(o, &req.yaw_deg, req.yaw_mode);
    s.objects.push_back(req);
  }
  return s;
}

}  // namespace sd
