// The model runtime on each available device: seconds per 6-view set for the super-resolution stage (the
// learned model generate runs on every asset), and how far the GPU's output is from the CPU's.
//
// Usage: bench_models --model FILE.pt [--repeats N] [--size PX] [--tile PX]
// For each device (cpu, and cuda when this LibTorch sees a GPU): loads the model, upscales 6 random-content
// views of PX x PX (default 320, the rig's view size) once to warm up, then --repeats times; prints the
// median seconds per 6 views, and the largest absolute difference between the devices' outputs (0..1 sRGB).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/image.h"
#include "models/super_resolution.h"

namespace {

std::vector<sd::ImageF> RandomViews(int size) {
  // Smooth colour fields with some edges: closer to rendered views than white noise.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(0, 1);
  std::vector<sd::ImageF> views;
  for (int v = 0; v < 6; ++v) {
    sd::ImageF image(size, size, 3);
    const float fx = 2 + 6 * unit(rng), fy = 2 + 6 * unit(rng), phase = 6 * unit(rng);
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x)
        for (int c = 0; c < 3; ++c) {
          const float s = std::sin(fx * x / size * 3.14f + phase + c) * std::cos(fy * y / size * 3.14f);
          image.at(x, y, c) = std::clamp(0.5f + 0.4f * s + ((x / 40 + y / 40) % 2 ? 0.05f : -0.05f), 0.0f, 1.0f);
        }
    views.push_back(std::move(image));
  }
  return views;
}

}  // namespace

int main(int argc, char** argv) {
  std::string model;
  int repeats = 5, size = 320, tile = 128;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_models: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--model") model = next();
    else if (a == "--repeats") repeats = std::max(1, std::atoi(next().c_str()));
    else if (a == "--size") size = std::max(8, std::atoi(next().c_str()));
    else if (a == "--tile") tile = std::max(16, std::atoi(next().c_str()));
    else {
      std::fprintf(stderr, "bench_models: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  if (model.empty()) {
    std::fprintf(stderr, "bench_models: --model FILE.pt is required\n");
    return 2;
  }
  try {
    std::printf("runtime: %s\n", sd::models::RuntimeDescription().c_str());
    const std::vector<sd::ImageF> views = RandomViews(size);
    std::vector<std::vector<sd::ImageF>> outputs;
    for (const std::string device : {"cpu", "cuda"}) {
      if (device == "cuda" && sd::models::RuntimeDescription().find("CUDA available") == std::string::npos) {
        std::printf("cuda: not available to this LibTorch\n");
        continue;
      }
      sd::models::RuntimeOptions runtime;
      runtime.device = device;
      sd::models::UpscaleOptions options;
      options.tile = tile;
      const sd::models::Upscaler up = sd::models::Upscaler::FromModel(model, runtime, options);
      std::vector<sd::ImageF> out;
      for (const sd::ImageF& v : views) out.push_back(up.Upscale(v));  // warm-up (and the outputs compared)
      std::vector<double> seconds;
      for (int r = 0; r < repeats; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        for (const sd::ImageF& v : views) (void)up.Upscale(v);
        seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      }
      std::nth_element(seconds.begin(), seconds.begin() + seconds.size() / 2, seconds.end());
      std::printf("%-4s %s: %.3f s per 6 views of %dx%d (median of %d, tile %d)\n", device.c_str(),
                  up.Describe().c_str(), seconds[seconds.size() / 2], size, size, repeats, tile);
      outputs.push_back(std::move(out));
    }
    if (outputs.size() == 2) {
      double max_diff = 0;
      for (size_t v = 0; v < outputs[0].size(); ++v)
        for (size_t i = 0; i < outputs[0][v].vector().size(); ++i)
          max_diff = std::max(max_diff, static_cast<double>(std::abs(outputs[0][v].vector()[i] - outputs[1][v].vector()[i])));
      std::printf("cpu vs cuda: max |difference| %.2e (0..1 sRGB)\n", max_diff);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_models: %s\n", e.what());
    return 1;
  }
  return 0;
}
