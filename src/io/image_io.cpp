#include "io/image_io.h"

#include <algorithm>
#include <cctype>
#include <limits>

#include <stb/stb_image.h>
#include <stb/stb_image_write.h>

#include "core/error.h"
#include "io/files.h"

namespace sd {
namespace {

std::string LowerExtension(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

void AppendToString(void* context, void* data, int size) {
  static_cast<std::string*>(context)->append(static_cast<const char*>(data), static_cast<size_t>(size));
}

}  // namespace

ImageU8 DecodeImage(std::string_view bytes, const std::string& what, int channels) {
  SD_CHECK(channels >= 0 && channels <= 4, << "channels " << channels);
  // stb_image takes an int length; anything larger is not an image we can hold anyway.
  if (bytes.size() > static_cast<size_t>(std::numeric_limits<int>::max()))
    throw InputError(what, Msg() << "cannot decode image: " << bytes.size() << " bytes is too large");
  int w = 0, h = 0, n = 0;
  unsigned char* pixels = stbi_load_from_memory(reinterpret_cast<const stbi_uc*>(bytes.data()),
                                                static_cast<int>(bytes.size()), &w, &h, &n, channels);
  if (!pixels) throw InputError(what, std::string("cannot decode image: ") + stbi_failure_reason());
  const int nc = channels ? channels : n;
  ImageU8 img(w, h, nc);
  std::copy(pixels, pixels + static_cast<size_t>(w) * h * nc, img.data());
  stbi_image_free(pixels);
  return img;
}

ImageU8 ReadImage(const std::filesystem::path& path, int channels) {
  return DecodeImage(ReadFileToString(path), path.string(), channels);
}

std::string EncodeImage(const ImageU8& image, const std::string& format, int jpeg_quality) {
  std::string out;
  int ok = 0;
  if (format == "png") {
    ok = stbi_write_png_to_func(AppendToString, &out, image.width(), image.height(), image.channels(), image.data(),
                                image.width() * image.channels());
  } else if (format == "jpg" || format == "jpeg") {
    ok = stbi_write_jpg_to_func(AppendToString, &out, image.width(), image.height(), image.channels(), image.data(),
                                std::clamp(jpeg_quality, 1, 100));
  } else {
    throw InputError("", "unsupported image format '" + format + "' (png or jpg)");
  }
  SD_CHECK(ok, << "image encoder failed");
  return out;
}

void WriteImage(const std::filesystem::path& path, const ImageU8& image, int jpeg_quality) {
  const std::string ext = LowerExtension(path);
  std::string format;
  if (ext == ".png") format = "png";
  else if (ext == ".jpg" || ext == ".jpeg") format = "jpg";
  else throw InputError(path, "unsupported image extension '" + ext + "' (use .png, .jpg or .jpeg)");
  WriteFileAtomic(path, EncodeImage(image, format, jpeg_quality));
}

}  // namespace sd
