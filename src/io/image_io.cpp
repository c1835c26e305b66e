#include "io/image_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

#include <stb/stb_image.h>
#include <stb/stb_image_write.h>

#include "core/error.h"
#include "io/files.h"

namespace sd {
namespace {

// The first bytes of every PNG file.
constexpr std::string_view kPngSignature("\x89PNG\r\n\x1a\n", 8);

std::string LowerExtension(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

// stb_image 2.27 (Debian 12) builds a JPEG Huffman table from its 16 code counts without checking that they sum
// to at most 256, the size of its tables: a DHT segment declaring more writes past them inside the decoder's
// state (found by fuzz/image_fuzzer; upstream checks since 2.28). Every DHT stb would read is checked first,
// walking the markers as stb does, including those between the scans of a progressive JPEG.
void RefuseOversizedJpegHuffmanTables(std::string_view bytes, const std::string& what) {
  if (bytes.size() < 4 || static_cast<unsigned char>(bytes[0]) != 0xFF || static_cast<unsigned char>(bytes[1]) != 0xD8)
    return;
  const auto byte_at = [&](size_t i) { return i < bytes.size() ? static_cast<unsigned char>(bytes[i]) : 0u; };
  // Read past its end, the data is zeros, as stb reads it (stbi__get8 returns 0 there): a table cut short by
  // the end of the file still has 16 counts, some of them real.
  size_t at = 2;
  while (at + 2 <= bytes.size()) {
    if (byte_at(at) != 0xFF) {  // entropy-coded data after a scan: on to the next marker
      ++at;
      continue;
    }
    const unsigned marker = byte_at(at + 1);
    if (marker == 0xFF || marker == 0x00 || (marker >= 0xD0 && marker <= 0xD8)) {  // fill, stuffing, RSTn, SOI
      ++at;
      continue;
    }
    if (marker == 0xD9) return;  // EOI
    const size_t length = byte_at(at + 2) << 8 | byte_at(at + 3);
    if (marker == 0xC4) {
      long left = static_cast<long>(length) - 2;
      size_t table = at + 4;
      while (left > 0 && table < bytes.size()) {
        size_t codes = 0;
        for (size_t i = 1; i <= 16; ++i) codes += byte_at(table + i);
        if (codes > 256)
          throw InputError(what, Msg() << "cannot decode image: corrupt JPEG: a Huffman table declares " << codes
                                       << " codes (at most 256)");
        table += 17 + codes;
        left -= static_cast<long>(17 + codes);
      }
    }
    at += 2 + std::max<size_t>(length, 2);
  }
}

// stb_image 2.27 copies each IDAT chunk into a buffer it allocates at the first non-empty one, so an empty
// IDAT before any data passes a null destination to memcpy (undefined, found by fuzz/image_fuzzer). An empty
// IDAT carries no image data and is legal PNG; dropping it decodes the same image. Returns the PNG without its
// empty IDAT chunks, or nothing when it has none (the common case, no copy).
std::optional<std::string> WithoutEmptyPngDataChunks(std::string_view bytes) {
  if (bytes.substr(0, kPngSignature.size()) != kPngSignature) return std::nullopt;
  const auto be32 = [&](size_t i) {
    uint32_t v = 0;
    for (size_t k = 0; k < 4; ++k) v = v << 8 | static_cast<unsigned char>(bytes[i + k]);
    return v;
  };
  std::optional<std::string> kept;
  size_t at = kPngSignature.size(), copied_to = 0;
  while (at + 12 <= bytes.size()) {
    const size_t length = be32(at);
    const std::string_view type = bytes.substr(at + 4, 4);
    if (length == 0 && type == "IDAT") {
      if (!kept) kept.emplace();
      kept->append(bytes.substr(copied_to, at - copied_to));
      copied_to = at + 12;
    }
    if (type == "IEND" || length > bytes.size() - at - 12) break;  // the end, or a truncated chunk stb refuses
    at += 12 + length;
  }
  if (kept) kept->append(bytes.substr(copied_to));
  return kept;
}

// Binary PGM / PPM (P5 / P6, maxval <= 255), read here rather than by stb_image 2.27, whose PNM decoder crashes on
// a truncated file (CVE-2021-42716). Masks are often written this way. Returns the file's own channels (1 or 3).
ImageU8 DecodeBinaryPnm(std::string_view bytes, const std::string& what) {
  size_t at = 2;
  const auto fail = [&](const std::string& why) { return InputError(what, "cannot decode image: PNM: " + why); };
  const auto next_number = [&](const char* name) {
    for (;;) {  // whitespace and # comments between header fields
      while (at < bytes.size() && std::isspace(static_cast<unsigned char>(bytes[at]))) ++at;
      if (at < bytes.size() && bytes[at] == '#') {
        while (at < bytes.size() && bytes[at] != '\n') ++at;
        continue;
      }
      break;
    }
    long v = 0;
    size_t digits = 0;
    for (; at < bytes.size() && std::isdigit(static_cast<unsigned char>(bytes[at])) && digits < 9; ++at, ++digits)
      v = v * 10 + (bytes[at] - '0');
    if (digits == 0 || (at < bytes.size() && std::isdigit(static_cast<unsigned char>(bytes[at]))))
      throw fail(Msg() << "bad " << name << " in the header");
    return v;
  };
  const int channels = bytes[1] == '5' ? 1 : 3;
  const long w = next_number("width"), h = next_number("height"), maxval = next_number("maxval");
  if (w <= 0 || h <= 0 || w > (1 << 15) || h > (1 << 15)) throw fail(Msg() << "size " << w << "x" << h << " out of range");
  if (maxval <= 0 || maxval > 255) throw fail(Msg() << "maxval " << maxval << " (only 8-bit files are read)");
  if (at >= bytes.size() || !std::isspace(static_cast<unsigned char>(bytes[at]))) throw fail("no whitespace after the header");
  ++at;
  const size_t need = static_cast<size_t>(w) * static_cast<size_t>(h) * channels;
  if (bytes.size() - at < need)
    throw fail(Msg() << "truncated: " << bytes.size() - at << " bytes of pixel data for " << need);
  ImageU8 img(static_cast<int>(w), static_cast<int>(h), channels);
  for (size_t i = 0; i < need; ++i) {
    const unsigned v = static_cast<unsigned char>(bytes[at + i]);
    img.data()[i] = static_cast<uint8_t>(maxval == 255 ? v : std::min<unsigned>(255, (v * 255 + maxval / 2) / maxval));
  }
  return img;
}

// `image` with `channels` channels (0: as it is), converted as stb_image converts (grey replicated, luma by its
// integer weights, opaque alpha added).
ImageU8 WithChannels(const ImageU8& image, int channels) {
  if (channels == 0 || channels == image.channels()) return image;
  ImageU8 out(image.width(), image.height(), channels);
  for (int y = 0; y < image.height(); ++y)
    for (int x = 0; x < image.width(); ++x) {
      const bool grey = image.channels() < 3;
      const unsigned r = image.at(x, y, 0), g = grey ? r : image.at(x, y, 1), b = grey ? r : image.at(x, y, 2);
      const uint8_t luma = static_cast<uint8_t>((r * 77 + g * 150 + b * 29) >> 8);
      const uint8_t rgb[3] = {static_cast<uint8_t>(r), static_cast<uint8_t>(g), static_cast<uint8_t>(b)};
      for (int c = 0; c < channels; ++c) {
        if ((channels == 2 && c == 1) || (channels == 4 && c == 3)) out.at(x, y, c) = 255;
        else out.at(x, y, c) = channels < 3 ? (grey ? rgb[0] : luma) : rgb[c];
      }
    }
  return out;
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
  // PNG and JPEG by stb, binary PGM/PPM (masks) by our own reader, nothing else: the logs, textures and mined
  // crops are PNG or JPEG, and stb_image 2.27's other decoders (GIF, PSD, PIC, TGA, HDR, BMP, its PNM) carry
  // overflows fixed only in later releases. A byte stream that only claims another format is not handed to them.
  static constexpr std::string_view kJpeg("\xFF\xD8\xFF", 3);
  if (bytes.size() >= 2 && bytes[0] == 'P' && (bytes[1] == '5' || bytes[1] == '6'))
    return WithChannels(DecodeBinaryPnm(bytes, what), channels);
  if (bytes.substr(0, kPngSignature.size()) != kPngSignature && bytes.substr(0, kJpeg.size()) != kJpeg)
    throw InputError(what, "cannot decode image: not a PNG, JPEG or binary PGM/PPM file");
  RefuseOversizedJpegHuffmanTables(bytes, what);
  const std::optional<std::string> cleaned = WithoutEmptyPngDataChunks(bytes);
  if (cleaned) bytes = *cleaned;
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

std::optional<int> EstimateJpegQuality(std::string_view bytes) {
  // The IJG standard luminance table (ITU-T T.81 Annex K); the order does not matter for its sum.
  static constexpr int kStandardLuma[64] = {16, 11, 10, 16, 24,  40,  51,  61,  12, 12, 14, 19, 26,  58,  60,  55,
                                            14, 13, 16, 24, 40,  57,  69,  56,  14, 17, 22, 29, 51,  87,  80,  62,
                                            18, 22, 37, 56, 68,  109, 103, 77,  24, 35, 55, 64, 81,  104, 113, 92,
                                            49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99};
  const auto u8 = [&](size_t i) { return static_cast<unsigned char>(bytes[i]); };
  if (bytes.size() < 4 || u8(0) != 0xFF || u8(1) != 0xD8) return std::nullopt;
  size_t i = 2;
  while (i + 4 <= bytes.size()) {
    if (u8(i) != 0xFF) return std::nullopt;
    const int marker = u8(i + 1);
    if (marker == 0xD9 || marker == 0xDA) return std::nullopt;  // end of image, or scan data: no table before it
    const size_t length = (static_cast<size_t>(u8(i + 2)) << 8) | u8(i + 3);
    if (length < 2 || i + 2 + length > bytes.size()) return std::nullopt;
    if (marker == 0xDB) {
      // One or more tables: Pq/Tq byte, then 64 entries of 1 (Pq = 0) or 2 bytes.
      size_t t = i + 4;
      const size_t end = i + 2 + length;
      while (t < end) {
        const int precision = u8(t) >> 4, id = u8(t) & 15;
        const size_t entry = precision == 0 ? 1 : 2;
        if (t + 1 + 64 * entry > end) return std::nullopt;
        if (id == 0 && precision == 0) {
          double sum = 0, standard = 0;
          for (int k = 0; k < 64; ++k) sum += u8(t + 1 + k), standard += kStandardLuma[k];
          const double scale = 100.0 * sum / standard;  // libjpeg: scale = q < 50 ? 5000 / q : 200 - 2 q
          const double q = scale <= 100 ? (200 - scale) / 2 : 5000 / scale;
          return std::clamp(static_cast<int>(std::lround(q)), 1, 100);
        }
        t += 1 + 64 * entry;
      }
    }
    i += 2 + length;
  }
  return std::nullopt;
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
