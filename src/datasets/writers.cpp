#include "datasets/writers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>

#include "core/error.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "io/pointcloud_io.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

namespace {

using datasets_internal::RelativePath;

constexpr double kPi = std::numbers::pi;

// The dataset's class name for an added object: canonical categories are translated, unknown names kept.
std::string ClassName(const AddedObject& obj, LogFormat format) {
  const std::optional<CategoryInfo> c = FindCategory(obj.category);
  return c ? DatasetCategoryName(*c, format) : obj.category;
}

double MaxVisibleFraction(const AddedObject& obj) {
  double v = -1;
  for (const CameraBox& b : obj.camera_boxes) v = std::max(v, b.visible_fraction);
  return v;
}

// nuScenes visibility token: bins of visible fraction 0-40, 40-60, 60-80, 80-100 % -> "1".."4".
std::string VisibilityToken(const AddedObject& obj) {
  double v = MaxVisibleFraction(obj);
  if (v < 0) {
    if (obj.annotation.visibility >= 1 && obj.annotation.visibility <= 4) return std::to_string(obj.annotation.visibility);
    return "";
  }
  return v <= 0.4 ? "1" : v <= 0.6 ? "2" : v <= 0.8 ? "3" : "4";
}

class SensorFileWriter {
 public:
  SensorFileWriter(const Log& log, const fs::path& out_dir, const WriteOptions& options)
      : log_(log), out_(out_dir), options_(options) {}

  void Image(const CameraSensor& cam, const ImageU8* replacement) {
    const fs::path dst = out_ / RelativePath(cam.image_path, log_.data_root);
    if (replacement) {
      if (cam.intrinsics.width > 0 && (replacement->width() != cam.intrinsics.width || replacement->height() != cam.intrinsics.height))
        throw InputError(cam.image_path, Msg() << "replacement image is " << replacement->width() << "x" << replacement->height()
                                               << ", the original is " << cam.intrinsics.width << "x" << cam.intrinsics.height);
      WriteImage(dst, *replacement, options_.jpeg_quality);
    } else {
      Unchanged(cam.image_path, dst);
    }
  }
  void Lidar(const LidarSensor& lidar, const PointCloud* replacement) {
    const fs::path dst = out_ / RelativePath(lidar.path, log_.data_root);
    if (replacement) {
      if (replacement->num_features != lidar.layout.num_features)
        throw InputError(lidar.path, Msg() << "replacement sweep has " << replacement->num_features << " features per point, the original "
                                           << lidar.layout.num_features);
      WritePointCloudBin(dst, *replacement);
    } else {
      Unchanged(lidar.path, dst);
    }
  }
  void Unchanged(const fs::path& src, const fs::path& dst) {
    if (!fs::exists(src)) {
      if (options_.require_sensor_files) throw InputError(src, "sensor file referenced by the log is missing");
      SD_LOG(Warn, src.string() << ": missing, not written to the derivative");
      return;
    }
    if (fs::exists(dst)) return;
    fs::create_directories(dst.parent_path());
    if (options_.unchanged == UnchangedFiles::kSymlink) {
      fs::create_symlink(fs::absolute(src), dst);
    } else {
      WriteFileAtomic(dst, ReadFileToString(src));
    }
  }
  void Frame(const sd::Frame& frame, const FrameEdit& edit) {
    for (const CameraSensor& cam : frame.cameras) {
      auto it = edit.images.find(cam.channel);
      Image(cam, it == edit.images.end() ? nullptr : &it->second);
    }
    for (const auto& [channel, img] : edit.images)
      if (!frame.FindCamera(channel)) throw InputError(log_.source, "edit replaces an image of unknown camera " + channel);
    if (frame.lidar) Lidar(*frame.lidar, edit.points ? &*edit.points : nullptr);
  }

