#include "cli/import.h"

#include "core/error.h"
#include "datasets/categories.h"
#include "io/files.h"
#include "io/mesh_io.h"

namespace sd::cli {

Asset ImportAsset(const ImportRequest& r) {
  RefuseOutputOverInputs(r.out, {r.mesh});
  const auto category = FindCategory(r.category);
  if (!category) throw InputError(r.mesh, "unknown category '" + r.category + "' (see `synthdrive categories`)");
  TriangleMesh mesh = LoadMesh(r.mesh);
  CanonicalizeOptions opt = r.canonical;
  if (r.height) opt.target_height = r.height;
  if (opt.scale <= 0 && !opt.target_height && !opt.target_size) opt.target_height = category->default_size.z();
  CanonicalizeResult c;
  try {
    c = Canonicalize(mesh, opt);
  } catch (const InputError& e) {
    throw InputError(r.mesh, e.what());
  }
  Asset a;
  a.mesh = std::move(c.mesh);
  if (a.mesh.normals.empty()) a.mesh.ComputeVertexNormals();
  a.info.id = r.id.empty() ? std::filesystem::absolute(r.out).lexically_normal().filename().string() : r.id;
  if (const std::string problem = AssetIdProblem(a.info.id); !problem.empty()) throw InputError(r.out, "--id: " + problem);
  a.info.name = r.name.empty() ? a.info.id : r.name;
  a.info.category = category->name;
  a.info.extent = c.extent;
  a.info.licence = r.licence;
  a.info.source = r.source.empty() ? r.mesh.filename().string() : r.source;
  a.info.attribution = r.attribution;
  a.info.stages = nlohmann::json::array({{{"stage", "import"},
                                          {"version", "synthdrive 0.1.0"},
                                          {"source_mesh", r.mesh.filename().string()},
                                          {"up", opt.up},
                                          {"front", opt.front},
                                          {"scale_to_metres", c.scale}}});
  if (c.frame) {  // estimated axes: say how, so a wrong guess can be traced and overridden with --up / --front
    a.info.stages[0]["up_method"] = c.frame->up_method;
    a.info.stages[0]["front_method"] = c.frame->front_method;
  }
  SaveAsset(a, r.out, r.overwrite);
  a.dir = r.out;
  return a;
}

}  // namespace sd::cli
