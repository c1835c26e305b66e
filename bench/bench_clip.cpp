// CLIP through SynthDrive's runtime and tokenizer: the embeddings it gives a list of images and prompts (for a
// comparison with the Python model the folder was exported from: tools/gpu/clip_check.py), and its embedding
// throughput on each device and precision.
//
// Usage: bench_clip --model DIR [--images LIST] [--texts FILE] [--out PREFIX] [--devices cpu,cuda] [--half]
//                   [--throughput N] [--batches 64,256] [--repeats R]
//   --images LIST   a text file naming one image per line; --texts FILE one UTF-8 prompt per line (an empty
//                   line is an empty prompt)
//   --out PREFIX    writes PREFIX_<run>_images.f32 and PREFIX_<run>_texts.f32 ([n, D] float32, row-major,
//                   unit rows) and PREFIX_tokens.i32 ([n, context] int32, the tokenizer's ids), where <run> is
//                   cpu, cuda or cuda_fp16
//   --half          adds a float16 run on CUDA (weights and activations; token ids stay float32)
//   --throughput N  images per timed pass (default 1024; 0 skips): N images of the model's input size through
//                   EmbedImages at each batch size, median of R passes after one warm-up; and the model's
//                   forward alone on a ready batch (what the GPU can do without our preprocessing around it)
// One line per run and batch size: "<run> batch B: X images/s embed, Y images/s forward".
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/image.h"
#include "io/image_io.h"
#include "models/clip.h"

namespace {

// Empty lines are kept when `keep_empty` (an empty prompt is a prompt), else skipped.
std::vector<std::string> ReadLines(const std::string& file, bool keep_empty) {
  std::ifstream in(file);
  if (!in) throw sd::InputError(file, "cannot be read");
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);)
    if (keep_empty || !line.empty()) lines.push_back(line);
  return lines;
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> parts;
  std::stringstream ss(s);
  for (std::string part; std::getline(ss, part, ',');)
    if (!part.empty()) parts.push_back(part);
  return parts;
}

void WriteRows(const std::string& file, const std::vector<std::vector<float>>& rows) {
  std::ofstream out(file, std::ios::binary);
  for (const auto& r : rows) out.write(reinterpret_cast<const char*>(r.data()), static_cast<std::streamsize>(r.size() * 4));
  if (!out) throw sd::InputError(file, "cannot be written");
}

// Smooth colour fields: content the model's layers treat like photographs (no denormals, no constant input).
std::vector<sd::ImageF> SyntheticImages(int count, int size) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> unit(0, 1);
  std::vector<sd::ImageF> images;
  for (int n = 0; n < count; ++n) {
    sd::ImageF im(size, size, 3);
    const float fx = 1 + 5 * unit(rng), fy = 1 + 5 * unit(rng), ph = 6 * unit(rng);
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x)
        for (int c = 0; c < 3; ++c)
          im.at(x, y, c) = 0.5f + 0.4f * std::sin(fx * x / size * 6.28f + ph + c) * std::cos(fy * y / size * 6.28f);
    images.push_back(std::move(im));
  }
  return images;
}

