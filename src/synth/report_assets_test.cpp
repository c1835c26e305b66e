#include "synth/report_assets.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>

#include "assetgen/views.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "synth/outcome.h"
#include "synth/report.h"
#include "synth/test_assets.h"
#include "testing/testing.h"

namespace sd {
namespace {
namespace fs = std::filesystem;

// An independent decoder for the check that the page embeds mesh.glb unchanged.
std::string DecodeBase64(const std::string& text) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::string out;
  int bits = 0, buffer = 0;
  for (char c : text) {
    if (c == '=') break;
    const int v = value(c);
    if (v < 0) ADD_FAILURE() << "not base64: '" << c << "'";
    buffer = (buffer << 6) | v;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((buffer >> bits) & 0xff);
    }
  }
  return out;
}

// The cone as an asset folder with a views/ folder of six rendered views, three of them marked synthetic
// (as a shape prior marks its rotated copies) and painted solid magenta so a shown one is easy to catch.
class ReportAssetsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    cone_ = testing::ImportTestAsset(dir_.path(), "assets/metadrive_traffic_cone/scene.gltf", "cone", "traffic_cone", "+x", 0, 0.7);
    SaveViews(RenderOracleViews(cone_.mesh, Zero123PlusPlusRig(64), 1), cone_.dir / "views", "camera", false);
    nlohmann::json cameras = ReadJsonFile(cone_.dir / "views" / "cameras.json");
    for (int k : kSynthetic) {
      cameras["views"][k]["synthetic"] = true;
      WriteImage(cone_.dir / "views" / cameras["views"][k]["image"].get<std::string>(), Magenta());
    }
    cameras["views"][0]["synthetic"] = false;  // an explicit false is real too
    WriteJsonFile(cone_.dir / "views" / "cameras.json", cameras);
    nlohmann::json asset = ReadJsonFile(cone_.dir / "asset.json");
    asset["views"] = "views/cameras.json";
    asset["source"] = "photo 0042.jpg of the test log";
    asset["licence"] = "CC-BY-4.0";
    asset["quality"] = {{"heldout_silhouette_iou", 0.912},
                        {"real_texture_fraction", 0.5},
                        {"watertight", 1},
                        {"shape_prior", {{"prior", "revolve"}, {"reason", "silhouette symmetric"}}},
                        {"photo_silhouette_iou", 0.95}};
    asset["stages"] = {{{"stage", "segment"}, {"method", "grabcut"}, {"seconds", 0.26}}, {{"stage", "generate"}}};
    WriteJsonFile(cone_.dir / "asset.json", asset);
    cone_ = LoadAsset(cone_.dir);

    log_.frames.resize(3);
    log_.frames[0].token = "tok-a";
    log_.frames[1].token = "tok-b";
    log_.frames[2].token = "tok-c";
    // Two frames of the report (log frames 2 and 0): two cones in CAM_FRONT, then one cone seen by no camera.
    frames_.resize(2);
    frames_[0].frame_index = 2;
    frames_[0].objects.resize(2);
    for (auto& ob : frames_[0].objects) ob.label.asset_id = "cone";
    frames_[0].cameras.resize(1);
    frames_[0].cameras[0].channel = "CAM_FRONT";
    frames_[0].cameras[0].objects = {0, 1};
    frames_[1].frame_index = 0;
    frames_[1].objects.resize(1);
    frames_[1].objects[0].label.asset_id = "cone";
  }

  static ImageU8 Magenta() {
    ImageU8 img(64, 64, 3);
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) img.at(x, y, 0) = 255, img.at(x, y, 1) = 0, img.at(x, y, 2) = 255;
    return img;
  }

  // A stand-in three.js install (the files the report copies), so the copy and the embedding are tested
  // without the npm download.
  fs::path FakeThreeInstall() {
    const fs::path web = dir_ / "web";
    WriteFileAtomic(web / "three" / "package.json", R"({"name": "three", "version": "0.147.0"})");
    WriteFileAtomic(web / "three" / "LICENSE", "The MIT License\n");
    WriteFileAtomic(web / "three" / "build" / "three.min.js", "var THREE={};\n");
    WriteFileAtomic(web / "three" / "examples" / "js" / "loaders" / "GLTFLoader.js", "THREE.GLTFLoader=function(){};\n");
    WriteFileAtomic(web / "three" / "examples" / "js" / "controls" / "OrbitControls.js", "THREE.OrbitControls=function(){};\n");
    return web;
  }

  static constexpr int kSynthetic[] = {1, 3, 5};
  testing::TempDir dir_;
  Asset cone_;
  Log log_;
  std::vector<FrameOutcome> frames_;
};

