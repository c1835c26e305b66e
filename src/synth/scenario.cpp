#include "synth/scenario.h"

#include <algorithm>

#include <cmath>

#include "core/error.h"
#include "io/json.h"

namespace sd {
namespace {

void ReadRange(const JsonReader& o, const std::string& key, double* lo, double* hi) {
  if (!o.Has(key)) return;
  const JsonReader r = o[key];
  if (r.Size() != 2) r.Fail("expected [min, max]");
  *lo = r[0].Number();
  *hi = r[1].Number();
  if (!(*lo <= *hi)) r.Fail("min must not exceed max");
}

}  // namespace

Scenario ReadScenario(const std::filesystem::path& path) {
  const nlohmann::json j = ReadJsonFile(path);
  const JsonReader r(j, path);
  if (!j.is_object()) r.Fail("expected a JSON object");
  Scenario s;
  if (r.Has("seed")) {
    const int64_t seed = r["seed"].Integer();
    if (seed < 0) r["seed"].Fail("seed must be non-negative");
    s.seed = static_cast<uint32_t>(seed);
  }
  s.margin_m = r.NumberOr("margin_m", s.margin_m);
  if (s.margin_m < 0) r["margin_m"].Fail("margin must be non-negative");
  if (r.Has("sun") && !(j["sun"].is_string() && j["sun"] == "auto")) {
    SunSpec sun;
    sun.azimuth_deg = r["sun"]["azimuth_deg"].Number();
    sun.elevation_deg = r["sun"]["elevation_deg"].Number();
    if (sun.elevation_deg <= 0 || sun.elevation_deg > 90) r["sun"]["elevation_deg"].Fail("must be in (0, 90]");
    s.sun = sun;
  }
  if (r.Has("location")) {
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
  const JsonReader objects = r["objects"];
  if (objects.Size() == 0) objects.Fail("no objects requested");
  for (size_t i = 0; i < objects.Size(); ++i) {
    const JsonReader o = objects[i];
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
    if (o.Has("yaw")) {
      const auto& y = o["yaw"].raw();
      if (y.is_number()) {
        req.yaw_mode = ObjectRequest::Yaw::kFixed;
        req.yaw_deg = y.get<double>();
      } else if (y == "aligned") {
        req.yaw_mode = ObjectRequest::Yaw::kAligned;
      } else if (y == "random") {
        req.yaw_mode = ObjectRequest::Yaw::kRandom;
      } else {
        o["yaw"].Fail("expected \"aligned\", \"random\" or degrees");
      }
    }
    s.objects.push_back(req);
  }
  return s;
}

}  // namespace sd
