#include "mining/item.h"

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <limits>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "io/geometry_json.h"
#include "io/json.h"

namespace sd::mining {

using nlohmann::json;

const char* ToString(SourceKind kind) {
  switch (kind) {
    case SourceKind::kLog: return "log";
    case SourceKind::kFolder: return "folder";
    case SourceKind::kUrl: return "url";
  }
  return "?";
}

SourceKind SourceKindFromString(const std::string& s) {
  if (s == "log") return SourceKind::kLog;
  if (s == "folder") return SourceKind::kFolder;
  if (s == "url") return SourceKind::kUrl;
  throw InputError({}, Msg() << "unknown source kind '" << s << "' (expected log, folder or url)");
}

double ObjectSizePx(const MinedItem& item) {
  return std::max(0.0, std::min(item.box2d.x2 - item.box2d.x1, item.box2d.y2 - item.box2d.y1));
}

std::string StableId(const std::string& key) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : key) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016" PRIx64, h);
  return buf;
}

namespace {

// No camera or crop comes near this; a larger number in a manifest is corruption, refused before it sizes a buffer.
constexpr int64_t kMaxImageSide = 1 << 15;

// A 64-bit hash as 16 hex digits: JSON numbers are doubles in most readers and would lose bits.
std::string HashHex(uint64_t h) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016" PRIx64, h);
  return buf;
}

uint64_t ReadHashHex(const JsonReader& r) {
  const std::string s = r.String();
  if (s.size() != 16 || s.find_first_not_of("0123456789abcdef") != std::string::npos)
    r.Fail("expected 16 lowercase hex digits");
  return std::stoull(s, nullptr, 16);
}

}  // namespace

json ToJson(const MinedItem& item) {
  json j;
  j["id"] = item.id;
  j["kind"] = ToString(item.kind);
  j["source"] = item.source;
  j["origin"] = item.origin;
  j["category"] = item.category;
  if (item.kind == SourceKind::kLog) {
    j["dataset_category"] = item.dataset_category;
    j["log_name"] = item.log_name;
    j["frame"] = item.frame_token;
    j["camera"] = item.camera;
    j["annotation"] = item.annotation_token;
    j["instance"] = item.instance_token;
    j["visibility_level"] = item.visibility_level;
    j["lidar_points"] = item.lidar_points;
  }
  if (item.box_ego) j["box_ego"] = Box3Json(*item.box_ego);
  if (item.box_camera) j["box_camera"] = Box3Json(*item.box_camera);
  if (item.camera_intrinsics) {
    const PinholeCamera& c = *item.camera_intrinsics;
    j["intrinsics"] = {{"width", c.width}, {"height", c.height}, {"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx},
                       {"cy", c.cy}};
  }
  if (item.annotated_box2d) j["annotated_box2d"] = Box2Json(*item.annotated_box2d);
  j["box2d"] = Box2Json(item.box2d);
  j["crop_rect"] = Box2Json(item.crop_rect);
  j["crop_scale"] = item.crop_scale;
  j["crop_size"] = {item.crop_width, item.crop_height};
  j["truncation"] = item.truncation;
  j["occlusion"] = item.occlusion;
  j["sharpness"] = item.sharpness;
  j["phash"] = HashHex(item.phash);
  j["mask_source"] = item.mask_source;
  j["crop_file"] = item.crop_file;
  j["mask_file"] = item.mask_file;
  return j;
}

MinedItem ItemFromJson(const json& j, const std::string& where) {
  const JsonReader r(j, where);
  MinedItem item;
  item.id = r["id"].String();
  item.kind = SourceKindFromString(r["kind"].String());
  item.source = r["source"].String();
  item.origin = r["origin"].String();
  item.category = r.StringOr("category", "");
  if (item.kind == SourceKind::kLog) {
    item.dataset_category = r.StringOr("dataset_category", "");
    item.log_name = r.StringOr("log_name", "");
    item.frame_token = r["frame"].String();
    item.camera = r["camera"].String();
    item.annotation_token = r.StringOr("annotation", "");
    item.instance_token = r.StringOr("instance", "");
    // -1: the log does not say.
    item.visibility_level = r.Has("visibility_level") ? static_cast<int>(r["visibility_level"].IntegerIn(-1, 100)) : -1;
    item.lidar_points =
        r.Has("lidar_points") ? static_cast<int>(r["lidar_points"].IntegerIn(-1, std::numeric_limits<int>::max())) : -1;
  }
  if (r.Has("box_ego")) item.box_ego = ReadBox3(r["box_ego"]);
  if (r.Has("box_camera")) item.box_camera = ReadBox3(r["box_camera"]);
  if (r.Has("intrinsics")) {
    const JsonReader k = r["intrinsics"];
    PinholeCamera cam;
    cam.width = static_cast<int>(k["width"].IntegerIn(1, kMaxImageSide));
    cam.height = static_cast<int>(k["height"].IntegerIn(1, kMaxImageSide));
    cam.fx = k["fx"].Number();
    cam.fy = k["fy"].Number();
    cam.cx = k["cx"].Number();
    cam.cy = k["cy"].Number();
    item.camera_intrinsics = cam;
  }
  if (r.Has("annotated_box2d")) item.annotated_box2d = ReadBox2(r["annotated_box2d"]);
  item.box2d = ReadBox2(r["box2d"]);
  item.crop_rect = ReadBox2(r["crop_rect"]);
  item.crop_scale = r.NumberOr("crop_scale", 1);
  const JsonReader size = r["crop_size"];
  if (size.Size() != 2) size.Fail("expected [width, height]");
  item.crop_width = static_cast<int>(size[0].IntegerIn(1, kMaxImageSide));
  item.crop_height = static_cast<int>(size[1].IntegerIn(1, kMaxImageSide));
  item.truncation = r.NumberOr("truncation", -1);
  item.occlusion = r.NumberOr("occlusion", -1);
  item.sharpness = r.NumberOr("sharpness", -1);
  item.phash = r.Has("phash") ? ReadHashHex(r["phash"]) : 0;
  item.mask_source = r.StringOr("mask_source", "");
  item.crop_file = r["crop_file"].String();
  item.mask_file = r.StringOr("mask_file", "");
  return item;
}

}  // namespace sd::mining
