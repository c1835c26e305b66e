#pragma once
// Mesh files as the commands read and write them. GLB/glTF hold our assets: canonical z-up inside, glTF's
// y-up on disk, so they are converted on the way in and out; OBJ is taken as it is (PLY is written, not read).
#include <filesystem>

#include "core/mesh.h"

namespace sd::cli {

TriangleMesh ReadMeshFile(const std::filesystem::path& path);
// Writes atomically by extension (.glb, .ply; .obj is refused: we do not write OBJ).
void WriteMeshFile(const std::filesystem::path& path, const TriangleMesh& mesh);
// InputError when the extension is not one WriteMeshFile writes.
void CheckMeshExtension(const std::filesystem::path& path);
// InputError when `path` exists and `overwrite` is false (nothing the user has is replaced by accident).
void RefuseExisting(const std::filesystem::path& path, bool overwrite);

}  // namespace sd::cli