TEST_F(ReportAssetsTest, CardShowsTheTurntableAndOnlyTheRealViews) {
  const testing::ScopedEnv web("SYNTHDRIVE_WEB", FakeThreeInstall().string());
  const fs::path out = dir_ / "report";
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_}, out);
  const fs::path card = out / "report" / "assets" / "cone";
  const ImageU8 turntable = ReadImage(card / "turntable.png");
  EXPECT_EQ(turntable.width(), 8 * 160);
  EXPECT_EQ(turntable.height(), 160);
  // Three real views -> three crops, none of them a synthetic (magenta) view.
  for (int k = 0; k < 3; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "view_%02d.png", k);
    ASSERT_TRUE(fs::exists(card / name)) << name;
    const ImageU8 crop = ReadImage(card / name, 3);
    EXPECT_EQ(crop.width(), 64);
    int magenta = 0;
    for (int y = 0; y < crop.height(); ++y)
      for (int x = 0; x < crop.width(); ++x)
        magenta += crop.at(x, y, 0) > 200 && crop.at(x, y, 1) < 60 && crop.at(x, y, 2) > 200;
    EXPECT_LT(magenta, crop.width() * crop.height() / 10) << name << " is a synthetic view";
  }
  EXPECT_FALSE(fs::exists(card / "view_03.png"));
  EXPECT_NE(html.cards.find("3 synthetic (made by a shape prior) not shown"), std::string::npos) << html.cards;
  EXPECT_NE(html.cards.find("photo 0042.jpg of the test log"), std::string::npos);
  EXPECT_NE(html.cards.find("CC-BY-4.0"), std::string::npos);
}

TEST_F(ReportAssetsTest, MaskOutlineIsDrawnOnTheCrop) {
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_}, dir_ / "report");
  const ImageU8 crop = ReadImage(dir_ / "report" / "report" / "assets" / "cone" / "view_00.png", 3);
  int cyan = 0;
  for (int y = 0; y < crop.height(); ++y)
    for (int x = 0; x < crop.width(); ++x) cyan += crop.at(x, y, 0) < 80 && crop.at(x, y, 1) > 180 && crop.at(x, y, 2) > 180;
  EXPECT_GT(cyan, 20);
}

TEST_F(ReportAssetsTest, QualityStagesAndLinksToTheFrames) {
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_}, dir_ / "report");
  const std::string& c = html.cards;
  EXPECT_NE(c.find("held-out silhouette IoU</td><td>0.912"), std::string::npos) << c;
  EXPECT_NE(c.find("LiDAR point-to-mesh median</td><td>&mdash;"), std::string::npos);  // not measured
  EXPECT_NE(c.find("real-texture fraction</td><td>50 %"), std::string::npos);
  EXPECT_NE(c.find("watertight</td><td>yes"), std::string::npos);
  EXPECT_NE(c.find("revolve (silhouette symmetric)"), std::string::npos);
  EXPECT_NE(c.find("photo_silhouette_iou</td><td>0.95"), std::string::npos);
  EXPECT_NE(c.find("<td>segment</td><td>grabcut</td><td>0.3</td>"), std::string::npos);
  EXPECT_NE(c.find("<td>generate</td><td>&mdash;</td><td>&mdash;</td>"), std::string::npos);
  EXPECT_NE(c.find("0.70 m"), std::string::npos);  // the cone's height in the extent
  // Three insertions in two frames; the card names the log's tokens and links the report's sections.
  EXPECT_NE(c.find("Inserted 3 times in 2 frames"), std::string::npos);
  EXPECT_NE(c.find("<a href='#" + FrameAnchor(0) + "'>tok-c</a> &times;2 (<a href='#" + CameraAnchor(0, "CAM_FRONT") + "'>CAM_FRONT</a>)"),
            std::string::npos) << c;
  EXPECT_NE(c.find("<a href='#" + FrameAnchor(1) + "'>tok-a</a> (no camera shows it)"), std::string::npos);
  EXPECT_NE(c.find("id='" + AssetAnchor("cone") + "'"), std::string::npos);
  EXPECT_NE(html.index.find("href='#" + AssetAnchor("cone") + "'"), std::string::npos);
}

