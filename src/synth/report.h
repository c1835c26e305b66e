#pragma once
// report.html for a synthesis run: per frame, each camera the objects touch before/after (inserted
// objects' visible 2D boxes in green, projected 3D boxes in yellow, real annotations in thin blue) and a
// bird's-eye view of the LiDAR (real points grey by height, points on inserted objects red, real boxes
// blue, inserted boxes red), and at the end a card per inserted asset (synth/report_assets.h: its real
// views, turntable, 3D view, quality figures and stages, linked both ways with the frames and cameras that show
// it), and per camera each inserted object at full resolution (before and after, zoomed 3x) with its figures against
// the real objects of the same image (synth/realism.h). Images are written as JPEG / PNG files beside the HTML
// under report/.
#include <filesystem>
#include <vector>

#include "assetgen/asset.h"
#include "datasets/log.h"

namespace sd {

struct FrameOutcome;
struct SynthPlan;

// `assets`: the run's assets (--asset and the bank's), for the cards of those the frames' objects use.
void WriteSynthReport(const Log& log, const std::vector<FrameOutcome>& frames, const std::vector<Asset>& assets,
                      const std::filesystem::path& html_path);

// plan.html of `synth --dry-run`, one self-contained page (no image files): per planned sequence a top-down SVG
// in the world frame (x right, y up; the ego path with a dot per frame, every annotated box of the planned
// frames in thin blue, the placed objects filled and numbered as in plan.json) and a per-frame table of the
// objects (V: visible, r: in range but in no camera image, blank: out of range; hover: distance).
void WritePlanReport(const Log& log, const SynthPlan& plan, const std::filesystem::path& html_path);

}  // namespace sd
