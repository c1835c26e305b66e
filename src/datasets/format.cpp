#include "datasets/format.h"

#include "core/error.h"
#include "datasets/internal.h"

namespace sd {

const std::vector<LogFormatInfo>& LogFormats() {
  // Probe order: info files first (a file, cheapest), then the directory layouts.
  static const std::vector<LogFormatInfo> kFormats = {
      datasets_internal::Mmdet3dV1Format(), datasets_internal::Mmdet3dV0Format(), datasets_internal::Mmdet3dKittiFormat(),
      datasets_internal::NuScenesTablesFormat(),
      datasets_internal::KittiFormat(),     datasets_internal::Argoverse2Format(), datasets_internal::PandaSetFormat(),
  };
  return kFormats;
}

const LogFormatInfo& FormatInfo(LogFormat format) {
  for (const LogFormatInfo& f : LogFormats())
    if (f.format == format) return f;
  CheckFailed(__FILE__, __LINE__, "FormatInfo", Msg() << "LogFormat " << static_cast<int>(format) << " has no row in LogFormats()");
}

const char* ToString(LogFormat f) { return FormatInfo(f).name; }

std::optional<LogFormat> LogFormatFromOption(std::string_view option) {
  for (const LogFormatInfo& f : LogFormats())
    if (option == f.option) return f.format;
  return std::nullopt;
}

std::vector<std::string> LogFormatOptions() {
  std::vector<std::string> out;
  for (const LogFormatInfo& f : LogFormats())
    if (out.empty() || out.back() != f.option) out.push_back(f.option);
  return out;
}

}  // namespace sd