TEST_F(ReportAssetsTest, EmbeddedGlbDecodesToTheBytesOfMeshGlb) {
  const testing::ScopedEnv web("SYNTHDRIVE_WEB", FakeThreeInstall().string());
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_}, dir_ / "report");
  const std::string script = ReadFileToString(dir_ / "report" / "report" / "assets" / "cone" / "mesh_glb.js");
  // (Not std::regex: libstdc++'s recursion overflows the stack on a megabyte-long match.)
  const std::string prefix = "(window.sdGlb = window.sdGlb || {})['cone'] = '", suffix = "';\n";
  ASSERT_EQ(script.compare(0, prefix.size(), prefix), 0) << script.substr(0, 200);
  ASSERT_EQ(script.compare(script.size() - suffix.size(), suffix.size(), suffix), 0);
  const std::string base64 = script.substr(prefix.size(), script.size() - prefix.size() - suffix.size());
  const std::string glb = ReadFileToString(cone_.dir / "mesh.glb");
  EXPECT_EQ(DecodeBase64(base64), glb);
  EXPECT_NE(html.cards.find("sdView3d(this, 'cone')"), std::string::npos);
}

TEST_F(ReportAssetsTest, ViewerFilesAreCopiedWithTheLicence) {
  const fs::path install = FakeThreeInstall();
  const testing::ScopedEnv web("SYNTHDRIVE_WEB", install.string());
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_}, dir_ / "report");
  const fs::path three = dir_ / "report" / "report" / "three";
  EXPECT_EQ(ReadFileToString(three / "three.min.js"), ReadFileToString(install / "three" / "build" / "three.min.js"));
  EXPECT_EQ(ReadFileToString(three / "GLTFLoader.js"), ReadFileToString(install / "three/examples/js/loaders/GLTFLoader.js"));
  EXPECT_EQ(ReadFileToString(three / "OrbitControls.js"), ReadFileToString(install / "three/examples/js/controls/OrbitControls.js"));
  EXPECT_EQ(ReadFileToString(three / "LICENSE"), "The MIT License\n");
  EXPECT_NE(html.cards.find("three.js 0.147.0"), std::string::npos);
  EXPECT_NE(html.cards.find("report/three/three.min.js"), std::string::npos);
}

TEST_F(ReportAssetsTest, WithoutThreeJsTheCardSaysHowToInstallAndShowsTheRest) {
  const testing::ScopedEnv web("SYNTHDRIVE_WEB", (dir_ / "no_web").string());
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_}, dir_ / "report");
  EXPECT_NE(html.cards.find("3D view: three.js is not installed"), std::string::npos) << html.cards;
  EXPECT_NE(html.cards.find("scripts/setup.sh"), std::string::npos);
  EXPECT_EQ(html.cards.find("sdView3d(this"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir_ / "report" / "report" / "three"));
  EXPECT_TRUE(fs::exists(dir_ / "report" / "report" / "assets" / "cone" / "turntable.png"));
  EXPECT_TRUE(fs::exists(dir_ / "report" / "report" / "assets" / "cone" / "view_00.png"));
}

// What scripts/fetch_web.sh installed: the files the viewer loads, as classic scripts that extend the global
// THREE (an ES-module build would not load from a file:// page).
TEST_F(ReportAssetsTest, InstalledThreeJsHasTheClassicScripts) {
  const fs::path three = ThreeJsDir();
  if (!fs::exists(three / "package.json"))
    GTEST_SKIP() << "three.js is not installed in " << three << " (scripts/fetch_web.sh installs it from npm)";
  EXPECT_NE(ReadFileToString(three / "examples/js/loaders/GLTFLoader.js").find("THREE.GLTFLoader ="), std::string::npos);
  EXPECT_NE(ReadFileToString(three / "examples/js/controls/OrbitControls.js").find("THREE.OrbitControls ="), std::string::npos);
  EXPECT_NE(ReadFileToString(three / "LICENSE").find("MIT"), std::string::npos);
  WriteAssetCards(log_, frames_, {cone_}, dir_ / "report");
  for (const char* name : {"three.min.js", "GLTFLoader.js", "OrbitControls.js", "LICENSE"})
    EXPECT_GT(fs::file_size(dir_ / "report" / "report" / "three" / name), 1000u) << name;
}