 private:
  const Log& log_;
  fs::path out_;
  const WriteOptions& options_;
};

void CheckEdits(const Log& log, const std::vector<FrameEdit>& edits) {
  std::set<size_t> seen;
  for (const FrameEdit& e : edits) {
    if (e.frame_index >= log.frames.size())
      throw InputError(log.source, Msg() << "edit names frame " << e.frame_index << " but the log has " << log.frames.size());
    if (!seen.insert(e.frame_index).second) throw InputError(log.source, Msg() << "frame " << e.frame_index << " edited twice");
  }
}

fs::path InfoOutPath(const Log& log, const fs::path& out_dir) {
  return out_dir / RelativePath(fs::absolute(log.annotation_path), fs::absolute(log.data_root));
}

// ---------------------------------------------------------------------------------------------------------
// Raw JSON text. The annotation files are edited in place as text: untouched records (other frames, other
// tables, every field the edit does not extend) keep the bytes they had. Re-serialising the parsed JSON would
// not: nlohmann sorts keys, formats numbers and whitespace its own way and turns Python's NaN into null.
// The scanner only runs on text ReadPythonJson / ReadJsonFile has already accepted.

struct Span {
  size_t begin = 0, end = 0;  // [begin, end) in the file text
};

struct RawMember {
  std::string key;
  Span item;   // from the key's opening quote to the value's end
  Span value;
};

struct Splice {
  size_t begin = 0, end = 0;  // replaced range (empty: insertion)
  std::string text;
};

// How a file lays out its containers, so added records look like their neighbours: `unit` is one level of
// indentation ("" for one-line files such as Lyft's tables), separators as the file writes them.
struct JsonStyle {
  std::string unit;
  std::string item_sep = ", ";  // between items of a one-line container
  std::string key_sep = ": ";
};

class RawJson {
 public:
  RawJson(std::string text, fs::path file) : text_(std::move(text)), file_(std::move(file)) {}
  const std::string& text() const { return text_; }
  std::string_view Text(Span s) const { return std::string_view(text_).substr(s.begin, s.end - s.begin); }

  Span Root() const {
    const size_t b = SkipWs(0);
    return {b, ValueEnd(b)};
  }
  bool IsArray(Span s) const { return s.end > s.begin && text_[s.begin] == '['; }
  bool IsObject(Span s) const { return s.end > s.begin && text_[s.begin] == '{'; }

  std::vector<Span> Elements(Span arr) const {
    if (!IsArray(arr)) Fail(arr.begin, "expected an array");
    std::vector<Span> out;
    size_t i = SkipWs(arr.begin + 1);
    if (text_[i] == ']') return out;
    for (;;) {
      const size_t e = ValueEnd(i);
      out.push_back({i, e});
      i = SkipWs(e);
      if (text_[i] == ']') return out;
      if (text_[i] != ',') Fail(i, "expected ',' or ']'");
      i = SkipWs(i + 1);
    }
  }

  std::vector<RawMember> Members(Span obj) const {
    if (!IsObject(obj)) Fail(obj.begin, "expected an object");
    std::vector<RawMember> out;
    size_t i = SkipWs(obj.begin + 1);
    if (text_[i] == '}') return out;
    for (;;) {
      if (text_[i] != '"') Fail(i, "expected a key");
      const size_t key_end = ValueEnd(i);
      RawMember m;
      m.key = json::parse(Text({i, key_end})).get<std::string>();
      size_t v = SkipWs(key_end);
      if (text_[v] != ':') Fail(v, "expected ':'");
      v = SkipWs(v + 1);
      m.value = {v, ValueEnd(v)};
      m.item = {i, m.value.end};
      i = SkipWs(m.value.end);
      out.push_back(std::move(m));
      if (text_[i] == '}') return out;
      if (text_[i] != ',') Fail(i, "expected ',' or '}'");
      i = SkipWs(i + 1);
    }
  }

  std::optional<RawMember> Member(Span obj, const std::string& key) const {
    for (RawMember& m : Members(obj))
      if (m.key == key) return m;
    return std::nullopt;
  }

  // The whitespace that starts the line holding `pos`.
  std::string LineIndent(size_t pos) const {
    size_t start = text_.rfind('\n', pos == 0 ? 0 : pos - 1);
    start = start == std::string::npos ? 0 : start + 1;
    size_t e = start;
    while (e < text_.size() && (text_[e] == ' ' || text_[e] == '\t')) ++e;
    return text_.substr(start, e - start);
  }

  // The file's layout, read off its first containers.
  JsonStyle Style() const {
    JsonStyle s;
    const Span root = Root();
    if (!IsArray(root) && !IsObject(root)) return s;
    const size_t first = SkipWs(root.begin + 1);
    if (text_.substr(root.begin + 1, first - root.begin - 1).find('\n') != std::string::npos) s.unit = LineIndent(first);
    bool have_key_sep = false, have_item_sep = false;
    Span c = root;
    for (int depth = 0; depth < 64 && (IsArray(c) || IsObject(c)) && !(have_key_sep && have_item_sep); ++depth) {
      std::vector<Span> items, children;
      if (IsArray(c)) {
        items = children = Elements(c);
      } else {
        for (const RawMember& m : Members(c)) items.push_back(m.item), children.push_back(m.value);
        if (!items.empty() && !have_key_sep) {
          const size_t key_end = ValueEnd(items[0].begin);
          s.key_sep = text_.substr(key_end, children[0].begin - key_end);
          have_key_sep = true;
        }
      }
      if (items.size() >= 2 && !have_item_sep) {
        s.item_sep = text_.substr(items[0].end, items[1].begin - items[0].end);
        have_item_sep = true;
      }
      if (children.empty()) break;
      c = children[0];
    }
    if (!s.unit.empty()) s.item_sep = ",";
    return s;
  }

