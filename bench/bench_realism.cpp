// Realism of inserted objects against the real thing (issue 8): each annotated real cone / barrier / car of the
// repo's nuScenes keyframe (data/driving/nuscenes-scene0061-kf0, mmdet3d info) and, when ../shared is present,
// of the KITTI frames (../shared/data/driving/kitti-object-openpcdet) is replaced by the demo asset of its
// category, scaled per axis to the annotated box and placed at it. Barriers are evaluated twice: with the demo's
// MetaDrive road barrier (an open sawhorse barricade; category "barrier", as before) and with the solid New Jersey
// concrete barrier of data/assets/procedural_jersey_barrier (tools/assets/make_jersey_barrier.py; reported as
// "barrier (solid)", and left out of the "all" medians so that those keep one mesh per object). Then:
//  - LiDAR: every beam of the real sweep (sensor origin -> each real return) is cast at the mesh alone
//    (render/lidar_cast.h CastLidarRays). A hit is a simulated point when the real beam was not blocked before
//    it: its real return lies inside the box (grown 0.2 m) or beyond the simulated range - 0.2 m. Beams that
//    returned nothing in the real sweep are not cast (both sides see the same beam set). Compared with the real
//    points inside the box: count ratio (simulated / real) and Chamfer distance (mean of the two mean
//    nearest-neighbour distances, metres). Points within 5 cm of the box bottom are left out on both sides
//    (road returns inside ground-touching boxes).
//  - Cameras: for each camera where the dataset has its own 2D box for the object (KITTI label bbox; nuScenes
//    v1 infos cam_instances), the mesh alone is rendered (render/camera_render.h RenderCamera, 1 spp, object-id
//    image) and the tight box of its silhouette is compared with the dataset box (IoU). Occlusion by other
//    scene content is not modelled (the mesh is alone in the scene). As a reference, the IoU of the annotated 3D
//    box's projected corner rectangle against the same dataset box is reported too (box_projection_iou).
// Prints a table per object and medians per dataset and category; writes bench/results/realism.json.
//
// Usage: bench_realism [--out PATH] [--no-kitti]. Repo root: $SYNTHDRIVE_SOURCE_DIR, else build/bin/../../.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "assetgen/canonical.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/mesh_io.h"
#include "render/camera_render.h"
#include "render/lidar_cast.h"
#include "render/ray_scene.h"

#include "bench_demo.h"

