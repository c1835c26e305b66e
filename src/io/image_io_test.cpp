#include "io/image_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "core/error.h"
#include "io/files.h"
#include "testing/testing.h"

namespace sd {
namespace {
namespace fs = std::filesystem;

const char* kCamFront =
    "driving/nuscenes-scene0061-kf0/samples/CAM_FRONT/"
    "n015-2018-07-24-11-22-45+0800__CAM_FRONT__1532402927612460.jpg";

ImageU8 Pattern(int w, int h, int c) {
  ImageU8 img(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k) img.at(x, y, k) = static_cast<uint8_t>((x * 7 + y * 13 + k * 50) & 255);
  return img;
}

// Smooth pattern for the lossy codec (JPEG error on sharp noise says nothing about our code).
ImageU8 Smooth(int w, int h) {
  ImageU8 img(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      img.at(x, y, 0) = static_cast<uint8_t>(255 * x / (w - 1));
      img.at(x, y, 1) = static_cast<uint8_t>(255 * y / (h - 1));
      img.at(x, y, 2) = 128;
    }
  return img;
}

TEST(ImageIo, ReadsNuScenesJpeg) {
  const ImageU8 img = ReadImage(testing::RepoData(kCamFront));
  EXPECT_EQ(img.width(), 1600);
  EXPECT_EQ(img.height(), 900);
  EXPECT_EQ(img.channels(), 3);
  const ImageU8 rgba = ReadImage(testing::RepoData(kCamFront), 4);
  EXPECT_EQ(rgba.channels(), 4);
  EXPECT_EQ(rgba.at(800, 450, 3), 255);
  EXPECT_EQ(rgba.at(800, 450, 1), img.at(800, 450, 1));
}

TEST(ImageIo, PngRoundTripIsExact) {
  testing::TempDir tmp;
  for (int c : {1, 3, 4}) {
    const ImageU8 img = Pattern(37, 21, c);
    const fs::path p = tmp / (std::to_string(c) + "ch.png");
    WriteImage(p, img);
    const ImageU8 back = ReadImage(p);
    EXPECT_EQ(back.width(), 37);
    EXPECT_EQ(back.height(), 21);
    EXPECT_EQ(back.channels(), c);
    EXPECT_EQ(back.vector(), img.vector());
  }
}

TEST(ImageIo, JpegRoundTripIsClose) {
  testing::TempDir tmp;
  const ImageU8 img = Smooth(64, 48);
  WriteImage(tmp / "s.jpg", img, 95);
  const ImageU8 back = ReadImage(tmp / "s.jpg");
  ASSERT_EQ(back.size(), img.size());
  double sum = 0;
  int worst = 0;
  for (size_t i = 0; i < img.size(); ++i) {
    const int d = std::abs(int(back.data()[i]) - int(img.data()[i]));
    sum += d;
    worst = std::max(worst, d);
  }
  EXPECT_LT(sum / img.size(), 2.0);
  EXPECT_LE(worst, 12);
}

TEST(ImageIo, CorruptOrMissingFilesNameTheFile) {
  testing::TempDir tmp;
  std::string bytes = ReadFileToString(testing::RepoData(kCamFront)).substr(0, 64);  // truncated JPEG
  WriteFileAtomic(tmp / "broken.jpg", bytes);
  WriteFileAtomic(tmp / "garbage.png", "definitely not a png");
  for (const char* name : {"broken.jpg", "garbage.png", "missing.png"}) {
    try {
      ReadImage(tmp / name);
      FAIL() << name;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(WriteImage(tmp / "x.bmp", Pattern(2, 2, 3)), InputError);
  EXPECT_FALSE(fs::exists(tmp / "x.bmp"));
}

TEST(ImageIo, DecodesFromMemoryAndNamesTheSource) {
  for (int c : {1, 3, 4}) {
    const ImageU8 img = Pattern(19, 11, c);
    const ImageU8 back = DecodeImage(EncodeImage(img, "png"), "mem.png");
    EXPECT_EQ(back.width(), 19);
    EXPECT_EQ(back.height(), 11);
    EXPECT_EQ(back.channels(), c);
    EXPECT_EQ(back.vector(), img.vector());
  }
  // Forcing 4 channels on a 3-channel image adds an opaque alpha and keeps the colour exactly.
  const ImageU8 rgb = Pattern(5, 4, 3);
  const ImageU8 rgba = DecodeImage(EncodeImage(rgb, "png"), "mem.png", 4);
  ASSERT_EQ(rgba.channels(), 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 5; ++x) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(rgba.at(x, y, k), rgb.at(x, y, k));
      EXPECT_EQ(rgba.at(x, y, 3), 255);
    }
  const std::string url = "http://example.invalid/cat.png";
  const std::string png = EncodeImage(Pattern(8, 8, 3), "png");
  for (const std::string& bytes : {std::string("<html>not an image</html>"), std::string(), png.substr(0, 40)}) {
    try {
      DecodeImage(bytes, url);
      FAIL() << bytes.size() << " bytes decoded";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()).rfind(url + ": cannot decode image", 0), 0u) << e.what();
    }
  }
}

// stb_image 2.27 writes past its Huffman tables when a DHT segment declares more than 256 codes (found by
// fuzz/image_fuzzer): refused before stb sees it, in a baseline JPEG of our own encoder with its first table's
// 16 counts raised to 255 each. The unchanged JPEG still decodes.
TEST(ImageIo, JpegHuffmanTablesDeclaringMoreThan256CodesAreRefused) {
  const std::string jpeg = EncodeImage(Pattern(32, 16, 3), "jpg", 90);
  ASSERT_NO_THROW(DecodeImage(jpeg, "good.jpg"));
  const size_t dht = jpeg.find("\xFF\xC4");
  ASSERT_NE(dht, std::string::npos);
  std::string broken = jpeg;
  for (size_t i = 1; i <= 16; ++i) broken[dht + 4 + i] = static_cast<char>(0xFF);
  try {
    DecodeImage(broken, "bad.jpg");
    FAIL() << "decoded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.jpg: cannot decode image: corrupt JPEG: a Huffman table declares 4080 codes"),
              std::string::npos) << e.what();
  }
}

