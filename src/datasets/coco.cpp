#include "datasets/coco.h"

#include <algorithm>
#include <map>
#include <set>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/json.h"

namespace fs = std::filesystem;

namespace sd {

namespace {

using ojson = nlohmann::ordered_json;  // fields in COCO's usual order, and the same order on every run

// 1-based id of the canonical category `name`; 0 when it has none.
int64_t CategoryId(const std::string& name) {
  const std::optional<CategoryInfo> c = FindCategory(name);
  if (!c) return 0;
  const std::vector<CategoryInfo>& all = Categories();
  for (size_t k = 0; k < all.size(); ++k)
    if (all[k].name == c->name) return static_cast<int64_t>(k + 1);
  return 0;
}

ojson CocoBox(const Box2& b) {
  const double w = b.x2 - b.x1, h = b.y2 - b.y1;
  return {{"bbox", {b.x1, b.y1, w, h}}, {"area", w * h}};
}

}  // namespace

void WriteCoco2D(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& file, const Coco2DOptions& options) {
  std::vector<const FrameEdit*> sorted;
  std::set<size_t> seen;
  for (const FrameEdit& e : edits) {
    if (e.frame_index >= log.frames.size())
      throw InputError(log.source, Msg() << "edit names frame " << e.frame_index << " but the log has " << log.frames.size());
    if (!seen.insert(e.frame_index).second) throw InputError(log.source, Msg() << "frame " << e.frame_index << " edited twice");
    sorted.push_back(&e);
  }
  std::sort(sorted.begin(), sorted.end(), [](const FrameEdit* a, const FrameEdit* b) { return a->frame_index < b->frame_index; });
  size_t max_cameras = 1;
  for (const Frame& f : log.frames) max_cameras = std::max(max_cameras, f.cameras.size());

  ojson images = ojson::array(), annotations = ojson::array();
  int64_t next_annotation = 1;
  for (const FrameEdit* e : sorted) {
    const Frame& frame = log.frames[e->frame_index];
    for (const AddedObject& obj : e->added) {
      if (!CategoryId(obj.category)) throw InputError(log.source, "added object of unknown category " + obj.category);
      for (const CameraBox& cb : obj.camera_boxes)
        if (!frame.FindCamera(cb.channel))
          throw InputError(log.source, Msg() << "frame " << frame.token << ": camera box for unknown camera " << cb.channel);
    }
    for (size_t c = 0; c < frame.cameras.size(); ++c) {
      const CameraSensor& cam = frame.cameras[c];
      const int64_t image_id = static_cast<int64_t>(e->frame_index * max_cameras + c + 1);
      images.push_back({{"id", image_id},
                        {"file_name", datasets_internal::RelativePath(cam.image_path, log.data_root)},
                        {"width", cam.intrinsics.width},
                        {"height", cam.intrinsics.height},
                        {"frame_token", frame.token},
                        {"frame_index", e->frame_index},
                        {"channel", cam.channel}});
      auto add = [&](const Box2& box, int64_t category_id, ojson extra) {
        if (box.Empty()) return;
        ojson a = {{"id", next_annotation++}, {"image_id", image_id}, {"category_id", category_id}};
        a.update(CocoBox(box));
        a["iscrowd"] = 0;
        a.update(extra);
        annotations.push_back(std::move(a));
      };
      if (options.real_boxes) {
        for (const Annotation& ann : frame.annotations) {
          if (ann.detected) continue;  // keep-out only (synth/detected_tracks.h): never a label
          auto it = ann.box2d_by_camera.find(cam.channel);
          const int64_t category_id = CategoryId(ann.category);
          if (it == ann.box2d_by_camera.end() || !category_id) continue;
          ojson extra = {{"synthetic", false}, {"dataset_category", ann.category}};
          if (!ann.token.empty()) extra["annotation_token"] = ann.token;
          add(it->second, category_id, std::move(extra));
        }
      }
      for (const AddedObject& obj : e->added)
        for (const CameraBox& cb : obj.camera_boxes)
          if (cb.channel == cam.channel)
            add(cb.box, CategoryId(obj.category),
                {{"synthetic", true},
                 {"visible_fraction", cb.visible_fraction},
                 {"truncation", cb.truncation},
                 {"asset_id", obj.asset_id}});
    }
  }
  ojson categories = ojson::array();
  const std::vector<CategoryInfo>& all = Categories();
  for (size_t k = 0; k < all.size(); ++k)
    categories.push_back({{"id", static_cast<int64_t>(k + 1)},
                          {"name", all[k].name},
                          {"supercategory", all[k].nuscenes_name.substr(0, all[k].nuscenes_name.find('.'))}});
  ojson out = ojson::object();
  const std::string log_name = log.name.empty() ? log.source.filename().string() : log.name;
  out["info"] = {{"description", options.description.empty() ? "SynthDrive 2D boxes of " + log_name : options.description},
                 {"source_format", ToString(log.format)},
                 {"version", "1.0"}};
  out["licenses"] = ojson::array();
  out["images"] = std::move(images);
  out["annotations"] = std::move(annotations);
  out["categories"] = std::move(categories);
  WriteFileAtomic(file, out.dump() + "\n");
}

Coco2D ReadCoco2D(const fs::path& path) {
  const nlohmann::json j = ReadJsonFile(path);
  const JsonReader root(j, path);
  if (!j.is_object()) root.Fail("expected a COCO object with images, annotations and categories");
  Coco2D coco;
  std::map<int64_t, size_t> image_index, category_index;
  const JsonReader cats = root["categories"];
  for (size_t k = 0; k < cats.Size(); ++k) {
    CocoCategory c;
    c.id = cats[k]["id"].Integer();
    c.name = cats[k]["name"].String();
    if (!category_index.emplace(c.id, coco.categories.size()).second) cats[k]["id"].Fail(Msg() << "duplicate category id " << c.id);
    coco.categories.push_back(std::move(c));
  }
  const JsonReader images = root["images"];
  for (size_t k = 0; k < images.Size(); ++k) {
    const JsonReader r = images[k];
    CocoImage im;
    im.id = r["id"].Integer();
    im.file_name = r["file_name"].String();
    im.width = static_cast<int>(r["width"].Integer());
    im.height = static_cast<int>(r["height"].Integer());
    im.frame_token = r.StringOr("frame_token", "");
    im.channel = r.StringOr("channel", "");
    if (im.width <= 0 || im.height <= 0) r.Fail(Msg() << "image size " << im.width << "x" << im.height);
    if (!image_index.emplace(im.id, coco.images.size()).second) r["id"].Fail(Msg() << "duplicate image id " << im.id);
    coco.images.push_back(std::move(im));
  }
  const JsonReader anns = root["annotations"];
  std::set<int64_t> ids;
  for (size_t k = 0; k < anns.Size(); ++k) {
    const JsonReader r = anns[k];
    CocoAnnotation a;
    a.id = r["id"].Integer();
    if (!ids.insert(a.id).second) r["id"].Fail(Msg() << "duplicate annotation id " << a.id);
    a.image_id = r["image_id"].Integer();
    if (!image_index.count(a.image_id)) r["image_id"].Fail(Msg() << "no image with id " << a.image_id);
    a.category_id = r["category_id"].Integer();
    auto cat = category_index.find(a.category_id);
    if (cat == category_index.end()) r["category_id"].Fail(Msg() << "no category with id " << a.category_id);
    a.category = coco.categories[cat->second].name;
    const JsonReader b = r["bbox"];
    if (b.Size() != 4) b.Fail(Msg() << "expected 4 numbers [x, y, w, h], found " << b.Size());
    const double x = b[0].Number(), y = b[1].Number(), w = b[2].Number(), h = b[3].Number();
    if (!(w >= 0 && h >= 0)) b.Fail(Msg() << "negative box size " << w << "x" << h);
    a.box = {x, y, x + w, y + h};
    a.area = r.NumberOr("area", w * h);
    if (r.Has("iscrowd")) a.iscrowd = r["iscrowd"].raw().is_boolean() ? r["iscrowd"].Bool() : r["iscrowd"].Integer() != 0;
    if (r.Has("synthetic")) a.synthetic = r["synthetic"].Bool();
    a.visible_fraction = r.NumberOr("visible_fraction", -1);
    a.truncation = r.NumberOr("truncation", -1);
    a.asset_id = r.StringOr("asset_id", "");
    coco.annotations.push_back(std::move(a));
  }
  return coco;
}

}  // namespace sd
