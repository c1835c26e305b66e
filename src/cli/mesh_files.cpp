#include "cli/mesh_files.h"

#include <algorithm>
#include <cctype>

#include "core/error.h"
#include "io/mesh_io.h"

namespace sd::cli {
namespace {

std::string LowerExtension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

}  // namespace

TriangleMesh ReadMeshFile(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) throw InputError(path, "no such file");
  const std::string ext = LowerExtension(path);
  TriangleMesh mesh = (ext == ".glb" || ext == ".gltf") ? LoadGlbZUp(path) : LoadMesh(path);
  if (mesh.NumFaces() == 0) throw InputError(path, "the mesh has no triangles");
  if (const std::string problem = mesh.Validate(); !problem.empty()) throw InputError(path, problem);
  return mesh;
}

void CheckMeshExtension(const std::filesystem::path& path) {
  const std::string ext = LowerExtension(path);
  if (ext != ".glb" && ext != ".ply") throw InputError(path, "output meshes are written as .glb or .ply");
}

void WriteMeshFile(const std::filesystem::path& path, const TriangleMesh& mesh) {
  CheckMeshExtension(path);
  if (LowerExtension(path) == ".glb") {
    SaveGlb(path, mesh);
  } else {
    SavePly(path, mesh);
  }
}

void RefuseExisting(const std::filesystem::path& path, bool overwrite) {
  if (!overwrite && std::filesystem::exists(path)) throw InputError(path, "already exists (pass --overwrite to replace it)");
}

}  // namespace sd::cli
