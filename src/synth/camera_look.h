#pragma once
// The camera's own look, estimated from each real image and given to the pixels synth inserts into it
// (docs/camera_look.md): its noise, its blur, its JPEG compression and its colour saturation. A render is noiseless, sharp to the pixel
// and uncompressed; a photograph is none of these, and a detector learns the difference before the object.
//
// Everything is measured on the image as it is stored (after the camera's own processing and compression), in
// 8-bit sRGB units, and applied so that the inserted pixels measure the same after the same steps.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/image.h"

namespace sd {

// Signal-dependent noise per channel: variance a + b v at 8-bit sRGB value v, as the image's flat regions show
// it. The residual is the 3x3 Laplacian's response inside each 8x8 block of the JPEG grid (never across a block
// edge, where compression leaves a step), normalised to a pixel's standard deviation under white noise; per
// intensity bin the 20th percentile of the blocks is taken, so texture does not count as noise.
struct NoiseModel {
  std::array<double, 3> a{}, b{};
  int blocks = 0;  // flat blocks the fit rests on (0: no estimate)
  double Sigma(int channel, double value) const;
};

// The residual noise sigma (8-bit units) of one 8x8-grid block's channel: the estimator the model is fitted with,
// exposed so a measurement can compare inserted pixels with real ones.
double BlockNoiseSigma(const ImageU8& image, int bx, int by, int channel);

struct CameraLook {
  NoiseModel noise;
  // The 10-90 % rise of the image's sharpest edges (20th percentile of the strong step edges found), pixels;
  // 0 when too few edges were found to say.
  double edge_width_px = 0;
  int edges = 0;
  // The median rise of the edges inside the image's real objects (their projected boxes), when they show at least
  // 30: what an object in this image looks like, softened by its distance, motion and the optics. 0: unknown.
  double object_edge_rise_px = 0;
  int object_edges = 0;
  // The same edges split by direction: the median rise across x (edges within 30 degrees of vertical) and across
  // y (within 30 degrees of horizontal), 0 where fewer than 15. Motion blur softens one direction only: a side
  // camera's image moves along x as the ego drives on.
  double object_edge_rise_across_x_px = 0, object_edge_rise_across_y_px = 0;
  int object_edges_across_x = 0, object_edges_across_y = 0;
  // The rise inserted objects are blurred to: the real objects' where known, else the image's sharpest edges.
  double TargetEdgeRise() const { return object_edge_rise_px > 0 ? object_edge_rise_px : edge_width_px; }
  // The file's JPEG quality (io/image_io.h EstimateJpegQuality); 0 when it is not a JPEG.
  int jpeg_quality = 0;

