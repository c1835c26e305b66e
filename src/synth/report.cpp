#include "synth/report.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include <Eigen/Geometry>

#include "io/files.h"
#include "io/image_io.h"
#include "datasets/categories.h"
#include "synth/camera_look.h"
#include "synth/outcome.h"
#include "synth/realism.h"
#include "synth/synth_plan.h"
#include "synth/report_assets.h"

namespace sd {
namespace fs = std::filesystem;
namespace {

struct Rgb { uint8_t r, g, b; };
constexpr Rgb kRealColour{80, 140, 255}, kDetectedColour{255, 170, 40};  // annotations; detected keep-out boxes

void Plot(ImageU8& img, int x, int y, Rgb c) {
  if (x < 0 || y < 0 || x >= img.width() || y >= img.height()) return;
  uint8_t* p = img.pixel(x, y);
  p[0] = c.r; p[1] = c.g; p[2] = c.b;
}

void Line(ImageU8& img, double x0, double y0, double x1, double y1, Rgb c, int thickness) {
  const double len = std::hypot(x1 - x0, y1 - y0);
  if (!(len < 1e5)) return;  // degenerate projections far outside the image
  const int steps = std::max(1, static_cast<int>(len));
  for (int i = 0; i <= steps; ++i) {
    const double t = static_cast<double>(i) / steps;
    const int x = static_cast<int>(x0 + t * (x1 - x0)), y = static_cast<int>(y0 + t * (y1 - y0));
    for (int dy = -thickness / 2; dy <= thickness / 2; ++dy)
      for (int dx = -thickness / 2; dx <= thickness / 2; ++dx) Plot(img, x + dx, y + dy, c);
  }
}

void Rect(ImageU8& img, const Box2& b, Rgb c, int thickness) {
  Line(img, b.x1, b.y1, b.x2, b.y1, c, thickness);
  Line(img, b.x2, b.y1, b.x2, b.y2, c, thickness);
  Line(img, b.x2, b.y2, b.x1, b.y2, c, thickness);
  Line(img, b.x1, b.y2, b.x1, b.y1, c, thickness);
}

void ProjectedBox(ImageU8& img, const Box3& box, const CameraSensor& cam, Rgb c, int thickness) {
  const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
  const auto corners = box.Corners();
  static const int kEdges[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6}, {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
  for (const auto& e : kEdges) {
    const auto a = cam.intrinsics.Project(T_cam_ego * corners[e[0]], 0.2);
    const auto b = cam.intrinsics.Project(T_cam_ego * corners[e[1]], 0.2);
    if (a && b) Line(img, a->x(), a->y(), b->x(), b->y(), c, thickness);
  }
}

ImageU8 Downscale(const ImageU8& img, int factor) {
  ImageU8 out(img.width() / factor, img.height() / factor, img.channels());
  for (int y = 0; y < out.height(); ++y)
    for (int x = 0; x < out.width(); ++x)
      for (int c = 0; c < img.channels(); ++c) {
        int sum = 0;
        for (int dy = 0; dy < factor; ++dy)
          for (int dx = 0; dx < factor; ++dx) sum += img.at(x * factor + dx, y * factor + dy, c);
        out.at(x, y, c) = static_cast<uint8_t>(sum / (factor * factor));
      }
  return out;
}

// A crop of `img` around `b` (grown by half its size, at least 48 px a side, clipped to the image), enlarged
// `zoom` times by pixel repetition: the object as a perception engineer zooms into it, no resampling.
ImageU8 ZoomedCrop(const ImageU8& img, const Box2& b, int zoom) {
  const double cx = 0.5 * (b.x1 + b.x2), cy = 0.5 * (b.y1 + b.y2);
  const double hw = std::max(24.0, 0.75 * (b.x2 - b.x1)), hh = std::max(24.0, 0.75 * (b.y2 - b.y1));
  const int x0 = std::max(0, static_cast<int>(cx - hw)), y0 = std::max(0, static_cast<int>(cy - hh));
  const int x1 = std::min(img.width(), static_cast<int>(cx + hw)), y1 = std::min(img.height(), static_cast<int>(cy + hh));
  ImageU8 out(std::max(1, x1 - x0) * zoom, std::max(1, y1 - y0) * zoom, 3);
  for (int y = 0; y < out.height(); ++y)
    for (int x = 0; x < out.width(); ++x)
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = img.at(std::min(x1 - 1, x0 + x / zoom), std::min(y1 - 1, y0 + y / zoom), c);
  return out;
}

std::string Ratio(double inserted, double real) {
  if (inserted <= 0 || real <= 0) return "&mdash;";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", inserted / real);
  return buf;
}

std::string Figure(double v, int blocks) {
  if (blocks <= 0) return "&mdash;";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

ImageU8 BirdsEye(const Frame& frame, const FrameOutcome& o) {
  const int size = 800;
  const double range = 40.0, scale = size / (2 * range);  // px per metre; ego at the centre, x up
  ImageU8 img(size, size, 3, 16);
  auto to_px = [&](const Eigen::Vector3d& p) { return Eigen::Vector2d(size / 2 - p.y() * scale, size / 2 - p.x() * scale); };
  const PointCloud& cloud = *o.edit.points;
  std::vector<int> on_object(cloud.size(), -1);
  for (const auto& [i, k] : o.lidar_object_points) on_object[i] = k;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d p = frame.lidar->T_ego_lidar * cloud.xyz(i).cast<double>();
    const Eigen::Vector2d q = to_px(p);
    if (on_object[i] >= 0) {
      for (int d = -1; d <= 1; ++d) { Plot(img, int(q.x()) + d, int(q.y()), {255, 60, 60}); Plot(img, int(q.x()), int(q.y()) + d, {255, 60, 60}); }
    } else {
      const double h = std::clamp(o.ground.HeightAboveGround(p), -0.5, 3.0);
      const uint8_t v = static_cast<uint8_t>(70 + 60 * (h + 0.5));
      Plot(img, static_cast<int>(q.x()), static_cast<int>(q.y()), {v, v, v});
    }
  }
  auto draw_box = [&](const Box3& b, Rgb c) {
    const auto k = b.Corners();
    for (int i = 0; i < 4; ++i) {
      const auto a = to_px(k[i]), e = to_px(k[(i + 1) % 4]);
      Line(img, a.x(), a.y(), e.x(), e.y(), c, 1);
    }
    const auto f = to_px(b.T_frame_box * Eigen::Vector3d(0.5 * b.size.x(), 0, -0.5 * b.size.z()));
    const auto m = to_px(b.center());
    Line(img, m.x(), m.y(), f.x(), f.y(), c, 1);  // heading tick
  };
  for (const auto& a : frame.annotations) draw_box(a.box, a.detected ? kDetectedColour : kRealColour);
  for (const auto& ob : o.objects) draw_box(ob.placement.box, {255, 60, 60});
  // Ego marker.
  Rect(img, Box2{size / 2.0 - 4, size / 2.0 - 8, size / 2.0 + 4, size / 2.0 + 8}, {60, 220, 60}, 1);
  return img;
}

// The sequence player: per camera (and the LiDAR bird's-eye view) one image with a slider over the frames, a
// before/after switch and a play button, so a person sees the inserted objects stay put in the world while the
// ego drives past them. `images[channel][k]` = {before, after} file names of frame k (empty: not seen).
std::string SequencePlayer(const std::vector<std::string>& tokens,
                           const std::map<std::string, std::vector<std::pair<std::string, std::string>>>& images) {
  std::ostringstream html;
  html << "<h2>Sequence (" << tokens.size() << " frames)</h2><p>Slider: frame; the checkbox shows the input instead "
          "of the output; play steps at 5 frames per second.</p><script>const sdTokens=[";
  for (size_t k = 0; k < tokens.size(); ++k) html << (k ? "," : "") << "'" << EscapeHtml(tokens[k]) << "'";
  html << "];function sdShow(id){const p=document.getElementById(id),k=+p.querySelector('input[type=range]').value,"
          "b=p.querySelector('input[type=checkbox]').checked,f=JSON.parse(p.dataset.frames)[k];"
          "p.querySelector('img').src=f?'report/'+(b?f[0]:f[1]):'';p.querySelector('span').textContent="
          "'frame '+sdTokens[k]+(f?'':' (not written)')+(b?' before':' after');}"
          "function sdPlay(id){const p=document.getElementById(id),r=p.querySelector('input[type=range]');"
          "if(p.timer){clearInterval(p.timer);p.timer=null;return;}p.timer=setInterval(()=>{r.value=(+r.value+1)%"
          "(+r.max+1);sdShow(id);},200);}</script>";
  int id = 0;
  for (const auto& [channel, frames] : images) {
    const std::string pid = "player" + std::to_string(id++);
    std::string list = "[";
    for (size_t k = 0; k < frames.size(); ++k) {
      list += k ? "," : "";
      list += frames[k].first.empty() ? "null" : "[\"" + frames[k].first + "\",\"" + frames[k].second + "\"]";
    }
    list += "]";
    html << "<div class='player' id='" << pid << "' data-frames='" << list << "'><h3>" << EscapeHtml(channel)
         << "</h3><input type='range' min='0' max='" << frames.size() - 1 << "' value='0' oninput=\"sdShow('" << pid
         << "')\" style='width:60%'> <label><input type='checkbox' onchange=\"sdShow('" << pid
         << "')\"> before</label> <button onclick=\"sdPlay('" << pid << "')\">play / stop</button> <span></span><br><img></div>"
         << "<script>sdShow('" << pid << "')</script>";
  }
  return html.str();
}

// Each inserted object of one camera at full resolution (before and after, zoomed 3x) with its figures against
// the real objects of the same image (synth/realism.h): noise over the image's own, edge rise, saturation; the
// ratios inserted / real (real: the same category where the image has some, else all its real objects).
std::string RealismTable(const Frame& frame, const FrameOutcome& o, const CameraOutcome& co, const CameraSensor& cam,
                         const std::filesystem::path& dir, int* img_id, std::vector<ObjectLook>* measured) {
  const CameraLook look = EstimateCameraLook(co.before, std::nullopt);
  std::vector<ObjectLook> real;
  for (const Annotation& a : frame.annotations) {
    if (a.detected) continue;  // a LiDAR detection's box is no real object's outline
    ObjectLook l = MeasureObjectLook(co.after, cam, a.box, look);
    l.category = CanonicalCategory(a.category);
    if (l.pixels >= 24 * 12) real.push_back(l);
  }
  measured->insert(measured->end(), real.begin(), real.end());
  std::ostringstream h;
  h << "<p>Inserted objects at full resolution (3&times;), with their figures against the " << real.size()
    << " real objects of this image (noise: over the image's own flat-region noise; edge: median 10&ndash;90 % rise; "
       "ratio = inserted / real, 0.7&ndash;1.4 reads alike):</p><table><tr><th>#</th><th>before</th><th>after</th><th>noise</th>"
       "<th>edge rise px</th><th>saturation</th><th>compared with</th></tr>";
  for (int k : co.objects) {
    const ObjectOutcome& ob = o.objects[static_cast<size_t>(k)];
    Box2 box{};
    for (const CameraBox& cb : ob.label.camera_boxes)
      if (cb.channel == co.channel) box = cb.box;
    ObjectLook ins = MeasureObjectLook(co.after, cam, ob.placement.box, look);
    ins.category = ob.label.category;
    ins.inserted = true;
    if (ins.pixels > 0) measured->push_back(ins);
    std::vector<ObjectLook> same = real;
    same.erase(std::remove_if(same.begin(), same.end(), [&](const ObjectLook& l) { return l.category != ob.label.category; }), same.end());
    const std::vector<ObjectLook>& reference = same.empty() ? real : same;
    std::vector<ObjectLook> both = reference;
    both.push_back(ins);
    const LookComparison c = CompareLooks(both);
    const std::string b_name = "crop" + std::to_string(*img_id) + "_before.png", a_name = "crop" + std::to_string(*img_id) + "_after.png";
    ++*img_id;
    WriteImage(dir / b_name, ZoomedCrop(co.before, box, 3));
    WriteImage(dir / a_name, ZoomedCrop(co.after, box, 3));
    h << "<tr><td>" << k << "</td><td><img class='crop' src='report/" << b_name << "'></td><td><img class='crop' src='report/" << a_name
      << "'></td><td>" << Figure(ins.noise_ratio, ins.noise_blocks) << " vs " << Figure(c.real_noise, c.real) << " ("
      << Ratio(c.inserted_noise, c.real_noise) << ")</td><td>" << Figure(ins.edge_rise_px, ins.edges) << " vs "
      << Figure(c.real_edge_rise, c.real) << " (" << Ratio(c.inserted_edge_rise, c.real_edge_rise) << ")</td><td>"
      << Figure(ins.saturation, ins.pixels) << " vs " << Figure(c.real_saturation, c.real) << " ("
      << Ratio(c.inserted_saturation, c.real_saturation) << ")</td><td>"
      << (same.empty() ? "all " + std::to_string(real.size()) + " real objects" : std::to_string(same.size()) + " real " + EscapeHtml(ob.label.category))
      << "</td></tr>";
  }
  h << "</table>";
  return h.str();
}

}  // namespace

void WriteSynthReport(const Log& log, const std::vector<FrameOutcome>& frames, const std::vector<Asset>& assets,
                      const fs::path& html_path) {
  const fs::path dir = html_path.parent_path() / "report";
  fs::create_directories(dir);
  const AssetCardsHtml cards = WriteAssetCards(log, frames, assets, html_path.parent_path());
  std::ostringstream html;
  html << "<!doctype html><html><head><meta charset='utf-8'><title>SynthDrive synthesis report</title><style>"
          "body{font-family:sans-serif;background:#111;color:#ddd;margin:20px}h2{border-bottom:1px solid #444}"
          ".pair{display:flex;gap:8px;margin-bottom:14px}.pair figure{margin:0}img{max-width:100%;border:1px solid #333}"
          "table{border-collapse:collapse}td,th{border:1px solid #444;padding:3px 8px;font-size:13px}"
          "img.crop{max-width:none;image-rendering:pixelated}"
          "figcaption{font-size:12px;color:#aaa}a{color:#8ab4f8}</style></head><body>";
  html << "<h1>SynthDrive synthesis report</h1><p>Log: " << EscapeHtml(log.source.string()) << " (" << ToString(log.format)
       << "). Green: visible 2D box of an inserted object; yellow: its 3D box; blue: real annotations; orange: "
          "keep-out boxes detected from the LiDAR where the log has none (docs/detection.md; never written as labels).</p>";
  // World-fixed runs write the sequence plan beside this report.
  if (fs::exists(html_path.parent_path() / "plan.html"))
    html << "<p>Placement plan of the sequence(s): <a href='plan.html'>plan.html</a></p>";
  html << cards.index;
  int img_id = 0;
  // Per camera and frame, the images written (for the sequence player).
  std::map<std::string, std::vector<std::pair<std::string, std::string>>> player;
  std::vector<std::string> tokens;
  for (const auto& o : frames) tokens.push_back(log.frames[o.frame_index].token);
  auto note = [&](const std::string& channel, size_t k, const std::string& before, const std::string& after) {
    auto& row = player[channel];
    row.resize(frames.size());
    row[k] = {before, after};
  };
  std::ostringstream body;
  std::vector<ObjectLook> measured;  // every real and inserted object of the cameras drawn, for the classifier
  for (size_t fk = 0; fk < frames.size(); ++fk) {
    const FrameOutcome& o = frames[fk];
    const Frame& frame = log.frames[o.frame_index];
    body << "<h2 id='" << FrameAnchor(fk) << "'>Frame " << EscapeHtml(frame.token) << "</h2><p>Sun: " << EscapeHtml(o.sun_source) << "<br>Light: " << EscapeHtml(o.light)
         << "<br>Road: " << EscapeHtml(o.road)
         << "<br>LiDAR model: " << EscapeHtml(o.lidar_model) << (o.lidar_ego_motion ? " (ego motion during the sweep)" : "")
         << "</p>";
    body << "<table><tr><th>#</th><th>asset</th><th>category</th><th>centre (ego, m)</th><th>size (m)</th>"
            "<th>yaw (deg)</th><th>LiDAR points</th><th>visible</th><th>cameras</th></tr>";
    for (size_t k = 0; k < o.objects.size(); ++k) {
      const auto& ob = o.objects[k];
      const Box3& b = ob.placement.box;
      char buf[256];
      std::snprintf(buf, sizeof buf, "(%.2f, %.2f, %.2f)</td><td>%.2f x %.2f x %.2f</td><td>%.1f", b.center().x(), b.center().y(),
                    b.center().z(), b.size.x(), b.size.y(), b.size.z(), b.Yaw() * 180 / M_PI);
      std::string cams;
      for (const auto& cb : ob.label.camera_boxes) cams += cb.channel + " ";
      body << "<tr><td>" << k << "</td><td><a href='#" << AssetAnchor(ob.label.asset_id) << "'>" << EscapeHtml(ob.label.asset_id)
           << "</a></td><td>" << ob.label.category << "</td><td>" << buf
           << "</td><td>" << ob.lidar_points << "</td><td>"
           << static_cast<int>(100 * (ob.rendered_pixels > 0 ? ob.visible_pixels / ob.rendered_pixels : 0)) << "%</td><td>" << cams
           << "</td></tr>";
    }
    body << "</table>";
    for (const auto& co : o.cameras) {
      const CameraSensor* cam = frame.FindCamera(co.channel);
      ImageU8 before = co.before, after = co.after;
      for (const auto& a : frame.annotations) ProjectedBox(before, a.box, *cam, a.detected ? kDetectedColour : kRealColour, 1);
      for (int k : co.objects) {
        const auto& ob = o.objects[k];
        ProjectedBox(after, ob.placement.box, *cam, {255, 220, 0}, 2);
        for (const auto& cb : ob.label.camera_boxes)
          if (cb.channel == co.channel) Rect(after, cb.box, {40, 255, 40}, 2);
      }
      const std::string b_name = "img" + std::to_string(img_id) + "_before.jpg";
      const std::string a_name = "img" + std::to_string(img_id) + "_after.jpg";
      ++img_id;
      const int factor = before.width() > 1000 ? 2 : 1;
      WriteImage(dir / b_name, factor > 1 ? Downscale(before, factor) : before, 88);
      WriteImage(dir / a_name, factor > 1 ? Downscale(after, factor) : after, 88);
      note(co.channel, fk, b_name, a_name);
      std::map<std::string, int> shown;  // the assets in this picture, each linked to its card below
      for (int k : co.objects) ++shown[o.objects[k].label.asset_id];
      body << "<h3 id='" << CameraAnchor(fk, co.channel) << "'>" << EscapeHtml(co.channel) << "</h3><p>";
      if (!shown.empty()) {
        body << "Assets:";
        for (auto it = shown.begin(); it != shown.end(); ++it)
          body << (it == shown.begin() ? " " : ", ") << "<a href='#" << AssetAnchor(it->first) << "'>" << EscapeHtml(it->first)
               << "</a>" << (it->second > 1 ? " &times;" + std::to_string(it->second) : "");
        body << "<br>";
      }
      body << EscapeHtml(co.light) << "</p><div class='pair'><figure><img src='report/" << b_name
           << "'><figcaption>before (real annotations)</figcaption></figure><figure><img src='report/" << a_name
           << "'><figcaption>after</figcaption></figure></div>";
      if (!co.objects.empty()) body << RealismTable(frame, o, co, *cam, dir, &img_id, &measured);
    }
    if (frame.lidar && o.edit.points) {
      const std::string name = "bev" + std::to_string(img_id++) + ".png";
      WriteImage(dir / name, BirdsEye(frame, o));
      note("LiDAR, bird's-eye view", fk, name, name);
      body << "<h3>LiDAR, bird's-eye view (80 m x 80 m, ego at the centre facing up)</h3><img src='report/" << name
           << "' style='max-width:800px'>";
    }
  }
  // A sequence: the cameras the objects never touch in a frame still play, from the input's own image.
  if (frames.size() >= 2) {
    for (auto& [channel, row] : player) {
      row.resize(frames.size());
      for (size_t k = 0; k < row.size(); ++k) {
        if (!row[k].first.empty()) continue;
        const CameraSensor* cam = log.frames[frames[k].frame_index].FindCamera(channel);
        if (!cam || !fs::exists(cam->image_path)) continue;
        const ImageU8 img = ReadImage(cam->image_path, 3);
        const std::string name = "img" + std::to_string(img_id++) + "_input.jpg";
        WriteImage(dir / name, img.width() > 1000 ? Downscale(img, 2) : img, 88);
        row[k] = {name, name};
      }
    }
    html << SequencePlayer(tokens, player);
  }
  // Could a detector tell the inserts from the real objects by these statistics alone? (realism.h)
  const TwoSampleTest test = ClassifyRealVsInserted(measured);
  html << "<h2>Real or inserted?</h2><p>";
  if (test.folds > 0)
    html << "A classifier on each object's noise, edge rise and saturation (cross-validated logistic regression, "
         << test.folds << " folds) tells the " << test.inserted << " inserted objects from the " << test.real
         << " real objects of the same images with a balanced accuracy of <b>" << Fixed(test.balanced_accuracy, 2)
         << "</b> (0.5 = chance: they measure alike; 1 = every one told apart).";
  else
    html << "Too few objects to train a real-vs-inserted classifier (" << test.real << " real, " << test.inserted
         << " inserted; two of each are needed).";
  html << " Per object below; cast shadows against the real objects' in <code>synthdrive eval realism</code>.</p>";
  html << body.str();
  html << cards.cards;
  html << "</body></html>\n";
  WriteFileAtomic(html_path, html.str());
}

void WritePlanReport(const Log& log, const SynthPlan& plan, const fs::path& html_path) {
  static const char* kColors[] = {"#ff8c00", "#e6194b", "#3cb44b", "#ffe119", "#f032e6", "#42d4f4", "#bfef45", "#fabed4"};
  std::ostringstream html;
  html << "<!doctype html><html><head><meta charset='utf-8'><title>SynthDrive synthesis plan</title><style>"
          "body{font-family:sans-serif;background:#111;color:#ddd;margin:20px}h2{border-bottom:1px solid #444}"
          "table{border-collapse:collapse}td,th{border:1px solid #444;padding:1px 4px;font-size:11px;text-align:center}"
          "td.v{background:#264d26}td.r{background:#4d4426}svg{background:#1b1b1b;border:1px solid #333}</style></head><body>";
  html << "<h1>SynthDrive synthesis plan (dry run)</h1><p>Log: " << EscapeHtml(log.source.string()) << " (" << ToString(log.format)
       << "). Top-down, world frame: white = ego path (a dot per frame), blue = annotated boxes of every planned frame, "
          "filled = placed objects (colour per arrangement / request).</p>";
  char buf[256];
  for (const auto& seq : plan.sequences) {
    const SequencePlan& p = seq.plan;
    html << "<h2>Frames " << p.frame_begin << ".." << p.frame_end - 1 << "</h2><p>Surface: " << EscapeHtml(seq.surface) << " ("
         << EscapeHtml(seq.surface_detail) << "). Ego path " << p.ego_path_length_m << " m, " << p.objects.size()
         << " objects, seed " << p.seed << ", margin " << p.margin_m << " m.</p>";
    std::vector<std::array<Eigen::Vector2d, 4>> real;
    std::vector<Eigen::Vector2d> path;
    for (const PlannedFrame& f : p.frames) {
      const Frame& frame = log.frames[f.frame_index];
      path.push_back(frame.T_world_ego.translation.head<2>());
      for (const auto& a : frame.annotations) {
        const auto c = a.box.Transformed(frame.T_world_ego).Corners();
        real.push_back({c[0].head<2>(), c[1].head<2>(), c[2].head<2>(), c[3].head<2>()});
      }
    }
    Eigen::AlignedBox2d extent;
    for (const auto& q : path) extent.extend(q);
    for (const auto& o : p.objects)
      for (const auto& c : o.box.Corners()) extent.extend(c.head<2>());
    extent.min() -= Eigen::Vector2d(15, 15);
    extent.max() += Eigen::Vector2d(15, 15);
    const double width_px = 1000, scale = width_px / std::max(extent.sizes().x(), 1.0);
    const double height_px = std::min(1400.0, extent.sizes().y() * scale);
    auto X = [&](const Eigen::Vector2d& q) { return (q.x() - extent.min().x()) * scale; };
    auto Y = [&](const Eigen::Vector2d& q) { return (extent.max().y() - q.y()) * scale; };
    auto polygon = [&](const auto& pts) {
      std::string s;
      for (const auto& q : pts) {
        std::snprintf(buf, sizeof buf, "%.1f,%.1f ", X(q), Y(q));
        s += buf;
      }
      return s;
    };
    std::snprintf(buf, sizeof buf, "<svg width='%.0f' height='%.0f'>", width_px, height_px);
    html << buf;
    for (const auto& r : real)
      html << "<polygon points='" << polygon(r) << "' fill='none' stroke='#4f7fd0' stroke-width='0.6' opacity='0.6'/>";
    html << "<polyline points='" << polygon(path) << "' fill='none' stroke='#fff' stroke-width='1.5'/>";
    for (const auto& q : path) {
      std::snprintf(buf, sizeof buf, "<circle cx='%.1f' cy='%.1f' r='2' fill='#fff'/>", X(q), Y(q));
      html << buf;
    }
    std::vector<std::string> sources;
    for (size_t i = 0; i < p.objects.size(); ++i) {
      const PlannedObject& o = p.objects[i];
      size_t color = std::find(sources.begin(), sources.end(), o.source) - sources.begin();
      if (color == sources.size()) sources.push_back(o.source);
      const auto c = o.box.Corners();
      const std::array<Eigen::Vector2d, 4> fp{c[0].head<2>(), c[1].head<2>(), c[2].head<2>(), c[3].head<2>()};
      html << "<polygon points='" << polygon(fp) << "' fill='" << kColors[color % 8] << "' stroke='#000' stroke-width='0.5'><title>"
           << i << ": " << EscapeHtml(o.source) << " " << EscapeHtml(o.role) << " " << EscapeHtml(o.category) << " "
           << EscapeHtml(o.asset_id) << "</title></polygon>";
      std::snprintf(buf, sizeof buf, "<text x='%.1f' y='%.1f' fill='#ddd' font-size='10'>%zu</text>", X(o.box.center().head<2>()) + 4,
                    Y(o.box.center().head<2>()) - 4, i);
      html << buf;
    }
    html << "</svg><p>";
    for (size_t s = 0; s < sources.size(); ++s)
      html << "<span style='color:" << kColors[s % 8] << "'>&#9632;</span> " << EscapeHtml(sources[s]) << " &nbsp; ";
    html << "</p><table><tr><th>frame</th><th>token</th>";
    for (size_t i = 0; i < p.objects.size(); ++i) html << "<th title='" << EscapeHtml(p.objects[i].category) << "'>" << i << "</th>";
    html << "</tr><tr><td></td><td>category</td>";
    for (const auto& o : p.objects) html << "<td>" << EscapeHtml(o.category) << "</td>";
    html << "</tr>";
    for (const PlannedFrame& f : p.frames) {
      html << "<tr><td>" << f.frame_index << "</td><td>" << EscapeHtml(f.token.substr(0, 10)) << "</td>";
      for (const PlannedView& v : f.objects) {
        std::snprintf(buf, sizeof buf, "%.1f m", v.distance_m);
        html << "<td class='" << (v.visible ? "v" : v.in_range ? "r" : "") << "' title='" << buf << "'>"
             << (v.visible ? "V" : v.in_range ? "r" : "") << "</td>";
      }
      html << "</tr>";
    }
    html << "</table>";
  }
  html << "</body></html>\n";
  WriteFileAtomic(html_path, html.str());
}

}  // namespace sd
