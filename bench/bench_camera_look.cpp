// bench_camera_look: do inserted objects measure like the real objects of the same image? Synthesises frames of
// the repo's nuScenes keyframe and KITTI frames, and of PandaSet (../shared, a lane closure, world-fixed), with
// the camera's look off and on (synth/camera_look.h), and measures every real annotated object and every
// inserted one the same way (synth/realism.h): noise relative to the image's own model, 10-90 % edge rise,
// saturation (and against real objects of the same category). Prints a table per log and writes
// bench/results/camera_look.json. A plain program.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_demo.h"
#include "datasets/categories.h"
#include "io/files.h"
#include "io/json.h"
#include "io/image_io.h"
#include "synth/batch.h"
#include "synth/camera_look.h"
#include "synth/realism.h"

namespace {
namespace fs = std::filesystem;

// Real objects worth measuring: at least 24 px tall and mostly inside the image.
bool Measurable(const sd::ObjectLook& o) { return o.pixels >= 24 * 12; }

struct Run {
  std::string log, mode;
  std::vector<sd::ObjectLook> objects;
  std::vector<double> shadow_grain;  // per shadowed road block: its residual sigma after / before
  std::vector<sd::ShadowContrast> shadows;  // cast shadows' road darkening, real and inserted objects
  std::vector<sd::ContactDarkening> contacts;  // the road at their foot against the road around them
  double seconds = 0;
};

// The grain the inserted shadows add to the road: over the 8x8 blocks that the insertion changed entirely and that
// lie outside every inserted object's outline (shadow on real road), the block's residual sigma after over before
// (green). A clean shadow scales the road's own grain by its shade (< 1); sampling noise raises it.
void ShadowGrain(const sd::CameraOutcome& co, const sd::CameraSensor& cam, const std::vector<sd::Box3>& inserted,
                 std::vector<double>* out) {
  const sd::ImageF objects = sd::ObjectOutlinesMask(cam, inserted, 0);
  for (int by = 0; by + 1 < co.after.height() / 8; ++by)
    for (int bx = 0; bx + 1 < co.after.width() / 8; ++bx) {
      int changed = 0;
      bool on_object = false;
      for (int y = by * 8; y < by * 8 + 8; ++y)
        for (int x = bx * 8; x < bx * 8 + 8; ++x) {
          on_object = on_object || objects.at(x, y) > 0;
          changed += co.after.at(x, y, 1) != co.before.at(x, y, 1) ? 1 : 0;
        }
      if (on_object || changed < 60) continue;
      const double before = sd::BlockNoiseSigma(co.before, bx, by, 1);
      if (before < 0.3) continue;  // a block the camera's JPEG flattened: no grain to compare with
      out->push_back(sd::BlockNoiseSigma(co.after, bx, by, 1) / before);
    }
}

Run Measure(const std::string& name, const sd::Log& log, const std::vector<size_t>& frames, const std::vector<sd::Asset>& assets,
            const sd::Scenario& scenario, const sd::SynthPlan* plan, const sd::CameraLookOptions& look_options,
            const std::string& mode) {
  Run run{name, mode, {}, {}, {}, {}, 0};
  sd::SynthOptions options;
  options.camera_look = look_options;
  for (size_t fi : frames) {
    const auto t0 = std::chrono::steady_clock::now();
    sd::FrameOutcome out;
    try {
      out = sd::SynthesizeFrame(log, fi, assets, scenario, options, plan ? plan->ForFrame(fi) : nullptr);
    } catch (const sd::InputError& e) {
      std::printf("(%s frame %zu: %s; skipped)\n", name.c_str(), fi, e.what());
      continue;
    }
    run.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const sd::Frame& frame = log.frames[fi];
    // Shadows over the frame's final images (the untouched cameras' are the originals).
    std::vector<sd::ImageF> linear;
    for (const sd::CameraSensor& cam : frame.cameras) {
      const sd::CameraOutcome* touched = nullptr;
      for (const sd::CameraOutcome& co : out.cameras)
        if (co.channel == cam.channel) touched = &co;
      linear.push_back(sd::ToLinear(touched ? touched->after : sd::ReadImage(cam.image_path, 3)));
    }
    std::vector<std::pair<std::string, sd::Box3>> inserted;
    for (const sd::ObjectOutcome& ob : out.objects) inserted.emplace_back(ob.label.category, ob.placement.box);
    for (sd::ShadowContrast& s : sd::MeasureShadowContrasts(frame, inserted, linear, out.sun_direction_ego))
      run.shadows.push_back(std::move(s));
    for (sd::ContactDarkening& c : sd::MeasureContactDarkening(frame, inserted, linear, out.sun_direction_ego))
      run.contacts.push_back(std::move(c));
    for (const sd::CameraOutcome& co : out.cameras) {
      const sd::CameraSensor* cam = frame.FindCamera(co.channel);
      // The image's own look, from the photograph before insertion.
      const sd::CameraLook look = sd::EstimateCameraLook(co.before, std::nullopt);  // its noise model
      for (const sd::Annotation& a : frame.annotations) {
        sd::ObjectLook o = sd::MeasureObjectLook(co.after, *cam, a.box, look);
        o.category = sd::CanonicalCategory(a.category);
        if (Measurable(o)) run.objects.push_back(o);
      }
      std::vector<sd::Box3> inserted_boxes;
      for (const sd::ObjectOutcome& ob : out.objects) inserted_boxes.push_back(ob.placement.box);
      ShadowGrain(co, *cam, inserted_boxes, &run.shadow_grain);
      for (int k : co.objects) {
        sd::ObjectLook o = sd::MeasureObjectLook(co.after, *cam, out.objects[static_cast<size_t>(k)].placement.box, look);
        o.category = sd::CanonicalCategory(out.objects[static_cast<size_t>(k)].label.category);
        o.inserted = true;
        if (o.pixels > 0) run.objects.push_back(o);
      }
    }
  }
  return run;
}

// Saturation against the real objects of the same category (the target: within 1.3x), per category
// with both real and inserted objects.
nlohmann::json CategoryRows(const Run& r) {
  std::map<std::string, std::vector<sd::ObjectLook>> by_category;
  for (const sd::ObjectLook& o : r.objects) by_category[o.category].push_back(o);
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [category, objects] : by_category) {
    const sd::LookComparison c = sd::CompareLooks(objects);
    if (c.real == 0 || c.inserted == 0) continue;
    std::printf("| %-22s | %-22s | %-13s | %3d | %3d | %5.2f | %5.2f | **%4.2f** |\n", r.log.c_str(), r.mode.c_str(),
                category.c_str(), c.real, c.inserted, c.real_saturation, c.inserted_saturation,
                c.inserted_saturation / std::max(c.real_saturation, 1e-6));
    out.push_back({{"log", r.log}, {"mode", r.mode}, {"category", category}, {"real_objects", c.real},
                   {"inserted_objects", c.inserted}, {"saturation", {{"real", c.real_saturation}, {"inserted", c.inserted_saturation}}}});
  }
  return out;
}