namespace {
namespace fs = std::filesystem;

using sd::bench::FindRepoRoot;

// One mesh an annotated object of `category` is replaced by; `label` is the category column of the tables and
// the JSON ("barrier (solid)" for the extra barrier mesh, else the category itself).
struct BenchMesh {
  std::string category, label, asset;
  sd::TriangleMesh mesh;
  bool Extra() const { return label != category; }
};

// The demo's meshes canonicalised in memory, as the demo imports them (src/cli/cmd_demo.cpp): y-up, the cone
// scaled to 0.7 m, the barrier and the car in metres; then the jersey barrier (y-up, metres, its front = the
// file's +x, the faces toward traffic: like the MetaDrive barrier, the thin side is the front, as the nuScenes
// boxes' length is). Canonical frame: x front, y left, z up.
std::vector<BenchMesh> LoadBenchMeshes(const fs::path& data) {
  std::vector<BenchMesh> out;
  auto add = [&](const sd::bench::DemoMesh& m, const std::string& label) {
    out.push_back({m.category, label, m.id, sd::Canonicalize(sd::LoadMesh(data / m.mesh), m.Options()).mesh});
  };
  for (const sd::bench::DemoMesh& m : sd::bench::DemoMeshes()) add(m, m.category);
  add({"assets/procedural_jersey_barrier/jersey_barrier.obj", "procedural_jersey_barrier", "barrier", "+x", 1.0, 0},
      "barrier (solid)");
  return out;
}

// The mesh scaled per axis so that its bounding box is the annotated box, in the log's ego frame.
sd::TriangleMesh MeshAtBox(const sd::TriangleMesh& canonical, const sd::Box3& box) {
  sd::TriangleMesh m = canonical;
  const sd::AlignedBox3f b = m.Bounds();
  const Eigen::Vector3f size = b.Size();
  const Eigen::Vector3f centre = b.Center();
  for (auto& p : m.positions) {
    Eigen::Vector3d q;
    for (int k = 0; k < 3; ++k) q[k] = (p[k] - centre[k]) / std::max(size[k], 1e-6f) * box.size[k];
    p = (box.T_frame_box * q).cast<float>();
  }
  m.normals.clear();
  m.ComputeVertexNormals();
  return m;
}

double MeanNearest(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b) {
  double sum = 0;
  for (const auto& p : a) {
    double best = std::numeric_limits<double>::infinity();
    for (const auto& q : b) best = std::min(best, (p - q).squaredNorm());
    sum += std::sqrt(best);
  }
  return sum / static_cast<double>(a.size());
}

double Median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

struct CameraResult {
  std::string camera;
  sd::Box2 real, rendered;
  double iou = 0;
  // Reference: the rectangle of the annotated 3D box's projected corners (clipped to the image) against the
  // dataset box; NaN when the box straddles the image plane. Separates box/calibration effects from the mesh.
  double box_iou = std::numeric_limits<double>::quiet_NaN();
};

struct ObjectResult {
  std::string dataset, frame, category, asset, token;  // category: BenchMesh::label
  bool extra = false;                                 // BenchMesh::Extra(): not in the "all" medians
  double distance = 0;
  int real_points = 0, sim_points = 0;
  double count_ratio = std::numeric_limits<double>::quiet_NaN();
  double chamfer = std::numeric_limits<double>::quiet_NaN();
  std::vector<CameraResult> cameras;
};

bool AboveBottom(const sd::Box3& box, const Eigen::Vector3d& p_ego) {
  const Eigen::Vector3d q = box.T_frame_box.Inverse() * p_ego;
  return q.z() > -0.5 * box.size.z() + 0.05;
}

void EvaluateFrame(const std::string& dataset, const sd::Frame& frame, const std::vector<BenchMesh>& meshes,
                   std::vector<ObjectResult>& results) {
  if (!frame.lidar) return;
  const sd::PointCloud sweep = sd::ReadLidar(*frame.lidar);
  const Eigen::Vector3d origin_ego = frame.lidar->T_ego_lidar.translation;
  std::vector<Eigen::Vector3d> points(sweep.size());
  std::vector<Eigen::Vector3f> dirs(sweep.size());
  std::vector<double> ranges(sweep.size());
  for (size_t i = 0; i < sweep.size(); ++i) {
    points[i] = frame.lidar->T_ego_lidar * sweep.xyz(i).cast<double>();
    const Eigen::Vector3d d = points[i] - origin_ego;
    ranges[i] = d.norm();
    dirs[i] = (ranges[i] > 1e-6 ? Eigen::Vector3d(d / ranges[i]) : Eigen::Vector3d::UnitX()).cast<float>();
  }
  for (const auto& ann : frame.annotations) {
    const auto cat = sd::FindCategory(ann.category);
    if (!cat) continue;
    for (const BenchMesh& bench_mesh : meshes) {
      if (bench_mesh.category != cat->name) continue;
      ObjectResult r;
      r.dataset = dataset;
      r.frame = frame.token;
      r.category = bench_mesh.label;
      r.asset = bench_mesh.asset;
      r.extra = bench_mesh.Extra();
      r.token = ann.token;
      r.distance = (ann.box.center() - origin_ego).head<2>().norm();

      auto mesh = std::make_shared<const sd::TriangleMesh>(MeshAtBox(bench_mesh.mesh, ann.box));
      sd::RayScene scene;
      scene.AddMesh(mesh);
      scene.Commit();

      // Real points on the object.
      std::vector<Eigen::Vector3d> real, sim;
      for (const auto& p : points)
        if (ann.box.Contains(p) && AboveBottom(ann.box, p)) real.push_back(p);
      // Simulated: the real beams that reach the mesh unblocked. Only beams towards the box's neighbourhood are
      // cast (a cheap angular prefilter: the box's bounding sphere seen from the sensor).
      const Eigen::Vector3d to_box = ann.box.center() - origin_ego;
      const double radius = 0.5 * ann.box.size.norm() + 0.5;
      const double dist = to_box.norm();
      const double cos_max = dist > radius ? std::cos(std::asin(radius / dist)) : -1.0;
      const Eigen::Vector3d axis = to_box / std::max(dist, 1e-9);
      std::vector<size_t> idx;
      std::vector<Eigen::Vector3f> cast_dirs;
      for (size_t i = 0; i < dirs.size(); ++i)
        if (dirs[i].cast<double>().dot(axis) >= cos_max) {
          idx.push_back(i);
          cast_dirs.push_back(dirs[i]);
        }
      const auto hits = sd::CastLidarRays(scene, origin_ego.cast<float>(), cast_dirs, 200.0f);
      for (size_t k = 0; k < hits.size(); ++k) {
        if (!hits[k].hit) continue;
        const size_t i = idx[k];
        const bool unblocked = ann.box.Contains(points[i], 0.2) || ranges[i] >= hits[k].range - 0.2;
        const Eigen::Vector3d p = hits[k].point.cast<double>();
        if (unblocked && AboveBottom(ann.box, p)) sim.push_back(p);
      }
      r.real_points = static_cast<int>(real.size());
      r.sim_points = static_cast<int>(sim.size());
      if (!real.empty()) r.count_ratio = static_cast<double>(sim.size()) / static_cast<double>(real.size());
      if (!real.empty() && !sim.empty()) r.chamfer = 0.5 * (MeanNearest(real, sim) + MeanNearest(sim, real));

      // Cameras with a dataset 2D box.
      for (const auto& [channel, real_box] : ann.box2d_by_camera) {
        const sd::CameraSensor* cam = frame.FindCamera(channel);
        if (!cam || real_box.Empty()) continue;
        const sd::Rigid3d T_cam_ego = cam->T_ego_cam.Inverse();
        const auto corners = ann.box.Corners();
        bool straddles = false;
        for (const auto& c : corners) straddles |= (T_cam_ego * c).z() <= 1e-3;
        double box_iou = std::numeric_limits<double>::quiet_NaN();
        sd::CameraRenderOptions ro;
        ro.samples_per_pixel = 1;
        ro.ao_samples = 0;
        if (!straddles) {
          const auto rect = sd::ProjectedRect(cam->intrinsics, T_cam_ego,
                                              std::vector<Eigen::Vector3d>(corners.begin(), corners.end()), 2);
          if (!rect) continue;
          const auto tight = sd::ProjectedRect(cam->intrinsics, T_cam_ego,
                                               std::vector<Eigen::Vector3d>(corners.begin(), corners.end()), 0);
          if (tight) box_iou = sd::IoU(sd::Box2{double((*tight)[0]), double((*tight)[1]), double((*tight)[2]),
                                                double((*tight)[3])},
                                       real_box);
          ro.x0 = (*rect)[0];
          ro.y0 = (*rect)[1];
          ro.x1 = (*rect)[2];
          ro.y1 = (*rect)[3];
        }
        const sd::CameraRender render = sd::RenderCamera(scene, cam->intrinsics, cam->T_ego_cam, sd::Lighting{}, ro);
        int x1 = std::numeric_limits<int>::max(), y1 = x1, x2 = -1, y2 = -1;
        for (int y = 0; y < render.object.height(); ++y)
          for (int x = 0; x < render.object.width(); ++x)
            if (render.object.at(x, y) >= 0) {
              x1 = std::min(x1, x);
              y1 = std::min(y1, y);
              x2 = std::max(x2, x + 1);
              y2 = std::max(y2, y + 1);
            }
        CameraResult c;
        c.camera = channel;
        c.real = real_box;
        if (x2 >= 0) c.rendered = sd::Box2{double(x1), double(y1), double(x2), double(y2)};
        c.iou = sd::IoU(c.rendered, real_box);
        c.box_iou = box_iou;
        r.cameras.push_back(c);
      }
      results.push_back(std::move(r));
    }
  }
}

nlohmann::json Num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

}  // namespace

