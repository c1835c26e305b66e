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

void WriteSynthReport(const Log& log, const std::vector<FrameOutcome>& frames, const std::filesystem::path& html_path);

}  // namespace sd