double Median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::string model_dir, images_list, texts_file, out_prefix;
  std::vector<std::string> devices;
  std::vector<int> batches{64, 256};
  bool half = false;
  int throughput = 1024, repeats = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_clip: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--model") model_dir = next();
    else if (a == "--images") images_list = next();
    else if (a == "--texts") texts_file = next();
    else if (a == "--out") out_prefix = next();
    else if (a == "--devices") devices = Split(next());
    else if (a == "--half") half = true;
    else if (a == "--throughput") throughput = std::max(0, std::atoi(next().c_str()));
    else if (a == "--repeats") repeats = std::max(1, std::atoi(next().c_str()));
    else if (a == "--batches") {
      batches.clear();
      for (const std::string& b : Split(next())) batches.push_back(std::max(1, std::atoi(b.c_str())));
    } else {
      std::fprintf(stderr, "bench_clip: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  if (model_dir.empty()) {
    std::fprintf(stderr, "bench_clip: --model DIR (a folder export_clip.py wrote) is required\n");
    return 2;
  }
  try {
    const std::string runtime = sd::models::RuntimeDescription();
    std::printf("runtime: %s\n", runtime.c_str());
    if (devices.empty()) {
      devices.push_back("cpu");
      if (runtime.find("CUDA available") != std::string::npos) devices.push_back("cuda");
    }
    std::vector<sd::ImageU8> images;
    if (!images_list.empty())
      for (const std::string& f : ReadLines(images_list, false)) images.push_back(sd::ReadImage(f, 3));
    const std::vector<std::string> texts = texts_file.empty() ? std::vector<std::string>{} : ReadLines(texts_file, true);

    struct Run {
      std::string label, device;
      bool half;
    };
    std::vector<Run> runs;
    for (const std::string& d : devices) {
      runs.push_back({d, d, false});
      if (half && d.rfind("cuda", 0) == 0) runs.push_back({d + "_fp16", d, true});
    }
    bool tokens_written = false;
    for (const Run& run : runs) {
      sd::models::RuntimeOptions options;
      options.device = run.device;
      options.half = run.half;
      const sd::models::ClipEncoder clip = sd::models::ClipEncoder::Load(model_dir, options);
      std::printf("%s: %s\n", run.label.c_str(), clip.Describe().c_str());
      if (!out_prefix.empty()) {
        if (!images.empty()) WriteRows(out_prefix + "_" + run.label + "_images.f32", clip.EmbedImages(images));
        if (!texts.empty()) WriteRows(out_prefix + "_" + run.label + "_texts.f32", clip.EmbedTexts(texts));
        if (!texts.empty() && !tokens_written) {
          std::ofstream out(out_prefix + "_tokens.i32", std::ios::binary);
          for (const std::string& t : texts)
            for (int id : clip.tokenizer().Tokenize(t, clip.context_length()))
              out.write(reinterpret_cast<const char*>(&id), 4);
          tokens_written = true;
        }
      }
      if (throughput == 0) continue;
      const int s = clip.image_size();
      const std::vector<sd::ImageF> synthetic = SyntheticImages(throughput, s);
      for (int batch : batches) {
        sd::models::ClipOptions clip_options;
        clip_options.batch_size = batch;
        const sd::models::ClipEncoder batched = sd::models::ClipEncoder::Load(model_dir, options, clip_options);
        std::vector<double> embed_s, forward_s;
        // The model alone on a ready [B, 3, S, S] batch: the same input tensor every pass.
        const sd::models::Model image_model =
            sd::models::Model::Load(std::filesystem::path(model_dir) / sd::models::kClipImageFile,
                                    sd::models::kClipImageStage, options);
        sd::models::Tensor ready({batch, 3, s, s});
        for (int n = 0; n < batch; ++n)
          std::copy(synthetic[n % synthetic.size()].vector().begin(), synthetic[n % synthetic.size()].vector().end(),
                    ready.values.begin() + static_cast<std::ptrdiff_t>(n) * 3 * s * s);  // layout immaterial here
        const std::vector<sd::models::Tensor> ready_inputs = {std::move(ready)};  // built once: not a 38 MB copy per pass
        const int passes = std::max(1, throughput / batch);
        for (int r = 0; r <= repeats; ++r) {  // r == 0 warms up (cuDNN / allocator)
          auto t0 = std::chrono::steady_clock::now();
          (void)batched.EmbedImages(synthetic);
          const double e = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          t0 = std::chrono::steady_clock::now();
          for (int p = 0; p < passes; ++p) (void)image_model.Run(ready_inputs);
          const double f = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          if (r > 0) {
            embed_s.push_back(e);
            forward_s.push_back(f);
          }
        }
        std::printf("%s batch %d: %.0f images/s embed, %.0f images/s forward (median of %d passes of %d images)\n",
                    run.label.c_str(), batch, throughput / Median(embed_s), passes * batch / Median(forward_s),
                    repeats, throughput);
        std::fflush(stdout);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_clip: %s\n", e.what());
    return 1;
  }
  return 0;
}