 private:
  size_t SkipWs(size_t i) const {
    while (i < text_.size() && (text_[i] == ' ' || text_[i] == '\t' || text_[i] == '\n' || text_[i] == '\r')) ++i;
    if (i >= text_.size()) Fail(i, "unexpected end of file");
    return i;
  }
  size_t ValueEnd(size_t i) const {
    const char c = text_[i];
    if (c == '"') {
      for (++i; i < text_.size(); ++i) {
        if (text_[i] == '\\') ++i;
        else if (text_[i] == '"') return i + 1;
      }
      Fail(i, "unterminated string");
    }
    if (c == '{' || c == '[') {
      int depth = 0;
      for (; i < text_.size(); ++i) {
        const char d = text_[i];
        if (d == '"') i = ValueEnd(i) - 1;
        else if (d == '{' || d == '[') ++depth;
        else if ((d == '}' || d == ']') && --depth == 0) return i + 1;
      }
      Fail(i, "unterminated container");
    }
    size_t e = i;
    while (e < text_.size() && !std::strchr(",]} \t\r\n", text_[e])) ++e;
    if (e == i) Fail(i, "expected a value");
    return e;
  }
  [[noreturn]] void Fail(size_t pos, const std::string& what) const {
    throw InputError(file_, Msg() << "byte " << pos << ": " << what);
  }