  nlohmann::json ToJson() const;
  std::string Summary() const;
};

// `jpeg_quality`: of the file the image was read from, when it is a JPEG. `objects`: where the image's real
// objects are (> 0.5), for object_edge_rise_px; null: not known.
CameraLook EstimateCameraLook(const ImageU8& image, std::optional<int> jpeg_quality, const ImageF* objects = nullptr);

// One strong step edge of an image: its 10-90 % rise (pixels, along the gradient) and the gradient's unit
// direction (nx, ny), image axes.
struct EdgeRise {
  double rise_px = 0;
  double nx = 0, ny = 0;
};
// The strong step edges of `image` (luma of sRGB), in scan order. Restricted to `region` (x0, y0, x1, y1) when
// given, and to pixels where `mask` (same size) is > 0.5 when given.
std::vector<EdgeRise> FindEdgeRises(const ImageU8& image, const std::array<int, 4>* region = nullptr,
                                    const ImageF* mask = nullptr);
// Their rises alone, sorted.
std::vector<double> EdgeRiseWidths(const ImageU8& image, const std::array<int, 4>* region = nullptr,
                                   const ImageF* mask = nullptr);

// Which of the camera's traits synth gives the inserted pixels (SynthOptions::camera_look).
struct CameraLookOptions {
  bool blur = true;    // the rendered layer blurred to the image's edge rise
  bool noise = true;   // the image's noise added to the inserted pixels, before the compression
  bool jpeg = true;    // the inserted pixels through the image's own JPEG quality, on its 8x8 grid
  bool colour = true;  // no insert more saturated than the image's real objects of its category (CapSaturation)
};

// The Gaussian sigma (pixels) that brings an edge of rise `from_px` to `to_px` (a Gaussian's 10-90 % rise is
// 2.563 sigma; blurs add in quadrature); 0 when it is already as soft.
double ExtraBlurSigma(double from_px, double to_px);

// Blurs `image` (any channel count) inside [x0, x1) x [y0, y1) by a separable Gaussian of `sigma`, reading
// clamped pixels outside it.
void GaussianBlurRegion(ImageF* image, double sigma, int x0, int y0, int x1, int y1);
// How far (pixels, each axis) GaussianBlurRegion of `sigma` reads and spreads a pixel: its kernel's half-width,
// ceil(3 sigma) and at least 1; 0 for a sigma it leaves the image alone at (< 0.05).
int GaussianBlurReach(double sigma);

// An object's saturation (synth/realism.h and the cap below): the 90th percentile of the HSV saturation of the
// sRGB-encoded pixels inside its projected box outline: its most colourful surfaces, whatever share of the box
// its stripes and the background take (a mean would ask a plain red cone to be as dull as a striped one).
double OutlineSaturation(std::vector<double> pixel_saturations);

// Colour: an asset's albedo is a new object's (a cone's pure orange); the camera's colour response, dirt and haze
// leave the real ones of a log less saturated. Saturation is measured as synth/realism.h measures an object
// (OutlineSaturation over `outline` > 0.5). When the insert measures above
// `ceiling` (its category's colour reference: realism.h RealSaturation), its own pixels (`weight`, 0..1: its
// coverage) are moved towards their luminance in linear light, c' = Y + k (c - Y), by the k that brings the
// outline's measure to the ceiling (k >= `min_scale`). `linear`: the composite, linear light, 3 channels.
// HSV saturation, (max - min) / max of the three channels in any one scale (8-bit or 0..1 sRGB); 0 for black.
double HsvSaturation(double r, double g, double b);

// The most colourful the camera rendered anything in `image`: the 99.5th percentile of the HSV saturation of its
// pixels brighter than 40 (dark pixels' saturation is noise), on a 2-pixel grid. The colour cap's ceiling where
// no real object of an insert's category is seen: no insert more colourful than the image's most colourful half
// per cent.
double ImageSaturationCeiling(const ImageU8& image);

// The ceiling of one category over how many views of its real objects (0: none seen): their most saturated, or,
// for a category with a standard livery seen three times or more, their median (realism.h RealSaturation).
struct SaturationReference {
  double ceiling = 0;
  int views = 0;
  std::string statistic = "max";  // "max" or "median"
};
struct SaturationCap {
  double before = 0, after = 0, ceiling = 0;
  double scale = 1;  // the k applied; 1: untouched
};
SaturationCap CapSaturation(ImageF* linear, const ImageF& outline, const ImageF& weight, double ceiling,
                            double min_scale = 0.2);
// The same over a list of the outline's pixels, each with its insert's share `w` (0 for a real pixel): what a
// caller capping one object of a large image passes, instead of two masks of the image's size.
struct OutlinePixel {
  int x, y;
  float w;
};
SaturationCap CapSaturation(ImageF* linear, const std::vector<OutlinePixel>& pixels, double ceiling, double min_scale = 0.2);

// The sensor's last steps on the inserted pixels of a final sRGB image: noise of `look` (scaled by each pixel's
// alpha), then a round trip through JPEG at the image's quality over the 8x8-aligned rectangle around them,
// blended back by alpha. `alpha` (one channel, image size) says how much of each pixel was inserted; the
// rectangle [x0, x1) x [y0, y1) bounds it. `shadow_noise` (optional, same size): real pixels an inserted shadow
// darkened lost that share of their noise (sqrt(1 - shade^2)); it is given back, after the compression (their
// own is in the image already). `seed`: the noise stream (FrameSeeds::sensor).
// `parts` ({x0, y0, x1, y1}, within the rectangle; empty: the rectangle itself) must hold every pixel with alpha or
// shadow noise. Only they are visited, and the result is the whole rectangle's, byte for byte: the noise streams
// meet the pixels in scan order either way, and the JPEG codes only the blocks around the parts (unless that is
// most of the grid), with one 16-pixel block of context all round: blocks are coded independently, and all a
// block's decoded pixels read of their neighbours is chroma (the decoder's upsampling).
void ApplySensorToInserts(ImageU8* image, const ImageF& alpha, const ImageF* shadow_noise, int x0, int y0, int x1, int y1,
                          const std::vector<std::array<int, 4>>& parts, const CameraLook& look,
                          const CameraLookOptions& options, uint64_t seed);

}  // namespace sd
