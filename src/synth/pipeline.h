#pragma once
// `synthdrive synth`: insert assets into a real driving log, camera and LiDAR, with labels, written as a
// derivative dataset in the input's own format.
#include <filesystem>
#include <string>
#include <vector>

#include "assetgen/asset.h"
#include "core/image.h"
#include "datasets/readers.h"
#include "datasets/writers.h"
#include "synth/ground.h"
#include "synth/placement.h"
#include "synth/scenario.h"

namespace sd {

struct SynthOptions {
  int samples_per_pixel = 4;
  int ao_samples = 16;
  std::vector<std::string> frames;  // frame tokens or indices to synthesise; empty = all frames
  WriteOptions write;
  bool overwrite = false;
  bool report = true;
};

struct SynthRequest {
  std::filesystem::path log;            // dataset root or info file
  OpenLogOptions log_options;
  std::vector<std::filesystem::path> assets;  // asset folders
  std::filesystem::path scenario;
  std::filesystem::path out;
  SynthOptions options;
};

// What happened to one inserted object in one frame, for labels, reports and verification.
struct ObjectOutcome {
  PlacedObject placement;
  AddedObject label;
  int lidar_points = 0;
  double rendered_pixels = 0, visible_pixels = 0;
};

struct CameraOutcome {
  std::string channel;
  ImageU8 before, after;  // only for cameras the objects touch
  std::vector<int> objects;  // indices into FrameOutcome::objects drawn in this camera
};

struct FrameOutcome {
  size_t frame_index = 0;
  FrameEdit edit;
  std::vector<ObjectOutcome> objects;
  std::vector<CameraOutcome> cameras;
  GroundModel ground;
  std::string sun_source;
  PointCloud sweep_before;  // sensor frame
  std::vector<std::pair<int, int>> lidar_object_points;  // (point index in edit.points, object index)
};

// Synthesises one frame in memory (no files written).
FrameOutcome SynthesizeFrame(const Log& log, size_t frame_index, const std::vector<Asset>& assets,
                             const Scenario& scenario, const SynthOptions& options);

struct SynthSummary {
  std::filesystem::path out, report;
  size_t frames = 0, objects = 0;
};

// The whole command: loads everything, synthesises the selected frames, writes the derivative dataset,
// synth.json (placements and provenance) and report.html into `out` atomically.
SynthSummary RunSynth(const SynthRequest& request);

}  // namespace sd