  std::string text_;
  fs::path file_;
};

using ojson = nlohmann::ordered_json;  // added records keep the dataset's field order
using Items = std::vector<std::pair<std::string, ojson>>;  // keys are ignored for arrays

// `v` as the file lays out its own values, starting on a line indented by `indent`. Numbers are nlohmann's
// shortest round-trip form; only added records are written this way.
std::string Serialize(const ojson& v, const JsonStyle& s, const std::string& indent) {
  if (!v.is_structured() || v.empty()) return v.dump();
  const bool array = v.is_array();
  const std::string inner = indent + s.unit;
  std::string out(1, array ? '[' : '{');
  bool first = true;
  for (auto it = v.begin(); it != v.end(); ++it) {
    if (!first) out += s.unit.empty() ? s.item_sep : ",";
    first = false;
    if (!s.unit.empty()) out += "\n" + inner;
    if (!array) out += ojson(it.key()).dump() + s.key_sep;
    out += Serialize(it.value(), s, inner);
  }
  if (!s.unit.empty()) out += "\n" + indent;
  out += array ? ']' : '}';
  return out;
}

ojson ArrayOf(const Items& items) {
  ojson a = ojson::array();
  for (const auto& kv : items) a.push_back(kv.second);
  return a;
}
ojson ObjectOf(const Items& items) {
  ojson o = ojson::object();
  for (const auto& [k, v] : items) o[k] = v;
  return o;
}

// Appends `items` to the array or object `c`, separated and indented like the items already there.
Splice AppendItems(const RawJson& j, Span c, const Items& items, const JsonStyle& s) {
  const bool array = j.IsArray(c);
  std::vector<Span> have;
  if (array) have = j.Elements(c);
  else
    for (const RawMember& m : j.Members(c)) have.push_back(m.item);
  auto item_text = [&](const std::pair<std::string, ojson>& kv, const std::string& indent) {
    return (array ? std::string() : ojson(kv.first).dump() + s.key_sep) + Serialize(kv.second, s, indent);
  };
  std::string text;
  if (!have.empty()) {
    const std::string lead(j.Text({c.begin + 1, have[0].begin}));
    std::string sep = have.size() >= 2 ? std::string(j.Text({have[0].end, have[1].begin}))
                      : lead.find('\n') != std::string::npos ? "," + lead
                      : s.unit.empty() ? s.item_sep : ",";
    const size_t nl = sep.rfind('\n');
    const std::string indent = nl == std::string::npos ? j.LineIndent(have.back().begin) : sep.substr(nl + 1);
    for (const auto& kv : items) text += sep + item_text(kv, indent);
    return {have.back().end, have.back().end, text};
  }
  if (items.empty()) return {c.end, c.end, ""};
  const std::string outer = j.LineIndent(c.begin), inner = outer + s.unit;
  for (size_t k = 0; k < items.size(); ++k) {
    if (k) text += s.unit.empty() ? s.item_sep : ",";
    if (!s.unit.empty()) text += "\n" + inner;
    text += item_text(items[k], inner);
  }
  if (!s.unit.empty()) text += "\n" + outer;
  return {c.begin + 1, c.end - 1, text};
}

// Adds `items` to the container `key` of object `obj`: appended when it is there, the value replaced when it is
// null or of another type, and the member created (in `new_members`, added to `obj` by the caller in one go)
// when it is missing. `as_object` picks the container type.
void ExtendMember(const RawJson& j, Span obj, const std::string& key, const Items& items, bool as_object, const JsonStyle& s,
                  std::vector<Splice>* splices, Items* new_members) {
  if (items.empty()) return;
  const std::optional<RawMember> m = j.Member(obj, key);
  const ojson value = as_object ? ObjectOf(items) : ArrayOf(items);
  if (!m) {
    new_members->push_back({key, value});
  } else if (as_object ? j.IsObject(m->value) : j.IsArray(m->value)) {
    splices->push_back(AppendItems(j, m->value, items, s));
  } else {
    splices->push_back({m->value.begin, m->value.end, Serialize(value, s, j.LineIndent(m->item.begin))});
  }
}

// The text of `within` with `splices` (absolute offsets inside it, non-overlapping) applied.
std::string ApplySplices(const RawJson& j, Span within, std::vector<Splice> splices) {
  std::stable_sort(splices.begin(), splices.end(), [](const Splice& a, const Splice& b) { return a.begin < b.begin; });
  std::string out;
  size_t at = within.begin;
  for (const Splice& s : splices) {
    SD_CHECK(s.begin >= at && s.end >= s.begin && s.end <= within.end, << "overlapping splice at " << s.begin);
    out += j.Text({at, s.begin});
    out += s.text;
    at = s.end;
  }
  out += j.Text({at, within.end});
  return out;
}

// The array `arr` with only the elements `keep` (their text unchanged), in that order, laid out as before.
std::string ArrayWith(const RawJson& j, Span arr, const std::vector<Span>& elements, const std::vector<std::string>& keep,
                      const JsonStyle& s) {
  if (keep.empty() || elements.empty()) return "[]";
  const std::string lead(j.Text({arr.begin + 1, elements[0].begin}));
  const std::string trail(j.Text({elements.back().end, arr.end - 1}));
  const std::string sep = elements.size() >= 2 ? std::string(j.Text({elements[0].end, elements[1].begin}))
                          : lead.find('\n') != std::string::npos ? "," + lead
                          : s.unit.empty() ? s.item_sep : ",";
  std::string out = "[" + lead;
  for (size_t k = 0; k < keep.size(); ++k) out += (k ? sep : "") + keep[k];
  return out + trail + "]";
}

// ---------------------------------------------------------------------------------------------------------
// mmdet3d v1

// mmdet3d's nuScenes attribute index for an object without motion state ('None' = 8); parked vehicles and
// standing pedestrians otherwise.
int AttrLabel(const std::string& canonical) {
  if (canonical == "car" || canonical == "truck" || canonical == "bus" || canonical == "trailer" || canonical == "construction_vehicle")
    return 6;  // vehicle.parked
  if (canonical == "pedestrian") return 3;  // pedestrian.standing
  if (canonical == "bicycle" || canonical == "motorcycle") return 1;  // cycle.without_rider
  return 8;
}

// The info file's records; InputError unless there is one per frame of the log (the readers keep them 1:1).
std::vector<Span> InfoRecords(const Log& log, const RawJson& raw, const char* key, Span* list) {
  const std::optional<RawMember> m = raw.IsObject(raw.Root()) ? raw.Member(raw.Root(), key) : std::nullopt;
  if (!m || !raw.IsArray(m->value)) throw InputError(log.annotation_path, Msg() << key << " is not an array");
  *list = m->value;
  std::vector<Span> records = raw.Elements(m->value);
  if (records.size() != log.frames.size())
    throw InputError(log.annotation_path,
                     Msg() << key << " has " << records.size() << " records, the log " << log.frames.size() << " frames");
  for (const Span& r : records)
    if (!raw.IsObject(r)) throw InputError(log.annotation_path, Msg() << key << " holds a record that is not an object");
  return records;
}

// New class names go where the metainfo keeps its class list (categories {name: index}, classes, CLASSES).
void AddV1Classes(const RawJson& raw, const std::vector<std::string>& new_names, size_t first_index, const JsonStyle& s,
                  std::vector<Splice>* splices) {
  if (new_names.empty()) return;
  Items by_index, names;
  for (size_t k = 0; k < new_names.size(); ++k) {
    by_index.push_back({new_names[k], static_cast<int>(first_index + k)});
    names.push_back({"", new_names[k]});
  }
  const Span root = raw.Root();
  const std::optional<RawMember> meta = raw.Member(root, "metainfo");
  Items top;
  if (!meta || !raw.IsObject(meta->value)) {
    ExtendMember(raw, root, "metainfo", {{"categories", ObjectOf(by_index)}}, true, s, splices, &top);
    if (!top.empty()) splices->push_back(AppendItems(raw, root, top, s));
    return;
  }
  const std::optional<RawMember> cats = raw.Member(meta->value, "categories");
  Items added;
  if (cats && raw.IsObject(cats->value)) splices->push_back(AppendItems(raw, cats->value, by_index, s));
  else if (raw.Member(meta->value, "classes")) ExtendMember(raw, meta->value, "classes", names, false, s, splices, &added);
  else if (raw.Member(meta->value, "CLASSES")) ExtendMember(raw, meta->value, "CLASSES", names, false, s, splices, &added);
  else ExtendMember(raw, meta->value, "categories", by_index, true, s, splices, &added);
  if (!added.empty()) splices->push_back(AppendItems(raw, meta->value, added, s));
}

std::vector<fs::path> WriteMmdet3dV1(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  const RawJson raw(ReadFileToString(log.annotation_path), log.annotation_path);
  const JsonStyle style = raw.Style();
  Span list;
  const std::vector<Span> records = InfoRecords(log, raw, "data_list", &list);
  std::vector<std::string> names = log.categories, new_names;
  auto label_of = [&](const std::string& cls) {
    auto it = std::find(names.begin(), names.end(), cls);
    if (it != names.end()) return static_cast<int>(it - names.begin());
    names.push_back(cls);
    new_names.push_back(cls);
    return static_cast<int>(names.size() - 1);
  };
  std::vector<std::string> kept;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const Span rec = records[e.frame_index];
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    Items instances;
    std::vector<std::string> channels;  // in order of first use
    std::map<std::string, Items> cam_instances;
    for (const AddedObject& obj : e.added) {
      const int label = label_of(ClassName(obj, LogFormat::kMmdet3dV1));
      const Box3 b = obj.annotation.box.Transformed(T_lidar_ego);
      const Eigen::Vector3d c = b.center(), s = b.size;
      ojson inst = {{"bbox_label", label},
                    {"bbox_3d", {c.x(), c.y(), c.z(), s.x(), s.y(), s.z(), b.Yaw()}},
                    {"bbox_3d_isvalid", true},
                    {"bbox_label_3d", label},
                    {"num_lidar_pts", std::max(0, obj.annotation.num_lidar_pts)},
                    {"num_radar_pts", 0},
                    {"velocity", {0.0, 0.0}}};
      if (!obj.asset_id.empty()) inst["synthdrive_asset_id"] = obj.asset_id;
      instances.push_back({"", inst});
      for (const CameraBox& cb : obj.camera_boxes) {
        const CameraSensor* cam = frame.FindCamera(cb.channel);
        if (!cam) throw InputError(log.source, "camera box for unknown camera " + cb.channel);
        const Box3 bc = obj.annotation.box.Transformed(cam->T_ego_cam.Inverse());
        const Eigen::Vector3d p = bc.center();
        const std::optional<Eigen::Vector2d> uv = cam->intrinsics.Project(p);
        if (!uv) continue;  // centre behind the camera: mmdet3d keeps no such cam_instance
        // Camera boxes: [x y z l h w yaw], yaw about camera +y (pinned in readers_test).
        ojson ci = {{"bbox_label", label},
                    {"bbox_label_3d", label},
                    {"bbox", {cb.box.x1, cb.box.y1, cb.box.x2, cb.box.y2}},
                    {"bbox_3d_isvalid", true},
                    {"bbox_3d", {p.x(), p.y(), p.z(), s.x(), s.z(), s.y(), datasets_internal::CameraYaw(bc.T_frame_box.Rotation())}},
                    {"velocity", {0.0, 0.0}},
                    {"center_2d", {uv->x(), uv->y()}},
                    {"depth", p.z()},
                    {"attr_label", AttrLabel(FindCategory(obj.category) ? FindCategory(obj.category)->name : "")}};
        if (!cam_instances.count(cb.channel)) channels.push_back(cb.channel);
        cam_instances[cb.channel].push_back({"", ci});
      }
    }
    std::vector<Splice> splices;
    Items new_members;
    ExtendMember(raw, rec, "instances", instances, false, style, &splices, &new_members);
    if (!channels.empty()) {
      const std::optional<RawMember> m = raw.Member(rec, "cam_instances");
      if (m && raw.IsObject(m->value)) {
        Items new_channels;
        for (const std::string& ch : channels)
          ExtendMember(raw, m->value, ch, cam_instances[ch], false, style, &splices, &new_channels);
        if (!new_channels.empty()) splices.push_back(AppendItems(raw, m->value, new_channels, style));
      } else {
        Items by_channel;
        for (const std::string& ch : channels) by_channel.push_back({ch, ArrayOf(cam_instances[ch])});
        ExtendMember(raw, rec, "cam_instances", by_channel, true, style, &splices, &new_members);
      }
    }
    if (!new_members.empty()) splices.push_back(AppendItems(raw, rec, new_members, style));
    kept.push_back(ApplySplices(raw, rec, splices));
  }
  std::vector<Splice> splices;
  AddV1Classes(raw, new_names, log.categories.size(), style, &splices);
  splices.push_back({list.begin, list.end, ArrayWith(raw, list, records, kept, style)});
  const fs::path dst = InfoOutPath(log, out_dir);
  WriteFileAtomic(dst, ApplySplices(raw, {0, raw.text().size()}, splices));
  return {dst};
}