TEST_F(ReportAssetsTest, BadAssetFoldersGiveANoteNotACrash) {
  const testing::ScopedEnv web("SYNTHDRIVE_WEB", FakeThreeInstall().string());
  // No views/ (an imported mesh), a malformed cameras.json, a mesh.glb gone since loading, an unknown id.
  const Asset plain = testing::ImportTestAsset(dir_.path(), "assets/metadrive_traffic_cone/scene.gltf", "plain", "traffic_cone", "+x", 0, 0.7);
  Asset broken = testing::ImportTestAsset(dir_.path(), "assets/metadrive_traffic_cone/scene.gltf", "broken", "traffic_cone", "+x", 0, 0.7);
  WriteFileAtomic(broken.dir / "views" / "cameras.json", "{\"views\": [");
  fs::remove(broken.dir / "mesh.glb");
  for (auto& f : frames_) {
    f.objects.push_back(f.objects[0]);
    f.objects.back().label.asset_id = "plain";
    f.objects.push_back(f.objects[0]);
    f.objects.back().label.asset_id = "broken";
  }
  frames_[0].objects.push_back(frames_[0].objects[0]);
  frames_[0].objects.back().label.asset_id = "ghost";
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_, plain, broken}, dir_ / "report");
  const std::string& c = html.cards;
  EXPECT_NE(c.find("no real views: the asset folder has no views/"), std::string::npos) << c;
  EXPECT_NE(c.find("cameras.json: malformed JSON"), std::string::npos) << c;
  EXPECT_NE(c.find("broken/mesh.glb: "), std::string::npos) << c;
  EXPECT_NE(c.find("asset &#39;ghost&#39; was not among the assets given to the report"), std::string::npos) << c;
  EXPECT_TRUE(fs::exists(dir_ / "report" / "report" / "assets" / "broken" / "turntable.png"));
  // Cards in the order the assets were given, the unknown id last.
  const size_t cone = c.find("id='asset-cone'"), p = c.find("id='asset-plain'"), b = c.find("id='asset-broken'"),
               g = c.find("id='asset-ghost'");
  EXPECT_TRUE(cone < p && p < b && b < g && g != std::string::npos);
}

TEST_F(ReportAssetsTest, IdsBecomeDistinctSafeKeys) {
  EXPECT_EQ(AssetAnchor("cone_01-b.v2"), "asset-cone_01-b.v2");
  EXPECT_NE(AssetAnchor("a b"), AssetAnchor("a_b"));
  EXPECT_EQ(AssetAnchor("a'b"), "asset-a~27b");
  EXPECT_EQ(AssetAnchor(".."), "asset-~..");
  EXPECT_EQ(EscapeHtml("<a href=\"x\">'&"), "&lt;a href=&quot;x&quot;&gt;&#39;&amp;");
}

// The whole page: each inserted object's row links its card, and nothing refers to the network.
TEST_F(ReportAssetsTest, ReportLinksObjectsToCardsAndHasNoNetworkReference) {
  const testing::ScopedEnv web("SYNTHDRIVE_WEB", FakeThreeInstall().string());
  log_.source = "test.json";
  // The camera of the frame section the card links to (the report draws the boxes into its images).
  CameraSensor cam;
  cam.channel = "CAM_FRONT";
  cam.intrinsics.width = 64, cam.intrinsics.height = 48;
  cam.intrinsics.fx = cam.intrinsics.fy = 50, cam.intrinsics.cx = 32, cam.intrinsics.cy = 24;
  log_.frames[2].cameras = {cam};
  frames_[0].cameras[0].before = frames_[0].cameras[0].after = ImageU8(64, 48, 3, 90);
  WriteSynthReport(log_, frames_, {cone_}, dir_ / "out" / "report.html");
  std::string page = ReadFileToString(dir_ / "out" / "report.html");
  EXPECT_NE(page.find("<td><a href='#asset-cone'>cone</a></td>"), std::string::npos);
  EXPECT_NE(page.find("<h2 id='" + FrameAnchor(0) + "'>Frame tok-c</h2>"), std::string::npos);
  EXPECT_NE(page.find("<section class='card' id='asset-cone'>"), std::string::npos);
  // No real object in this frame: the page says the classifier has too little to learn from.
  EXPECT_NE(page.find("<h2>Real or inserted?</h2><p>Too few objects"), std::string::npos);
  EXPECT_NE(page.find("<h3 id='" + CameraAnchor(0, "CAM_FRONT") + "'>CAM_FRONT</h3><p>Assets: <a href='#asset-cone'>cone</a> &times;2<br>"),
            std::string::npos);
  std::transform(page.begin(), page.end(), page.begin(), [](unsigned char ch) { return std::tolower(ch); });
  EXPECT_EQ(page.find("http://"), std::string::npos);
  EXPECT_EQ(page.find("https://"), std::string::npos);
  EXPECT_EQ(page.find("//cdn"), std::string::npos);
}

TEST_F(ReportAssetsTest, NothingInsertedNoCards) {
  for (auto& f : frames_) f.objects.clear();
  const AssetCardsHtml html = WriteAssetCards(log_, frames_, {cone_}, dir_ / "report");
  EXPECT_TRUE(html.cards.empty());
  EXPECT_TRUE(html.index.empty());
  EXPECT_FALSE(fs::exists(dir_ / "report" / "report" / "assets"));
}

}  // namespace
}  // namespace sd
