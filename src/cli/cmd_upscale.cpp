// `synthdrive upscale`: the super-resolution stage on its own, for one image or a folder of them.
#include <algorithm>
#include <filesystem>
#include <memory>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "cli/mesh_files.h"
#include "core/error.h"
#include "core/image.h"
#include "core/log.h"
#include "io/files.h"
#include "io/image_io.h"
#include "models/super_resolution.h"

namespace sd::cli {

namespace {

namespace fs = std::filesystem;

bool IsImageFile(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg";
}

std::vector<fs::path> ImagesIn(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.is_regular_file() && IsImageFile(entry.path())) files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) throw InputError(dir, "no .png or .jpg images in this folder");
  return files;
}

}  // namespace

Runner AddUpscaleCommand(CLI::App& app) {
  struct Args {
    std::string in, out, model = "auto", device = "cpu";
    int scale = 2, tile = 128;
    bool overwrite = false;
  };
  auto a = std::make_shared<Args>();
  app.add_option("--in", a->in, "Image (.png/.jpg) or folder of images")->required();
  app.add_option("--out", a->out, "Output image, or output folder when --in is a folder (same file names)")->required();
  app.add_option("--scale", a->scale, "Upscale factor")->default_val(2)->check(CLI::Range(2, 8));
  app.add_option("--model", a->model,
                 "auto (installed ESRGAN-slim, else bicubic), bicubic, an installed model name (esrgan-slim, "
                 "esrgan-medium) or a .pt file")
      ->default_val("auto");
  app.add_option("--tile", a->tile, "Tile size in input pixels (bounds memory; results do not depend on it)")
      ->default_val(128)->check(CLI::Range(16, 4096));
  app.add_option("--device", a->device, "cpu, cuda or cuda:N")->default_val("cpu");
  app.add_flag("--overwrite", a->overwrite, "Replace an existing output");

  return [a]() {
    const fs::path in(a->in), out(a->out);
    std::error_code ec;
    if (!fs::exists(in, ec)) throw InputError(in, "no such file or folder");
    const bool folder = fs::is_directory(in, ec);
    if (!folder && !IsImageFile(out)) throw InputError(out, "output must be a .png or .jpg file");
    RefuseOutputOverInputs(out, {in});
    RefuseExisting(out, a->overwrite);
    const std::vector<fs::path> inputs = folder ? ImagesIn(in) : std::vector<fs::path>{in};

    models::RuntimeOptions runtime;
    runtime.device = a->device;
    models::UpscaleOptions options;
    options.tile = a->tile;
    const models::Upscaler upscaler = models::Upscaler::Resolve(a->model, a->scale, runtime, options);
    SD_LOG(Info, "upscaler: " << upscaler.Describe());

    if (!folder) {
      const ImageU8 result = upscaler.Upscale(ReadImage(in));
      WriteImage(out, result);  // atomic: temporary name, then rename
      SD_LOG(Info, "wrote " << out.string() << " (" << result.width() << "x" << result.height() << ")");
      return 0;
    }
    StagingDirectory staging(out, a->overwrite);
    Progress progress("upscaling", inputs.size());
    for (const fs::path& file : inputs) {
      WriteImage(staging.path() / file.filename(), upscaler.Upscale(ReadImage(file)));
      progress.Advance();
    }
    progress.Finish();
    staging.Commit();
    SD_LOG(Info, "wrote " << inputs.size() << " images to " << out.string());
    return 0;
  };
}

}  // namespace sd::cli