// ---------------------------------------------------------------------------------------------------------
// mmdet3d v0

std::vector<fs::path> WriteMmdet3dV0(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  const RawJson raw(ReadFileToString(log.annotation_path), log.annotation_path);
  const JsonStyle style = raw.Style();
  Span list;
  const std::vector<Span> records = InfoRecords(log, raw, "infos", &list);
  std::vector<std::string> kept;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const Span rec = records[e.frame_index];
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    Items boxes, names, velocities, lidar_pts, radar_pts, valid;
    for (const AddedObject& obj : e.added) {
      const Box3 b = obj.annotation.box.Transformed(T_lidar_ego);
      const Eigen::Vector3d c = b.center(), s = b.size;
      double yaw_old = -b.Yaw() - kPi / 2;
      yaw_old = std::atan2(std::sin(yaw_old), std::cos(yaw_old));
      boxes.push_back({"", {c.x(), c.y(), c.z(), s.y(), s.x(), s.z(), yaw_old}});  // w before l
      names.push_back({"", ClassName(obj, LogFormat::kMmdet3dV0)});
      velocities.push_back({"", {0.0, 0.0}});
      lidar_pts.push_back({"", std::max(0, obj.annotation.num_lidar_pts)});
      radar_pts.push_back({"", 0});
      valid.push_back({"", obj.annotation.num_lidar_pts != 0});
    }
    std::vector<Splice> splices;
    Items new_members;
    const std::pair<const char*, const Items*> columns[] = {{"gt_boxes", &boxes},         {"gt_names", &names},
                                                            {"gt_velocity", &velocities}, {"num_lidar_pts", &lidar_pts},
                                                            {"num_radar_pts", &radar_pts}, {"valid_flag", &valid}};
    for (const auto& [key, items] : columns) ExtendMember(raw, rec, key, *items, false, style, &splices, &new_members);
    if (!new_members.empty()) splices.push_back(AppendItems(raw, rec, new_members, style));
    kept.push_back(ApplySplices(raw, rec, splices));
  }
  const fs::path dst = InfoOutPath(log, out_dir);
  WriteFileAtomic(dst, ApplySplices(raw, {0, raw.text().size()}, {{list.begin, list.end, ArrayWith(raw, list, records, kept, style)}}));
  return {dst};
}