nlohmann::json Row(const Run& r) {
  const sd::LookComparison c = sd::CompareLooks(r.objects);
  const sd::TwoSampleTest t = sd::ClassifyRealVsInserted(r.objects);
  std::vector<double> grain = r.shadow_grain;
  std::sort(grain.begin(), grain.end());
  const double grain_median = grain.empty() ? 0.0 : grain[grain.size() / 2];
  std::printf("| %-22s | %-22s | %3d | %3d | %5.2f | %5.2f | %5.2f | %5.2f | %5.2f | %5.2f | %5.2f | %5.2f | %5.2f (%zu) | %4.2f | %6.1f |\n", r.log.c_str(),
              r.mode.c_str(), c.real, c.inserted, c.real_noise, c.inserted_noise,
              c.real_noise > 0 ? c.inserted_noise / c.real_noise : 0.0, c.real_edge_rise, c.inserted_edge_rise,
              c.real_edge_rise > 0 ? c.inserted_edge_rise / c.real_edge_rise : 0.0, c.real_saturation, c.inserted_saturation,
              grain_median, grain.size(), t.balanced_accuracy, r.seconds);
  const sd::ShadowComparison sh = sd::CompareShadows(r.shadows);
  std::printf("|   cast shadows (lit/shadow road, 1 = none): real %.2f (%d objects), inserted %.2f (%d)\n", sh.real_contrast,
              sh.real, sh.inserted_contrast, sh.inserted);
  nlohmann::json contact = nlohmann::json::array();
  for (const sd::ContactComparison& cc : sd::CompareContacts(r.contacts)) {
    std::printf("|   contact darkening %s(road 0.6-1 m / 3-20 cm, 1 = none): real %.2f (%d objects), inserted %.2f (%d)\n",
                cc.category.empty() ? "" : (cc.category + " ").c_str(), cc.real_darkening, cc.real, cc.inserted_darkening,
                cc.inserted);
    contact.push_back({{"category", cc.category}, {"real", cc.real_darkening}, {"real_objects", cc.real},
                       {"inserted", cc.inserted_darkening}, {"inserted_objects", cc.inserted}});
  }
  nlohmann::json shadows = nlohmann::json::array();
  for (const sd::ShadowContrast& s : r.shadows)
    shadows.push_back({{"frame", s.frame}, {"camera", s.channel}, {"category", s.category}, {"inserted", s.inserted},
                       {"contrast", s.contrast}});
  return {{"log", r.log},
          {"mode", r.mode},
          {"shadow_contrast", {{"real", sh.real_contrast}, {"real_objects", sh.real}, {"inserted", sh.inserted_contrast},
                               {"inserted_objects", sh.inserted}, {"objects", shadows}}},
          {"contact_darkening", contact},
          {"real_objects", c.real},
          {"inserted_objects", c.inserted},
          {"noise", {{"real", c.real_noise}, {"inserted", c.inserted_noise}}},
          {"edge_rise_px", {{"real", c.real_edge_rise}, {"inserted", c.inserted_edge_rise}}},
          {"saturation", {{"real", c.real_saturation}, {"inserted", c.inserted_saturation}}},
          {"shadow_grain", {{"median", grain_median}, {"blocks", grain.size()}}},
          {"classifier", t.ToJson()},
          {"seconds", r.seconds}};
}

}  // namespace

