#pragma once
// report.html for a synthesis run: per frame, each camera the objects touch before/after (inserted
// objects' visible 2D boxes in green, projected 3D boxes in yellow, real annotations in thin blue) and a
// bird's-eye view of the LiDAR (real points grey by height, points on inserted objects red, real boxes
// blue, inserted boxes red). Images are written as JPEG files beside the HTML under report/.
#include <filesystem>
#include <vector>

#include "datasets/log.h"

namespace sd {

struct FrameOutcome;
struct SynthPlan;

void WriteSynthReport(const Log& log, const std::vector<FrameOutcome>& frames, const std::filesystem::path& html_path);

// plan.html of `synth --dry-run`, one self-contained page (no image files): per planned sequence a top-down SVG
// in the world frame (x right, y up; the ego path with a dot per frame, every annotated box of the planned
// frames in thin blue, the placed objects filled and numbered as in plan.json) and a per-frame table of the
// objects (V: visible, r: in range but in no camera image, blank: out of range; hover: distance).
void WritePlanReport(const Log& log, const SynthPlan& plan, const std::filesystem::path& html_path);

}  // namespace sd
