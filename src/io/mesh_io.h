#pragma once
// Mesh files <-> TriangleMesh.
//  - Load: Wavefront OBJ (+ MTL, diffuse textures `map_Kd`, `Kd` colours), glTF 2.0 (.gltf + .bin/images,
//    and binary .glb): all mesh primitives of the default scene with node transforms applied, baseColor
//    factor + texture, TEXCOORD_0, NORMAL, COLOR_0. Axes and units are kept as in the file (glTF is y-up).
//  - Save: GLB (one primitive per material, embedded PNG textures) and PLY (binary little-endian, vertex
//    positions/normals/colours, faces).
//    OBJ: faces triangulated as fans, one vertex per distinct (v, vt, vn) triple, `Kd`/`d` taken as linear
//    RGBA, vt flipped to v = 1 - v; faces without `usemtl` get an appended "default" material.
//    glTF: material i of the file is material i of the mesh (a "default" one is appended for primitives
//    without a material); metallic/roughness are the factors only (metallicRoughnessTexture, normal and
//    occlusion maps are not read). TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN primitives are read.
// Errors: InputError naming the file (missing file, parse failure, missing MTL or texture file — named too —,
// no triangles, out-of-range indices).
#include <filesystem>

#include "core/mesh.h"

namespace sd {

TriangleMesh LoadMesh(const std::filesystem::path& path);  // dispatches on extension
TriangleMesh LoadObj(const std::filesystem::path& path);
TriangleMesh LoadGltf(const std::filesystem::path& path);  // .gltf or .glb

// Our canonical frame is z-up; glTF is y-up. SaveGlb converts z-up -> y-up, (x, y, z) -> (x, z, -y), when
// `convert_z_up_to_gltf` is true, and LoadGlbZUp undoes it, so assets round-trip.
// SaveGlb writes one primitive per used material, each with its own vertex subset in the mesh's vertex
// order (a single-material mesh round-trips vertex for vertex; shared vertices are duplicated otherwise),
// all materials in order (an empty list becomes one default material), textures as PNG, normals re-normalised,
// vertex colours as float COLOR_0. Material indices survive a round trip.
// SavePly: float x y z [nx ny nz] [uchar red green blue alpha: sRGB-encoded colour, linear alpha],
// faces as "list uchar int vertex_indices".
void SaveGlb(const std::filesystem::path& path, const TriangleMesh& mesh, bool convert_z_up_to_gltf = true);
TriangleMesh LoadGlbZUp(const std::filesystem::path& path);  // LoadGltf + y-up -> z-up
void SavePly(const std::filesystem::path& path, const TriangleMesh& mesh);

}  // namespace sd