// ---------------------------------------------------------------------------------------------------------
// nuScenes tables

json ReadTableOrEmpty(const fs::path& p) { return fs::exists(p) ? ReadJsonFile(p) : json::array(); }

// Writes table `src` with `records` appended at `dst`; a missing table is created in `style`.
void AppendToTable(const fs::path& src, const fs::path& dst, const Items& records, const JsonStyle& style, const std::string& eof) {
  if (!fs::exists(src)) {
    WriteFileAtomic(dst, Serialize(ArrayOf(records), style, "") + eof);
    return;
  }
  const RawJson raw(ReadFileToString(src), src);
  const Span root = raw.Root();
  if (!raw.IsArray(root)) throw InputError(src, "expected a JSON array of records");
  const JsonStyle own = raw.Elements(root).empty() ? style : raw.Style();
  WriteFileAtomic(dst, ApplySplices(raw, {0, raw.text().size()}, {AppendItems(raw, root, records, own)}));
}

std::vector<fs::path> WriteNuScenesTables(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  const fs::path vdir = log.annotation_path;
  const fs::path out_vdir = out_dir / RelativePath(fs::absolute(vdir), fs::absolute(log.data_root));
  const json categories = ReadTableOrEmpty(vdir / "category.json");
  Items annotations, instances, new_categories;
  std::map<std::string, std::string> new_category_tokens;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    for (size_t k = 0; k < e.added.size(); ++k) {
      const AddedObject& obj = e.added[k];
      const std::string name = ClassName(obj, LogFormat::kNuScenesTables);
      // The dataset's own record for this class: its exact nuScenes name, else any name that means the same
      // canonical class (Lyft calls vehicle.car "car").
      std::string cat_token;
      for (const json& c : categories)
        if (c.value("name", "") == name) cat_token = c.value("token", "");
      const std::optional<CategoryInfo> canonical = FindCategory(obj.category);
      for (const json& c : categories) {
        if (!cat_token.empty() || !canonical) break;
        const std::optional<CategoryInfo> other = FindCategory(c.value("name", ""));
        if (other && other->name == canonical->name) cat_token = c.value("token", "");
      }
      if (cat_token.empty() && new_category_tokens.count(name)) cat_token = new_category_tokens[name];
      if (cat_token.empty()) {
        cat_token = new_category_tokens[name] = datasets_internal::HexToken("category:" + name);
        new_categories.push_back({"", {{"token", cat_token}, {"name", name}, {"description", "added by SynthDrive"}}});
      }
      const std::string seed = Msg() << frame.token << "/" << k << "/" << obj.asset_id << "/" << name;
      const std::string ann_token = datasets_internal::HexToken("ann:" + seed), inst_token = datasets_internal::HexToken("inst:" + seed);
      const Box3 b = obj.annotation.box.Transformed(frame.T_world_ego);
      const Eigen::Quaterniond q = b.T_frame_box.rotation;
      annotations.push_back({"",
                             {{"token", ann_token},
                              {"sample_token", frame.token},
                              {"instance_token", inst_token},
                              {"visibility_token", VisibilityToken(obj)},
                              {"attribute_tokens", ojson::array()},
                              {"translation", {b.center().x(), b.center().y(), b.center().z()}},
                              {"size", {b.size.y(), b.size.x(), b.size.z()}},  // w, l, h
                              {"rotation", {q.w(), q.x(), q.y(), q.z()}},
                              {"prev", ""},
                              {"next", ""},
                              {"num_lidar_pts", std::max(0, obj.annotation.num_lidar_pts)},
                              {"num_radar_pts", 0}}});
      instances.push_back({"",
                           {{"token", inst_token},
                            {"category_token", cat_token},
                            {"nbr_annotations", 1},
                            {"first_annotation_token", ann_token},
                            {"last_annotation_token", ann_token}}});
    }
  }
  // Tables we do not extend are copied byte for byte; the ones we extend get records appended as text, so
  // every existing record keeps its bytes too. A table the input lacks is created in sample.json's layout.
  const std::map<std::string, const Items*> extended = {
      {"sample_annotation.json", &annotations}, {"instance.json", &instances}, {"category.json", &new_categories}};
  for (const auto& entry : fs::directory_iterator(vdir)) {
    if (!entry.is_regular_file() || entry.path().extension() != ".json") continue;
    auto it = extended.find(entry.path().filename().string());
    if (it == extended.end() || it->second->empty()) WriteFileAtomic(out_vdir / entry.path().filename(), ReadFileToString(entry.path()));
  }
  JsonStyle style;
  std::string eof;
  if (fs::exists(vdir / "sample.json")) {
    const RawJson sample(ReadFileToString(vdir / "sample.json"), vdir / "sample.json");
    style = sample.Style();
    eof = sample.text().substr(sample.Root().end);
  }
  std::vector<fs::path> written;
  for (const auto& [file, records] : {std::pair<std::string, const Items*>{"sample_annotation.json", &annotations},
                                      {"instance.json", &instances}, {"category.json", &new_categories}}) {
    if (!records->empty()) AppendToTable(vdir / file, out_vdir / file, *records, style, eof);
    if (!records->empty() || (file != "category.json" && fs::exists(vdir / file))) written.push_back(out_vdir / file);
  }
  return written;
}