// The same overrun from a Huffman table that the file's end cuts short (found by CI's fuzz run): stb reads the
// missing counts as zeros, so the counts that are there still sum past 256. A JPEG whose DHT segment claims more
// than it holds, ending in a table header and nine counts of 255.
TEST(ImageIo, AHuffmanTableCutShortByTheFilesEndIsRefusedToo) {
  const std::string jpeg = EncodeImage(Pattern(32, 16, 3), "jpg", 90);
  const size_t dht = jpeg.find("\xFF\xC4");
  ASSERT_NE(dht, std::string::npos);
  const size_t first_table_end = dht + 4 + 17 + [&] {
    size_t codes = 0;
    for (size_t i = 1; i <= 16; ++i) codes += static_cast<unsigned char>(jpeg[dht + 4 + i]);
    return codes;
  }();
  std::string cut = jpeg.substr(0, first_table_end) + "\x10" + std::string(9, '\xFF');
  cut[dht + 2] = 0x01, cut[dht + 3] = 0x00;  // the segment claims 256 bytes
  try {
    DecodeImage(cut, "cut.jpg");
    FAIL() << "decoded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.jpg: cannot decode image: corrupt JPEG: a Huffman table declares 2295 codes"),
              std::string::npos) << e.what();
  }
}

// Only PNG and JPEG reach stb (binary PGM/PPM our own reader): a BMP, a TGA-like stream or a GIF header is refused by its signature (stb 2.27's
// other decoders carry overflows fixed later), whatever the file is called; a PNG named .jpg still decodes.
TEST(ImageIo, OnlyPngAndJpegAreDecoded) {
  const std::string bmp = std::string("BM") + std::string(60, '\0');
  const std::string gif = "GIF89a" + std::string(20, '\x01');
  for (const std::string& bytes : {bmp, gif, std::string("\0\0\x02\0\0\0\0\0", 8) + std::string(40, '\x10')}) {
    try {
      DecodeImage(bytes, "x.png");
      FAIL() << bytes.substr(0, 6);
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), "x.png: cannot decode image: not a PNG, JPEG or binary PGM/PPM file");
    }
  }
  const ImageU8 img = Pattern(6, 5, 3);
  EXPECT_EQ(DecodeImage(EncodeImage(img, "png"), "named.jpg").vector(), img.vector());
  // Binary PGM / PPM (masks are often written so) are read by our own reader: exact pixels, a comment in the
  // header, channels converted as for the others; a truncated one is refused with its size.
  std::string ppm = "P6\n# a comment\n6 5\n255\n";
  for (uint8_t v : img.vector()) ppm.push_back(static_cast<char>(v));
  EXPECT_EQ(DecodeImage(ppm, "m.ppm").vector(), img.vector());
  const ImageU8 rgba = DecodeImage(ppm, "m.ppm", 4);
  ASSERT_EQ(rgba.channels(), 4);
  EXPECT_EQ(rgba.at(5, 4, 2), img.at(5, 4, 2));
  EXPECT_EQ(rgba.at(5, 4, 3), 255);
  std::string pgm = "P5 3 2 255\n";
  pgm += std::string("\x00\x80\xFF\x10\x20\x30", 6);
  const ImageU8 grey = DecodeImage(pgm, "m.pgm");
  ASSERT_EQ(grey.channels(), 1);
  EXPECT_EQ(grey.at(1, 0), 0x80);
  EXPECT_EQ(DecodeImage(pgm, "m.pgm", 3).at(2, 1, 1), 0x30);
  try {
    DecodeImage(pgm.substr(0, pgm.size() - 2), "cut.pgm");
    FAIL() << "decoded";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "cut.pgm: cannot decode image: PNM: truncated: 4 bytes of pixel data for 6");
  }
  EXPECT_THROW(DecodeImage("P5 3 2 65535\n" + std::string(12, '\0'), "deep.pgm"), InputError);
  EXPECT_THROW(DecodeImage("P5 99999999999 2 255\n", "huge.pgm"), InputError);
}

