#pragma once
// The asset cards of report.html: for every asset a synthesis run inserted at least once, where it came from
// (the real camera views of its views/ folder, asset.json's source, licence and attribution), what it looks
// like from every side (a turntable strip, and on demand an interactive three.js view), how good it is
// (asset.json "quality", extent, category, the pipeline stages) and where it was inserted (links to the
// report's per-frame and per-camera sections, which link back to the card).
//
// Files, under <folder of report.html>/report/ (the page links them relative to itself, so it works from
// file:// and after the folder is moved):
//   assets/<key>/turntable.png   RenderTurntable(mesh, 8, 160)
//   assets/<key>/view_<NN>.png   views/image_<NN>.png of a real view (cameras.json entry without
//                                "synthetic": true), its mask outline drawn in cyan; at most 8, spread over them
//   assets/<key>/mesh_glb.js     the asset's GLB file as base64 in a classic script: sdGlb["<key>"] = "...";
//                                Chromium neither fetch()es a file nor imports an ES module from a file:// page
//   three/{three.min.js, GLTFLoader.js, OrbitControls.js, LICENSE}   copied from ThreeJsDir() when installed
// <key> is the asset id with any byte but [A-Za-z0-9._-] written as ~XX (hex), so distinct ids get distinct keys.
// Nothing in the page loads from the network. The viewer's scripts load only when the user clicks "3D".
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "assetgen/asset.h"
#include "datasets/log.h"
#include "io/html.h"

namespace sd {

struct FrameOutcome;

// Where scripts/fetch_web.sh installs three.js: $SYNTHDRIVE_WEB/three, else $XDG_CACHE_HOME/synthdrive/web/three,
// else ~/.cache/synthdrive/web/three (package.json, LICENSE, build/three.min.js, examples/js/loaders/GLTFLoader.js,
// examples/js/controls/OrbitControls.js at their npm package paths).
std::filesystem::path ThreeJsDir();

// Anchors shared by the per-frame sections of report.html and the cards. `frame_position` is the frame's index
// in the report's list of outcomes (not the log's frame index).
std::string FrameAnchor(size_t frame_position);
std::string CameraAnchor(size_t frame_position, const std::string& channel);
std::string AssetAnchor(const std::string& asset_id);

struct AssetCardsHtml {
  std::string index;  // one line naming the inserted assets, each linked to its card (empty: nothing inserted)
  std::string cards;  // the cards section with the viewer's script (empty: nothing inserted)
};

// Writes the cards' files under `html_dir`/report/ and returns their HTML. Every asset id of `frames`' objects
// gets a card, in the order of `assets`; an id missing from `assets` gets a card saying so. Never throws for a
// bad asset folder: a missing or unreadable views/, image, mask or mesh file is named on the card and the rest
// of the card is shown. Without three.js in ThreeJsDir(), the card says so in one line and how to install it.
// Deterministic: the same inputs and installation give the same bytes (merged and local runs compare equal).
AssetCardsHtml WriteAssetCards(const Log& log, const std::vector<FrameOutcome>& frames, const std::vector<Asset>& assets,
                               const std::filesystem::path& html_dir);

}  // namespace sd