// ---------------------------------------------------------------------------------------------------------
// KITTI

std::vector<fs::path> WriteKitti(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  std::vector<fs::path> written;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const fs::path calib_src = log.data_root / "calib" / (frame.token + ".txt");
    const datasets_internal::KittiCalib calib = datasets_internal::ReadKittiCalib(calib_src);
    const Rigid3d T_rect0_velo = calib.T_rect0_velo();
    WriteFileAtomic(out_dir / "calib" / (frame.token + ".txt"), ReadFileToString(calib_src));
    const fs::path label_src = log.annotation_path / (frame.token + ".txt");
    std::string text = fs::exists(label_src) ? ReadFileToString(label_src) : std::string();
    if (!text.empty() && text.back() != '\n') text += '\n';
    for (const AddedObject& obj : e.added) {
      const Box3 b = obj.annotation.box.Transformed(T_rect0_velo);
      const Eigen::Vector3d x_axis = b.T_frame_box.Rotation().col(0);
      const double ry = std::atan2(-x_axis.z(), x_axis.x());
      const double l = b.size.x(), w = b.size.y(), h = b.size.z();
      const Eigen::Vector3d bottom = b.center() + Eigen::Vector3d(0, h / 2, 0);  // rect cam0: y down
      double alpha = ry - std::atan2(bottom.x(), bottom.z());
      alpha = std::atan2(std::sin(alpha), std::cos(alpha));
      Box2 box2;
      double truncation = 0, visible = -1;
      for (const CameraBox& cb : obj.camera_boxes)
        if (cb.channel == "image_2") {
          box2 = cb.box;
          truncation = cb.truncation;
          visible = cb.visible_fraction;
        }
      // KITTI occlusion: 0 fully visible, 1 partly, 2 largely occluded, 3 unknown.
      const int occluded = visible < 0 ? 3 : visible > 0.8 ? 0 : visible > 0.4 ? 1 : 2;
      std::ostringstream line;
      line << ClassName(obj, LogFormat::kKitti) << ' ' << Fixed(std::clamp(truncation, 0.0, 1.0), 2) << ' ' << occluded
           << ' ' << Fixed(alpha, 2) << ' ' << Fixed(box2.x1, 2) << ' ' << Fixed(box2.y1, 2) << ' ' << Fixed(box2.x2, 2)
           << ' ' << Fixed(box2.y2, 2)
           // Sub-millimetre digits (official labels carry 2) so the box survives a round trip to 1e-4 m.
           << ' ' << Fixed(h, 6) << ' ' << Fixed(w, 6) << ' ' << Fixed(l, 6) << ' ' << Fixed(bottom.x(), 6) << ' '
           << Fixed(bottom.y(), 6) << ' ' << Fixed(bottom.z(), 6) << ' ' << Fixed(ry, 6) << '\n';
      text += line.str();
    }
    const fs::path label_dst = out_dir / "label_2" / (frame.token + ".txt");
    WriteFileAtomic(label_dst, text);
    written.push_back(label_dst);
  }
  return written;
}

}  // namespace

std::vector<fs::path> WriteDerivative(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                      const WriteOptions& options) {
  if (!fs::is_directory(out_dir)) throw InputError(out_dir, "output directory does not exist");
  CheckEdits(log, edits);
  if (log.format == LogFormat::kArgoverse2)
    throw InputError(log.source, "writing Argoverse 2 logs is not supported (their tables are Apache Arrow files)");
  SensorFileWriter files(log, out_dir, options);
  for (const FrameEdit& e : edits) files.Frame(log.frames[e.frame_index], e);
  switch (log.format) {
    case LogFormat::kMmdet3dV1: return WriteMmdet3dV1(log, edits, out_dir);
    case LogFormat::kMmdet3dV0: return WriteMmdet3dV0(log, edits, out_dir);
    case LogFormat::kNuScenesTables: return WriteNuScenesTables(log, edits, out_dir);
    case LogFormat::kKitti: return WriteKitti(log, edits, out_dir);
    case LogFormat::kArgoverse2: break;  // refused above
  }
  return {};
}

}  // namespace sd