// stb_image 2.27 passes a null buffer to memcpy for an empty IDAT before the image data (found by
// fuzz/image_fuzzer, undefined behaviour). An empty IDAT is legal and carries nothing: the PNG decodes to the same
// pixels with empty IDATs before, between and after the real one.
TEST(ImageIo, EmptyPngDataChunksDecodeToTheSameImage) {
  const ImageU8 img = Pattern(23, 9, 3);
  const std::string png = EncodeImage(img, "png");
  const size_t idat = png.find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  const size_t data_chunk = idat - 4;  // the chunk starts with its length
  const std::string empty_idat("\0\0\0\0IDAT\xAE\x42\x60\x82", 12);
  const size_t after = png.find("IEND") - 4;
  const std::string with_empties =
      png.substr(0, data_chunk) + empty_idat + png.substr(data_chunk, after - data_chunk) + empty_idat + png.substr(after);
  for (int channels : {0, 3, 4}) {
    const ImageU8 back = DecodeImage(with_empties, "empty-idat.png", channels);
    const ImageU8 reference = DecodeImage(png, "plain.png", channels);
    EXPECT_EQ(back.width(), 23);
    EXPECT_EQ(back.vector(), reference.vector()) << channels;
  }
  EXPECT_EQ(DecodeImage(with_empties, "empty-idat.png").vector(), img.vector());
}

// The quality a JPEG was written at, read back from its quantisation table: our own encoder's (stb, IJG scaling)
// and the repo's nuScenes keyframe (what synth matches inserted pixels to).
TEST(ImageIo, EstimatesTheJpegQualityFromItsQuantisationTable) {
  const ImageU8 img = Pattern(32, 24, 3);
  for (int q : {30, 50, 75, 85, 90, 95}) {
    const auto estimate = EstimateJpegQuality(EncodeImage(img, "jpg", q));
    ASSERT_TRUE(estimate.has_value()) << q;
    EXPECT_NEAR(*estimate, q, 1) << q;
  }
  EXPECT_FALSE(EstimateJpegQuality(EncodeImage(img, "png")).has_value());
  EXPECT_FALSE(EstimateJpegQuality("").has_value());
  EXPECT_FALSE(EstimateJpegQuality(EncodeImage(img, "jpg", 90).substr(0, 30)).has_value());  // cut inside the tables
  const fs::path front = testing::RepoData("driving/nuscenes-scene0061-kf0/samples/CAM_FRONT");
  for (const auto& e : fs::directory_iterator(front)) {
    const auto q = EstimateJpegQuality(ReadFileToString(e.path()));
    ASSERT_TRUE(q.has_value()) << e.path();
    EXPECT_GE(*q, 70) << e.path();  // nuScenes' cameras: a high quality, not a re-encoded thumbnail
    std::cout << e.path().filename().string() << ": JPEG quality " << *q << "\n";
  }
}

}  // namespace
}  // namespace sd