int main(int argc, char** argv) {
  // --assets DIR: a folder of generated asset folders (what `synthdrive demo` writes to out/demo/assets, or a
  // bank's): a third run per log with those assets standing in for the CG meshes of their categories.
  fs::path generated_dir;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--assets" && i + 1 < argc) {
      generated_dir = argv[++i];
    } else {
      std::fprintf(stderr, "bench_camera_look: unknown argument %s (usage: bench_camera_look [--assets DIR])\n", a.c_str());
      return 2;
    }
  }
  const auto root = sd::bench::FindRepoRoot();
  if (!root) {
    std::fprintf(stderr, "bench_camera_look: cannot find the repo's data/ (set SYNTHDRIVE_SOURCE_DIR)\n");
    return 2;
  }
  const fs::path data = *root / "data";
  const fs::path tmp = fs::temp_directory_path() / ("bench_camera_look_" + std::to_string(::getpid()));
  std::vector<sd::Asset> assets;
  for (const sd::bench::DemoMesh& m : sd::bench::DemoMeshes())
    assets.push_back(sd::bench::ImportDemoAsset(data, m, tmp / "assets" / m.id));
  std::vector<sd::Asset> generated;
  if (!generated_dir.empty()) {
    std::map<std::string, int> per_category;
    for (const auto& entry : fs::directory_iterator(generated_dir)) {
      if (!fs::exists(entry.path() / "asset.json")) continue;
      generated.push_back(sd::LoadAsset(entry.path()));
      ++per_category[generated.back().info.category];
    }
    // The CG meshes stay for the categories the folder has none of.
    for (const sd::Asset& a : assets)
      if (!per_category.count(a.info.category)) generated.push_back(a);
    for (const auto& [category, n] : per_category) std::printf("generated %s: %d asset(s)\n", category.c_str(), n);
  }
  const sd::CameraLookOptions off{false, false, false, false}, on{};
  struct Mode {
    sd::CameraLookOptions look;
    const char* name;
    const std::vector<sd::Asset>* assets;
  };
  std::vector<Mode> modes = {{off, "off", &assets}, {on, "blur+noise+jpeg+colour", &assets}};
  if (!generated.empty()) modes.push_back({on, "look + generated assets", &generated});
  std::printf("| log | camera look | real | ins | noise real | noise ins | ratio | rise real px | rise ins px | ratio | sat real | sat ins | shadow grain (blocks) | classifier | s |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  nlohmann::json rows = nlohmann::json::array();
  std::vector<Run> runs;
  const auto row = [&](Run r) {
    rows.push_back(Row(r));
    runs.push_back(std::move(r));
  };

  {
    const sd::Log log = sd::OpenLog(data / "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");
    const sd::Scenario scenario = sd::ReadScenario(data / "scenarios/demo.json");
    for (const Mode& m : modes) row(Measure("nuScenes keyframe", log, {0}, *m.assets, scenario, nullptr, m.look, m.name));
  }
  {
    const sd::Log log = sd::OpenLog(data / "driving/kitti-object");
    // KITTI's frames are narrow city streets: the demo's cones and barrier only, nearer.
    sd::Scenario scenario = sd::ReadScenario(data / "scenarios/demo.json");
    scenario.objects.resize(2);
    for (sd::ObjectRequest& r : scenario.objects) r.distance_min = 6, r.distance_max = 20, r.lateral_min = -4, r.lateral_max = 4;
    std::vector<size_t> frames;
    for (size_t i = 0; i < log.frames.size(); ++i) frames.push_back(i);
    for (const Mode& m : modes) row(Measure("KITTI (3 frames)", log, frames, *m.assets, scenario, nullptr, m.look, m.name));
  }
  const fs::path seq = *root / ".." / "shared" / "data" / "driving" / "pandaset-002-f44-55";
  if (fs::is_directory(seq)) {
    const sd::Log log = sd::OpenLog(seq);
    const fs::path scenario_file = data / "scenarios" / "pandaset_closure.json";
    const sd::Scenario scenario = sd::ReadScenario(scenario_file);
    const std::vector<size_t> frames = {0, 4, 8, 11};
    std::vector<size_t> all;
    for (size_t i = 0; i < log.frames.size(); ++i) all.push_back(i);
    for (const Mode& m : modes) {
      try {
        const sd::SynthPlan plan = sd::PlanSynthesis(log, all, scenario, *m.assets, scenario_file, true);
        row(Measure("PandaSet 002 (4 frames)", log, frames, *m.assets, scenario, &plan, m.look, m.name));
      } catch (const sd::InputError& e) {
        std::printf("(PandaSet, %s: no plan: %s)\n", m.name, e.what());
      }
    }
  } else {
    std::printf("(PandaSet: %s not present; skipped)\n", seq.string().c_str());
  }
  std::printf("\n| log | camera look | category | real | ins | sat real | sat ins | ratio |\n|---|---|---|---|---|---|---|---|\n");
  nlohmann::json categories = nlohmann::json::array();
  for (const Run& r : runs)
    for (const auto& c : CategoryRows(r)) categories.push_back(c);
  std::error_code ec;
  fs::remove_all(tmp, ec);
  const fs::path out = *root / "bench" / "results" / "camera_look.json";
  sd::WriteJsonFile(out, {{"tool", "bench_camera_look"}, {"rows", rows}, {"same_category", categories}});
  std::printf("-> %s\n", out.string().c_str());
  return 0;
}
