#pragma once
// The one table of driving-log formats. Every place that enumerates formats (probing a path, forcing a reader
// with --format, writing a derivative, naming a class, printing the format) reads this table, so a format is
// added by adding one row.
//
// How to add a format:
//  1. one file `datasets/<format>.cpp` holding its reader (into datasets/log.h, conventions converted once,
//     dataset facts set on Log / LidarSensor) and its writer, and exposing its row (`<Format>Format()`,
//     declared in datasets/internal.h);
//  2. the row in LogFormats() (format.cpp), in probe order: the first row whose probe matches reads the path;
//  3. a value in `LogFormat` (log.h), its tests on real data pinning every convention (readers_test.cpp
//     pattern), a round-trip writer test, and a section in docs/datasets.md.
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "datasets/categories.h"
#include "datasets/log.h"
#include "datasets/readers.h"
#include "datasets/writers.h"

namespace sd {

struct LogFormatInfo {
  LogFormat format;
  const char* name;    // what outputs record ("nuscenes-tables", "mmdet3d-v1", ...): ToString(LogFormat)
  const char* option;  // the --format word that forces this reader ("nuscenes", "mmdet3d", ...); rows may share one
  // A cheap check of the path (directory layout, file extension): true when this reader should read it.
  // nullptr: found through another row with the same reader (mmdet3d v0 through v1's row).
  bool (*probe)(const std::filesystem::path& path);
  Log (*read)(const std::filesystem::path& path, const OpenLogOptions& options);
  // Writes the derivative's annotation files and every sensor file the edited frames reference (most formats
  // call WriteSensorFiles in internal.h); returns the annotation files written. nullptr: the format is read only.
  std::vector<std::filesystem::path> (*write)(const Log& log, const std::vector<FrameEdit>& edits,
                                              const std::filesystem::path& out_dir, const WriteOptions& options);
  // With write == nullptr: the message for the user ("writing Argoverse 2 logs is not supported (...)").
  const char* read_only_message;
  // The dataset's own class name for a canonical category ("movable_object.trafficcone", "TrafficCone", ...).
  std::string (*class_name)(const CategoryInfo& category);
};

// Every format, in probe order.
const std::vector<LogFormatInfo>& LogFormats();
const LogFormatInfo& FormatInfo(LogFormat format);
// The format a --format word forces (the first row with that option); nullopt for an unknown word.
std::optional<LogFormat> LogFormatFromOption(std::string_view option);
// The distinct --format words, in table order ("nuscenes", "mmdet3d", "kitti", ...).
std::vector<std::string> LogFormatOptions();

}  // namespace sd