int main(int argc, char** argv) {
  fs::path out_path;
  bool kitti = true;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--out") && i + 1 < argc) {
      out_path = argv[++i];
    } else if (!std::strcmp(argv[i], "--no-kitti")) {
      kitti = false;
    } else {
      std::fprintf(stderr, "usage: bench_realism [--out PATH] [--no-kitti]\n");
      return 2;
    }
  }
  const auto root = FindRepoRoot();
  if (!root) {
    std::fprintf(stderr, "bench_realism: cannot find the repo's data/ (set SYNTHDRIVE_SOURCE_DIR to the repo root)\n");
    return 1;
  }
  if (out_path.empty()) out_path = *root / "bench" / "results" / "realism.json";
  sd::SetLogLevel(sd::LogLevel::kWarn);
  try {
    const auto meshes = LoadBenchMeshes(*root / "data");
    std::vector<ObjectResult> results;
    const sd::Log nus =
        sd::OpenLog(*root / "data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");
    for (const auto& f : nus.frames) EvaluateFrame("nuscenes", f, meshes, results);
    const fs::path kitti_root = *root / ".." / "shared" / "data" / "driving" / "kitti-object-openpcdet";
    if (kitti && fs::is_directory(kitti_root)) {
      const sd::Log k = sd::OpenLog(kitti_root);
      for (const auto& f : k.frames) EvaluateFrame("kitti", f, meshes, results);
    } else {
      std::printf("(KITTI skipped: %s)\n", kitti ? "../shared/data/driving/kitti-object-openpcdet not found" : "--no-kitti");
    }

    std::printf("%-8s %-7s %-15s %6s %5s %5s %6s %8s  %s\n", "dataset", "frame", "category", "dist_m", "real",
                "sim", "ratio", "chamf_m", "2D IoU per camera");
    nlohmann::json objects = nlohmann::json::array();
    struct Agg { std::vector<double> ratio, chamfer, iou, box_iou; int n = 0; };
    std::map<std::pair<std::string, std::string>, Agg> agg;
    for (const auto& r : results) {
      std::string cams;
      nlohmann::json jc = nlohmann::json::array();
      // The extra barrier mesh's rows count in their own category only: "all" keeps one mesh per object.
      std::vector<Agg*> into = {&agg[{r.dataset, r.category}]};
      if (!r.extra) into.push_back(&agg[{r.dataset, "all"}]);
      for (Agg* a : into) ++a->n;
      for (const auto& c : r.cameras) {
        char buf[96];
        std::snprintf(buf, sizeof buf, "%s=%.2f ", c.camera.c_str(), c.iou);
        cams += buf;
        jc.push_back({{"camera", c.camera},
                      {"real_box", {c.real.x1, c.real.y1, c.real.x2, c.real.y2}},
                      {"rendered_box", c.rendered.Empty() ? nlohmann::json(nullptr)
                                                          : nlohmann::json({c.rendered.x1, c.rendered.y1,
                                                                            c.rendered.x2, c.rendered.y2})},
                      {"iou", c.iou},
                      {"box_projection_iou", Num(c.box_iou)}});
        for (Agg* a : into) {
          a->iou.push_back(c.iou);
          if (std::isfinite(c.box_iou)) a->box_iou.push_back(c.box_iou);
        }
      }
      std::printf("%-8s %-7.7s %-15s %6.1f %5d %5d %6.2f %8.3f  %s\n", r.dataset.c_str(), r.frame.c_str(),
                  r.category.c_str(), r.distance, r.real_points, r.sim_points, r.count_ratio, r.chamfer, cams.c_str());
      // Medians over objects with enough real points for the LiDAR figures to mean something.
      if (r.real_points >= 5)
        for (Agg* a : into) {
          a->ratio.push_back(r.count_ratio);
          if (std::isfinite(r.chamfer)) a->chamfer.push_back(r.chamfer);
        }
      objects.push_back({{"dataset", r.dataset}, {"frame", r.frame}, {"category", r.category}, {"asset", r.asset},
                         {"token", r.token}, {"distance_m", r.distance}, {"real_points", r.real_points},
                         {"sim_points", r.sim_points},
                         {"count_ratio", Num(r.count_ratio)}, {"chamfer_m", Num(r.chamfer)}, {"cameras", jc}});
    }
    std::printf("\nMedians (LiDAR over objects with >= 5 real points; IoU over every object-camera pair):\n");
    std::printf("%-8s %-15s %5s %8s %11s %9s %8s %9s %9s\n", "dataset", "category", "objs", "lidar_n", "count_ratio",
                "chamfer_m", "cam_n", "2D_IoU", "boxprj_IoU");
    nlohmann::json medians = nlohmann::json::array();
    for (const auto& [key, a] : agg) {
      std::printf("%-8s %-15s %5d %8zu %11.2f %9.3f %8zu %9.2f %9.2f\n", key.first.c_str(), key.second.c_str(), a.n,
                  a.ratio.size(), Median(a.ratio), Median(a.chamfer), a.iou.size(), Median(a.iou), Median(a.box_iou));
      medians.push_back({{"dataset", key.first}, {"category", key.second}, {"objects", a.n},
                         {"lidar_objects", a.ratio.size()}, {"median_count_ratio", Num(Median(a.ratio))},
                         {"median_chamfer_m", Num(Median(a.chamfer))}, {"camera_pairs", a.iou.size()},
                         {"median_iou", Num(Median(a.iou))},
                         {"median_box_projection_iou", Num(Median(a.box_iou))}});
    }
    nlohmann::json assets = nlohmann::json::object();  // category column -> asset id
    for (const BenchMesh& m : meshes) assets[m.label] = m.asset;
    nlohmann::json doc = {{"benchmark", "bench_realism"},
                          {"assets", assets},
                          {"medians", medians},
                          {"objects", objects}};
    fs::create_directories(out_path.parent_path());
    sd::WriteFileAtomic(out_path, doc.dump(2) + "\n");
    std::printf("\nwrote %s\n", out_path.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_realism: %s\n", e.what());
    return 1;
  }
  return 0;
}
