#pragma once
// PNG and JPEG files <-> ImageU8 (sRGB). Format chosen by extension on write (.png, .jpg/.jpeg).
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include "core/image.h"

namespace sd {

// Reads a PNG, a JPEG or a binary 8-bit PGM/PPM (by its signature, whatever the file's name; other formats are
// refused). `channels` 0 keeps
// the file's channel count, else forces 1, 3 or 4. InputError names the file when it is missing or not a
// decodable image.
ImageU8 ReadImage(const std::filesystem::path& path, int channels = 0);
// Decodes an encoded image held in memory (e.g. a downloaded body). `what` names its origin (a URL, an archive
// member) for the InputError thrown when the bytes are not a decodable image; `channels` as for ReadImage.
ImageU8 DecodeImage(std::string_view bytes, const std::string& what, int channels = 0);
// Writes atomically. JPEG quality 1..100 (95 keeps re-encoded dataset images visually lossless).
void WriteImage(const std::filesystem::path& path, const ImageU8& image, int jpeg_quality = 95);
// The quality a JPEG was saved at, on the IJG scale (1..100) that libjpeg, stb and most cameras' encoders use:
// estimated from its luminance quantisation table (DQT) as the scaling of the standard table that gives the
// same sum. nullopt when the bytes are not a baseline/progressive JPEG with an 8-bit luminance table.
std::optional<int> EstimateJpegQuality(std::string_view bytes);
// Encodes to memory ("png" or "jpg"), for reports that embed images.
std::string EncodeImage(const ImageU8& image, const std::string& format, int jpeg_quality = 90);

}  // namespace sd
