#include "synth/report_assets.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "assetgen/preview.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "synth/outcome.h"

namespace sd {
namespace fs = std::filesystem;
namespace {

using nlohmann::json;

constexpr size_t kMaxShownViews = 8;
constexpr int kViewSizePx = 192;  // the longer side of a shown view, so eight fit one row of a card
constexpr int kTurntableViews = 8, kTurntableSizePx = 160;
constexpr size_t kMaxListedFrames = 40;  // a long sequence's card names the first frames, then a count
const char kDash[] = "&mdash;";
// The three.js files the viewer uses: (path in the npm package, name in report/three/).
const std::pair<const char*, const char*> kThreeFiles[] = {{"build/three.min.js", "three.min.js"},
                                                           {"examples/js/loaders/GLTFLoader.js", "GLTFLoader.js"},
                                                           {"examples/js/controls/OrbitControls.js", "OrbitControls.js"},
                                                           {"LICENSE", "LICENSE"}};

// One-to-one, so two ids never share a folder or an anchor.
std::string FileKey(const std::string& id) {
  std::string key;
  for (const char c : id) {
    if (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-') {
      key += c;
    } else {
      char hex[4];
      std::snprintf(hex, sizeof hex, "~%02X", static_cast<unsigned char>(c));
      key += hex;
    }
  }
  return key.empty() || key[0] == '.' ? "~" + key : key;  // never "", "." or ".."
}

std::string Base64(std::string_view bytes) {
  static const char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = uint32_t(uint8_t(bytes[i])) << 16 | uint32_t(uint8_t(bytes[i + 1])) << 8 | uint8_t(bytes[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out += kAlphabet[(v >> s) & 63];
  }
  if (const size_t rest = bytes.size() - i; rest > 0) {
    uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
    if (rest == 2) v |= uint32_t(uint8_t(bytes[i + 1])) << 8;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += rest == 2 ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string Format(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

// ---------------------------------------------------------------------------------------------------------
// Where each asset was inserted.

struct Insertion {
  size_t position = 0;  // in the report's frames
  std::vector<std::string> cameras;  // channels whose before/after pair draws the asset
  int objects = 0;
};

std::map<std::string, std::vector<Insertion>> InsertionsByAsset(const std::vector<FrameOutcome>& frames) {
  std::map<std::string, std::vector<Insertion>> by_asset;
  for (size_t p = 0; p < frames.size(); ++p) {
    const FrameOutcome& o = frames[p];
    std::map<std::string, Insertion> here;
    for (const ObjectOutcome& ob : o.objects) {
      Insertion& in = here[ob.label.asset_id];
      in.position = p;
      ++in.objects;
    }
    for (const CameraOutcome& co : o.cameras) {
      std::set<std::string> drawn;
      for (int k : co.objects)
        if (k >= 0 && static_cast<size_t>(k) < o.objects.size()) drawn.insert(o.objects[k].label.asset_id);
      for (const std::string& id : drawn) here[id].cameras.push_back(co.channel);
    }
    for (auto& [id, in] : here) by_asset[id].push_back(std::move(in));
  }
  return by_asset;
}

std::string InsertionsHtml(const Log& log, const std::vector<FrameOutcome>& frames, const std::vector<Insertion>& list) {
  int objects = 0;
  for (const Insertion& in : list) objects += in.objects;
  std::ostringstream html;
  html << "<p class='where'>Inserted " << objects << (objects == 1 ? " time" : " times") << " in " << list.size()
       << (list.size() == 1 ? " frame" : " frames") << ":";
  for (size_t i = 0; i < list.size() && i < kMaxListedFrames; ++i) {
    const Insertion& in = list[i];
    html << (i ? ";" : "") << " <a href='#" << FrameAnchor(in.position) << "'>"
         << EscapeHtml(log.frames[frames[in.position].frame_index].token) << "</a>";
    if (in.objects > 1) html << " &times;" << in.objects;
    if (in.cameras.empty()) html << " (no camera shows it)";
    for (size_t c = 0; c < in.cameras.size(); ++c)
      html << (c ? ", " : " (") << "<a href='#" << CameraAnchor(in.position, in.cameras[c]) << "'>"
           << EscapeHtml(in.cameras[c]) << "</a>" << (c + 1 == in.cameras.size() ? ")" : "");
  }
  if (list.size() > kMaxListedFrames) html << "; and " << list.size() - kMaxListedFrames << " more frames";
  html << "</p>";
  return html.str();
}

// ---------------------------------------------------------------------------------------------------------
// The real views.

// What asset.json says about the asset's files; defaults when it cannot be read (LoadAsset read it once, so
// this only fails when the folder changed since).
struct AssetFiles {
  fs::path mesh, cameras_json;
};

AssetFiles FilesOf(const Asset& asset) {
  AssetFiles f{asset.dir / "mesh.glb", asset.dir / "views" / "cameras.json"};
  try {
    const json j = ReadJsonFile(asset.dir / "asset.json");
    if (j.contains("mesh") && j["mesh"].is_string()) f.mesh = asset.dir / j["mesh"].get<std::string>();
    if (j.contains("views") && j["views"].is_string()) f.cameras_json = asset.dir / j["views"].get<std::string>();
  } catch (const std::exception&) {
  }
  return f;
}

struct ViewFiles {
  std::string name;
  fs::path image, mask;  // mask empty when cameras.json names none
};

struct RealViews {
  std::vector<ViewFiles> shown;  // at most kMaxShownViews real views with a colour image, spread over them
  size_t total = 0, synthetic = 0, real_without_image = 0;
  std::string problem;  // why no view can be listed; empty when cameras.json was read
};

RealViews FindRealViews(const fs::path& cameras_json) {
  RealViews views;
  if (!fs::exists(cameras_json)) {
    views.problem = fs::exists(cameras_json.parent_path())
                        ? "no real views: " + cameras_json.filename().string() + " is missing from its views folder"
                        : "no real views: the asset folder has no views/ (an imported mesh has none)";
    return views;
  }
  json list;
  try {
    const json j = ReadJsonFile(cameras_json);
    if (!j.contains("views") || !j["views"].is_array())
      throw InputError(cameras_json, "no \"views\" array");
    list = j["views"];
  } catch (const std::exception& e) {
    views.problem = std::string("no real views: ") + e.what();
    return views;
  }
  std::vector<ViewFiles> real;
  views.total = list.size();
  for (size_t i = 0; i < list.size(); ++i) {
    const json& v = list[i];
    // A missing flag means a camera saw it: only shape priors mark their rotated / mirrored copies.
    if (v.is_object() && v.value("synthetic", json(false)) == json(true)) {
      ++views.synthetic;
      continue;
    }
    if (!v.is_object() || !v.contains("image") || !v["image"].is_string()) {
      ++views.real_without_image;
      continue;
    }
    ViewFiles f;
    f.name = v.contains("name") && v["name"].is_string() ? v["name"].get<std::string>() : "view " + std::to_string(i);
    f.image = cameras_json.parent_path() / v["image"].get<std::string>();
    if (v.contains("mask") && v["mask"].is_string()) f.mask = cameras_json.parent_path() / v["mask"].get<std::string>();
    real.push_back(std::move(f));
  }
  const size_t shown = std::min(real.size(), kMaxShownViews);
  for (size_t k = 0; k < shown; ++k) views.shown.push_back(real[k * real.size() / shown]);
  return views;
}

ImageU8 BoxDownscale(const ImageU8& img, int factor) {
  if (factor <= 1) return img;
  ImageU8 out(std::max(1, img.width() / factor), std::max(1, img.height() / factor), img.channels());
  for (int y = 0; y < out.height(); ++y)
    for (int x = 0; x < out.width(); ++x)
      for (int c = 0; c < img.channels(); ++c) {
        int sum = 0, n = 0;
        for (int dy = 0; dy < factor && y * factor + dy < img.height(); ++dy)
          for (int dx = 0; dx < factor && x * factor + dx < img.width(); ++dx, ++n) sum += img.at(x * factor + dx, y * factor + dy, c);
        out.at(x, y, c) = static_cast<uint8_t>(sum / std::max(1, n));
      }
  return out;
}

// Cyan on the mask's inner boundary. The image border is not a boundary: a crop cuts the object there.
void DrawMaskOutline(ImageU8* img, const ImageU8& mask) {
  auto inside = [&](int x, int y) {
    if (x < 0 || y < 0 || x >= mask.width() || y >= mask.height()) return true;
    return mask.at(x, y) >= 128;
  };
  for (int y = 0; y < mask.height(); ++y)
    for (int x = 0; x < mask.width(); ++x)
      if (inside(x, y) && !(inside(x - 1, y) && inside(x + 1, y) && inside(x, y - 1) && inside(x, y + 1))) {
        uint8_t* p = img->pixel(x, y);
        p[0] = 0, p[1] = 255, p[2] = 255;
      }
}

// Writes the shown views; returns their figures, and problems with individual files in `notes`.
std::string RealViewsHtml(const RealViews& views, const fs::path& out_dir, const std::string& rel_dir,
                          std::vector<std::string>* notes) {
  std::ostringstream html;
  const size_t real = views.total - views.synthetic;
  if (!views.problem.empty()) return "<p class='note'>" + EscapeHtml(views.problem) + "</p>";
  html << "<p class='where'>Real views (the camera crops it was made from; cyan: its mask): " << real << " of " << views.total;
  if (views.synthetic > 0) html << "; " << views.synthetic << " synthetic (made by a shape prior) not shown";
  if (views.real_without_image > 0) html << "; " << views.real_without_image << " real without a colour image";
  if (real > views.shown.size() && !views.shown.empty()) html << "; " << views.shown.size() << " shown, spread over them";
  html << ".</p><div class='views'>";
  for (size_t k = 0; k < views.shown.size(); ++k) {
    const ViewFiles& v = views.shown[k];
    ImageU8 image;
    try {
      image = ReadImage(v.image, 3);
    } catch (const std::exception& e) {
      notes->push_back(e.what());
      continue;
    }
    const int factor = (std::max(image.width(), image.height()) + kViewSizePx - 1) / kViewSizePx;
    image = BoxDownscale(image, factor);
    if (!v.mask.empty()) {
      try {
        const ImageU8 mask = ReadImage(v.mask, 1);
        if (mask.width() / std::max(1, factor) == image.width() && mask.height() / std::max(1, factor) == image.height())
          DrawMaskOutline(&image, BoxDownscale(mask, factor));
        else
          notes->push_back(v.mask.string() + ": mask size differs from its image; shown without outline");
      } catch (const std::exception& e) {
        notes->push_back(std::string(e.what()) + "; shown without outline");
      }
    }
    char name[32];
    std::snprintf(name, sizeof name, "view_%02zu.png", k);
    WriteImage(out_dir / name, image);  // PNG: JPEG chroma subsampling smears a one-pixel outline
    html << "<figure><img loading='lazy' src='" << rel_dir << name << "'><figcaption>" << EscapeHtml(v.name)
         << "</figcaption></figure>";
  }
  html << "</div>";
  if (views.shown.empty()) return "<p class='note'>no real view with a colour image (" + std::to_string(views.total) +
                                  " views, " + std::to_string(views.synthetic) + " synthetic)</p>";
  return html.str();
}

// ---------------------------------------------------------------------------------------------------------
// Quality and stages.

std::string ValueHtml(const json& v) {
  if (v.is_boolean()) return v.get<bool>() ? "yes" : "no";
  if (v.is_number()) return Format("%.4g", v.get<double>());
  if (v.is_string()) return EscapeHtml(v.get<std::string>());
  if (v.is_null()) return kDash;
  return EscapeHtml(v.dump());
}

std::string QualityHtml(const AssetInfo& info) {
  const json& q = info.quality.is_object() ? info.quality : json::object();
  auto number = [&](const char* key, const char* fmt, double scale) -> std::string {
    if (!q.contains(key) || !q[key].is_number()) return kDash;
    return Format(fmt, scale * q[key].get<double>());
  };
  std::string watertight = kDash;
  if (q.contains(quality::kWatertight) && (q[quality::kWatertight].is_number() || q[quality::kWatertight].is_boolean()))
    watertight = (q[quality::kWatertight].is_boolean() ? q[quality::kWatertight].get<bool>() : q[quality::kWatertight].get<double>() != 0)
                     ? "yes"
                     : "no";
  std::string prior = kDash;
  if (q.contains(quality::kShapePrior) && q[quality::kShapePrior].is_object()) {
    const json& s = q[quality::kShapePrior];
    prior = s.contains("prior") ? ValueHtml(s["prior"]) : kDash;
    if (s.contains("reason") && s["reason"].is_string()) prior += " (" + EscapeHtml(s["reason"].get<std::string>()) + ")";
  }
  char extent[96];
  std::snprintf(extent, sizeof extent, "%.2f &times; %.2f &times; %.2f m", info.extent.x(), info.extent.y(), info.extent.z());
  std::ostringstream html;
  html << "<table class='quality'><tr><th colspan='2'>quality</th></tr>"
       << "<tr><td>category</td><td>" << (info.category.empty() ? kDash : EscapeHtml(info.category)) << "</td></tr>"
       << "<tr><td>extent (length &times; width &times; height)</td><td>" << extent << "</td></tr>"
       << "<tr><td title='mean silhouette IoU at real views left out of the fit'>held-out silhouette IoU</td><td>"
       << number(quality::kHeldOutSilhouetteIou, "%.3f", 1) << "</td></tr>"
       << "<tr><td title='median distance of the object&#39;s LiDAR returns to the surface'>LiDAR point-to-mesh median</td><td>"
       << number(quality::kLidarPointToMeshMedianM, "%.3f m", 1) << "</td></tr>"
       << "<tr><td title='surface area textured from real camera pixels'>real-texture fraction</td><td>"
       << number(quality::kRealTextureFraction, "%.0f %%", 100) << "</td></tr>"
       << "<tr><td>watertight</td><td>" << watertight << "</td></tr>"
       << "<tr><td>shape prior</td><td>" << prior << "</td></tr>";
  // Figures of other kinds of asset (a photo asset's photo_silhouette_iou, ...), as asset.json names them.
  static const std::set<std::string> kShown = {quality::kHeldOutSilhouetteIou, quality::kLidarPointToMeshMedianM,
                                               quality::kRealTextureFraction, quality::kWatertight, quality::kShapePrior};
  for (const auto& [key, value] : q.items())
    if (!kShown.count(key)) html << "<tr><td>" << EscapeHtml(key) << "</td><td>" << ValueHtml(value) << "</td></tr>";
  html << "</table>";
  return html.str();
}

std::string StagesHtml(const json& stages) {
  std::ostringstream html;
  html << "<table class='stages'><tr><th>stage</th><th>method</th><th>seconds</th></tr>";
  if (!stages.is_array() || stages.empty()) html << "<tr><td>" << kDash << "</td><td>" << kDash << "</td><td>" << kDash << "</td></tr>";
  if (stages.is_array())
    for (const json& s : stages) {
      if (!s.is_object()) continue;
      html << "<tr><td>" << (s.contains("stage") ? ValueHtml(s["stage"]) : kDash) << "</td><td>"
           << (s.contains("method") ? ValueHtml(s["method"]) : kDash) << "</td><td>"
           << (s.contains("seconds") && s["seconds"].is_number() ? Format("%.1f", s["seconds"].get<double>()) : kDash)
           << "</td></tr>";
    }
  html << "</table>";
  return html.str();
}

// ---------------------------------------------------------------------------------------------------------
// three.js and the viewer.

struct ThreeJs {
  bool usable = false;
  std::string version;  // package.json "version"
  std::string missing;  // for the card, when not usable
};

// Copies the viewer's files into report/three/ when ThreeJsDir() holds all of them.
ThreeJs CopyThreeJs(const fs::path& report_dir) {
  const fs::path dir = ThreeJsDir();
  ThreeJs three;
  for (const auto& [package_path, name] : kThreeFiles)
    if (!fs::exists(dir / package_path)) {
      three.missing = "three.js is not installed (no " + (dir / package_path).string() +
                      "): run scripts/setup.sh (or scripts/fetch_web.sh), then synthesise again";
      return three;
    }
  try {
    const json package = ReadJsonFile(dir / "package.json");
    three.version = package.value("version", std::string("?"));
    for (const auto& [package_path, name] : kThreeFiles) WriteFileAtomic(report_dir / "three" / name, ReadFileToString(dir / package_path));
  } catch (const std::exception& e) {
    three.missing = std::string("three.js could not be copied: ") + e.what();
    return three;
  }
  three.usable = true;
  return three;
}

// The viewer: loads three.js, then the asset's GLB script, on the first click, so an unopened card costs
// nothing. Classic scripts only (see report_assets.h).
const char kViewerScript[] = R"JS(<script>
window.sdGlb = window.sdGlb || {};
function sdScript(src) {
  return new Promise((resolve, reject) => {
    const s = document.createElement('script');
    s.src = src;
    s.onload = resolve;
    s.onerror = () => reject(new Error('cannot load ' + src));
    document.head.appendChild(s);
  });
}
let sdThreeLoaded = null;
function sdThree() {
  // GLTFLoader and OrbitControls extend the global THREE, so three.min.js runs first.
  if (!sdThreeLoaded)
    sdThreeLoaded = sdScript('report/three/three.min.js')
      .then(() => Promise.all([sdScript('report/three/GLTFLoader.js'), sdScript('report/three/OrbitControls.js')]));
  return sdThreeLoaded;
}
function sdBytes(base64) {
  const text = atob(base64), bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; ++i) bytes[i] = text.charCodeAt(i);
  return bytes.buffer;
}
async function sdView3d(button, key) {
  const holder = document.getElementById('view3d-' + key), status = holder.querySelector('.status');
  button.disabled = true;
  status.textContent = 'loading...';
  try {
    await sdThree();
    if (!(key in sdGlb)) await sdScript('report/assets/' + key + '/mesh_glb.js');
    const gltf = await new Promise((resolve, reject) => new THREE.GLTFLoader().parse(sdBytes(sdGlb[key]), '', resolve, reject));
    const width = 480, height = 360;
    const renderer = new THREE.WebGLRenderer({antialias: true});
    renderer.setPixelRatio(window.devicePixelRatio);
    renderer.setSize(width, height);
    renderer.outputEncoding = THREE.sRGBEncoding;
    const scene = new THREE.Scene();
    scene.background = new THREE.Color(0x202020);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.0));
    const sun = new THREE.DirectionalLight(0xffffff, 0.8);
    sun.position.set(3, 6, -4);
    scene.add(sun);
    scene.add(gltf.scene);
    const box = new THREE.Box3().setFromObject(gltf.scene);
    const size = box.getSize(new THREE.Vector3()), centre = box.getCenter(new THREE.Vector3());
    const radius = 0.5 * size.length() || 1;
    // A metric floor: 1 m squares under objects longer than 2 m, else 10 cm.
    const cell = Math.max(size.x, size.z) > 2 ? 1 : 0.1, cells = 2 * Math.ceil(1.5 * radius / cell);
    const grid = new THREE.GridHelper(cells * cell, cells, 0x777777, 0x3c3c3c);
    grid.position.y = box.min.y;
    scene.add(grid);
    const camera = new THREE.PerspectiveCamera(35, width / height, radius / 100, radius * 100);
    // The asset's front is +x and its left +y, which glTF (y up) holds as -z: a three-quarter view from the front left.
    camera.position.copy(centre).add(new THREE.Vector3(1, 0.6, -1).normalize().multiplyScalar(3.2 * radius));
    const controls = new THREE.OrbitControls(camera, renderer.domElement);
    controls.target.copy(centre);
    controls.update();
    const draw = () => renderer.render(scene, camera);
    controls.addEventListener('change', draw);
    draw();
    holder.insertBefore(renderer.domElement, status);
    status.textContent = 'drag: orbit, right-drag: pan, wheel: zoom; grid squares ' + (cell === 1 ? '1 m' : '10 cm') + '.';
  } catch (e) {
    status.textContent = '3D view failed: ' + (e && e.message ? e.message : e);
    button.disabled = false;
  }
}
</script>)JS";

// The card's viewer line: a "3D" button and its holder, or one line saying why there is none. Writes the
// GLB script when the view can work.
std::string ViewerHtml(const fs::path& mesh_file, const std::string& key, const fs::path& out_dir, const ThreeJs& three) {
  if (!three.usable) return "<p class='note'>3D view: " + EscapeHtml(three.missing) + ".</p>";
  std::string glb;
  try {
    glb = ReadFileToString(mesh_file);
  } catch (const std::exception& e) {
    return "<p class='note'>3D view: " + EscapeHtml(e.what()) + ".</p>";
  }
  if (glb.size() < 12 || glb.compare(0, 4, "glTF") != 0)
    return "<p class='note'>3D view: " + EscapeHtml(mesh_file.string()) + " is not a GLB file (no glTF header).</p>";
  WriteFileAtomic(out_dir / "mesh_glb.js", "(window.sdGlb = window.sdGlb || {})['" + key + "'] = '" + Base64(glb) + "';\n");
  char size[32];
  std::snprintf(size, sizeof size, "%.1f MB", glb.size() / 1e6);
  return "<div class='view3d' id='view3d-" + key + "'><button onclick=\"sdView3d(this, '" + key +
         "')\">3D</button> <span class='status'>interactive view of " + EscapeHtml(mesh_file.filename().string()) + " (" +
         size + ")</span></div>";
}

std::string CardHtml(const Asset& asset, const std::string& key, const fs::path& report_dir, const ThreeJs& three) {
  const fs::path out_dir = report_dir / "assets" / key;
  const std::string rel_dir = "report/assets/" + key + "/";
  fs::create_directories(out_dir);
  const AssetInfo& info = asset.info;
  const AssetFiles files = FilesOf(asset);
  std::vector<std::string> notes;
  std::ostringstream html;
  const bool named = !info.name.empty() && info.name != info.id;
  html << "<h3>" << EscapeHtml(named ? info.name : info.id) << " <span class='id'>("
       << (named ? EscapeHtml(info.id) + ", " : std::string()) << EscapeHtml(info.category) << ")</span></h3>";
  auto or_dash = [](const std::string& s) { return s.empty() ? std::string(kDash) : EscapeHtml(s); };
  html << "<p class='prov'>Source: " << or_dash(info.source) << "<br>Licence: " << or_dash(info.licence)
       << "<br>Attribution: " << or_dash(info.attribution) << "</p>";
  html << RealViewsHtml(FindRealViews(files.cameras_json), out_dir, rel_dir, &notes);

  if (asset.mesh.faces.empty() || asset.mesh.positions.empty()) {
    html << "<p class='note'>turntable: the mesh has no triangles</p>";
  } else {
    WriteImage(out_dir / "turntable.png", RenderTurntable(asset.mesh, kTurntableViews, kTurntableSizePx));
    html << "<figure><img loading='lazy' class='turntable' src='" << rel_dir
         << "turntable.png'><figcaption>turntable: unlit base colour every 45&deg; from the front towards the left, "
            "15&deg; elevation</figcaption></figure>";
  }
  html << ViewerHtml(files.mesh, key, out_dir, three);
  html << "<div class='tables'>" << QualityHtml(info) << StagesHtml(info.stages) << "</div>";
  for (const std::string& note : notes) html << "<p class='note'>" << EscapeHtml(note) << "</p>";
  return html.str();
}

const char kCardStyle[] =
    "<style>.card{border:1px solid #444;border-radius:6px;padding:4px 14px 10px;margin:12px 0;background:#181818}"
    ".card h3 .id{color:#888;font-weight:normal;font-size:13px}.card .prov{font-size:13px;color:#bbb}"
    ".card .views{display:flex;flex-wrap:wrap;gap:6px}.card figure{margin:0 0 8px}.card .note{color:#e0a040;font-size:13px}"
    ".card .tables{display:flex;gap:16px;align-items:flex-start;flex-wrap:wrap;margin-top:8px}"
    ".card .view3d canvas{display:block;margin:6px 0;border:1px solid #333}.card .where{font-size:13px}</style>";

}  // namespace

fs::path ThreeJsDir() {
  if (const char* dir = std::getenv("SYNTHDRIVE_WEB"); dir && *dir) return fs::path(dir) / "three";
  if (const char* cache = std::getenv("XDG_CACHE_HOME"); cache && *cache) return fs::path(cache) / "synthdrive" / "web" / "three";
  if (const char* home = std::getenv("HOME"); home && *home) return fs::path(home) / ".cache" / "synthdrive" / "web" / "three";
  return fs::path(".synthdrive-web") / "three";
}

std::string FrameAnchor(size_t frame_position) { return "frame-" + std::to_string(frame_position); }
std::string CameraAnchor(size_t frame_position, const std::string& channel) {
  return FrameAnchor(frame_position) + "-" + FileKey(channel);
}
std::string AssetAnchor(const std::string& asset_id) { return "asset-" + FileKey(asset_id); }

AssetCardsHtml WriteAssetCards(const Log& log, const std::vector<FrameOutcome>& frames, const std::vector<Asset>& assets,
                               const fs::path& html_dir) {
  const std::map<std::string, std::vector<Insertion>> insertions = InsertionsByAsset(frames);
  if (insertions.empty()) return {};
  // Cards in the order the assets were given; ids the caller did not pass come last.
  std::vector<std::pair<std::string, const Asset*>> cards;
  for (const Asset& a : assets)
    if (insertions.count(a.info.id) && std::none_of(cards.begin(), cards.end(), [&](const auto& c) { return c.first == a.info.id; }))
      cards.push_back({a.info.id, &a});
  for (const auto& [id, list] : insertions)
    if (std::none_of(cards.begin(), cards.end(), [&](const auto& c) { return c.first == id; })) cards.push_back({id, nullptr});

  const fs::path report_dir = html_dir / "report";
  const ThreeJs three = CopyThreeJs(report_dir);
  AssetCardsHtml out;
  std::ostringstream index, body;
  index << "<p>Inserted assets (their cards are at the end):";
  body << kCardStyle << "<h2 id='assets'>Inserted assets</h2>";
  if (three.usable)
    body << "<p>3D view: three.js " << EscapeHtml(three.version)
         << " (MIT licence: <a href='report/three/LICENSE'>report/three/LICENSE</a>), loaded on the first click.</p>";
  body << kViewerScript;
  for (size_t i = 0; i < cards.size(); ++i) {
    const auto& [id, asset] = cards[i];
    const std::string key = FileKey(id);
    const std::vector<Insertion>& list = insertions.at(id);
    int objects = 0;
    for (const Insertion& in : list) objects += in.objects;
    index << (i ? "," : "") << " <a href='#" << AssetAnchor(id) << "'>" << EscapeHtml(id) << "</a> (&times;" << objects << ")";
    body << "<section class='card' id='" << AssetAnchor(id) << "'>";
    if (!asset) {
      body << "<h3>" << EscapeHtml(id) << "</h3><p class='note'>"
           << EscapeHtml("asset '" + id + "' was not among the assets given to the report: no files to show") << "</p>";
    } else {
      try {
        body << CardHtml(*asset, key, report_dir, three);
      } catch (const std::exception& e) {  // a card must not cost the run its report
        body << "<p class='note'>card incomplete: " << EscapeHtml(e.what()) << "</p>";
      }
    }
    body << InsertionsHtml(log, frames, list) << "</section>";
  }
  index << ".</p>";
  out.index = index.str();
  out.cards = body.str();
  return out;
}

}  // namespace sd
