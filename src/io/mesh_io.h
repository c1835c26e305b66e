#pragma once
// Mesh files <-> TriangleMesh.
//  - Load: Wavefront OBJ (+ MTL, diffuse textures `map_Kd`, `Kd` colours), glTF 2.0 (.gltf + .bin/images,
//    and binary .glb): all mesh primitives of the default scene with node transforms applied, baseColor
//    factor + texture, TEXCOORD_0, NORMAL, COLOR_0. Axes and units are kept as in the file (glTF is y-up).
//  - Save: GLB (one primitive per material, embedded PNG textures) and PLY (binary little-endian, vertex
//    positions/normals/colours, faces).
// Errors: InputError naming the file (missing file, parse failure, missing texture, no triangles).
#include <filesystem>

#include "core/mesh.h"

namespace sd {

TriangleMesh LoadMesh(const std::filesystem::path& path);  // dispatches on extension
TriangleMesh LoadObj(const std::filesystem::path& path);
TriangleMesh LoadGltf(const std::filesystem::path& path);  // .gltf or .glb

// Our canonical frame is z-up; glTF is y-up. SaveGlb converts z-up -> y-up (x stays, z_up -> y, y -> -z)
// when `convert_z_up_to_gltf` is true, and LoadGltf(…, true) undoes it, so assets round-trip.
void SaveGlb(const std::filesystem::path& path, const TriangleMesh& mesh, bool convert_z_up_to_gltf = true);
TriangleMesh LoadGlbZUp(const std::filesystem::path& path);  // LoadGltf + y-up -> z-up
void SavePly(const std::filesystem::path& path, const TriangleMesh& mesh);

}  // namespace sd
