#include "io/mesh_io.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <cstring>
#include <functional>
#include <map>
#include <string_view>
#include <tuple>
#include <unordered_map>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <tiny_gltf.h>
#include <tiny_obj_loader.h>

#include "core/error.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"

namespace sd {
namespace fs = std::filesystem;

namespace {

std::string LowerExtension(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

void RequireFile(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "file not found");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, expected a mesh file");
  // tinyobjloader and tinygltf open the file themselves: a FIFO would block them forever.
  if (!fs::is_regular_file(path, ec)) throw InputError(path, "is not a regular file (a FIFO, device or socket): not read as data");
}

// Pads every optional attribute that is in use to one entry per vertex (neutral values).
void PadAttributes(TriangleMesh& mesh) {
  const size_t nv = mesh.positions.size();
  if (!mesh.uvs.empty()) mesh.uvs.resize(nv, Eigen::Vector2f::Zero());
  if (!mesh.normals.empty()) mesh.normals.resize(nv, Eigen::Vector3f::UnitZ());
  if (!mesh.colors.empty()) mesh.colors.resize(nv, Eigen::Vector4f::Ones());
}

// Converts between our z-up frame and glTF's y-up frame: (x, y, z)_zup -> (x, z, -y)_gltf and back.
Eigen::Vector3f ZUpToGltf(const Eigen::Vector3f& p) { return {p.x(), p.z(), -p.y()}; }
Eigen::Vector3f GltfToZUp(const Eigen::Vector3f& p) { return {p.x(), -p.z(), p.y()}; }

Material DefaultMaterial() {
  Material m;
  m.name = "default";
  return m;
}

// ---------------------------------------------------------------------------------------------------------
// OBJ

// tinyobjloader reads a number it cannot parse ("v nan 0 0", "v 1e999 0 0", "v x y z") as 0 and says nothing: a
// vertex silently moved to the origin. Every number of the geometry lines (v, vt, vn) must parse whole and be finite.
void CheckObjNumbers(const fs::path& path) {
  const std::string text = ReadFileToString(path);
  size_t line_no = 0;
  for (size_t begin = 0; begin < text.size();) {
    size_t end = text.find('\n', begin);
    if (end == std::string::npos) end = text.size();
    ++line_no;
    const std::string_view line(text.data() + begin, end - begin);
    begin = end + 1;
    if (!(line.starts_with("v ") || line.starts_with("v\t") || line.starts_with("vt ") || line.starts_with("vn ")))
      continue;
    std::string numbers(line.substr(line.find_first_of(" \t")));
    const char* p = numbers.c_str();
    while (true) {
      while (*p == ' ' || *p == '\t' || *p == '\r') ++p;
      if (*p == '\0' || *p == '#') break;
      char* after = nullptr;
      const double value = std::strtod(p, &after);  // overflow gives inf; underflow a harmless 0
      const bool whole = after != p && (*after == '\0' || *after == ' ' || *after == '\t' || *after == '\r');
      if (!whole || !std::isfinite(value)) {
        const char* token_end = p;
        while (*token_end && *token_end != ' ' && *token_end != '\t' && *token_end != '\r') ++token_end;
        throw InputError(path, Msg() << "line " << line_no << ": '" << std::string(p, token_end)
                                     << "' is not a finite number (" << line.substr(0, line.find_first_of(" \t")) << " line)");
      }
      p = after;
    }
  }
}

}  // namespace

TriangleMesh LoadObj(const fs::path& path) {
  RequireFile(path);
  CheckObjNumbers(path);
  tinyobj::attrib_t attrib;
  std::vector<tinyobj::shape_t> shapes;
  std::vector<tinyobj::material_t> obj_materials;
  std::string warn, err;
  const fs::path dir = path.parent_path();
  const std::string mtl_dir = dir.empty() ? std::string("./") : dir.string() + "/";
  // default_vcols_fallback = false: colours only when every `v` line has them.
  const bool ok = tinyobj::LoadObj(&attrib, &shapes, &obj_materials, &warn, &err, path.c_str(), mtl_dir.c_str(),
                                   /*triangulate=*/true, /*default_vcols_fallback=*/false);
  if (!ok) throw InputError(path, "cannot parse OBJ: " + (err.empty() ? warn : err));
  if (const auto pos = warn.find("Material file ["); pos != std::string::npos)
    throw InputError(path, "material library not found: " + warn.substr(pos, warn.find('\n', pos) - pos));

  TriangleMesh mesh;
  // Materials: MTL order, then a default one for faces without `usemtl` (if any).
  std::map<fs::path, std::shared_ptr<const ImageU8>> textures;
  for (const auto& m : obj_materials) {
    Material mat;
    mat.name = m.name;
    // OBJ Kd is treated as linear (renderers multiply it into lighting unconverted).
    mat.base_color_factor = Eigen::Vector4f(m.diffuse[0], m.diffuse[1], m.diffuse[2], m.dissolve);
    mat.metallic = m.metallic;
    mat.roughness = m.roughness > 0 ? m.roughness : 1.0f;  // tinyobj reports 0 when Pr is absent
    if (!m.diffuse_texname.empty()) {
      const fs::path tex = dir / m.diffuse_texname;
      auto it = textures.find(tex);
      if (it == textures.end()) {
        std::error_code ec;
        if (!fs::exists(tex, ec))
          throw InputError(path, Msg() << "texture file '" << m.diffuse_texname << "' of material '" << m.name
                                       << "' not found (looked for " << tex.string() << ")");
        it = textures.emplace(tex, std::make_shared<const ImageU8>(ReadImage(tex))).first;
      }
      mat.base_color_texture = it->second;
      mat.base_color_texture_name = tex.filename().string();
    }
    mesh.materials.push_back(std::move(mat));
  }

  const bool has_colors = !attrib.colors.empty() && attrib.colors.size() == attrib.vertices.size();
  bool any_uv = false, any_normal = false;
  for (const auto& s : shapes)
    for (const auto& idx : s.mesh.indices) {
      any_uv |= idx.texcoord_index >= 0;
      any_normal |= idx.normal_index >= 0;
    }

  // OBJ indexes position, uv and normal separately; one output vertex per distinct (v, vt, vn) triple.
  std::map<std::tuple<int, int, int>, int> vertex_of;
  std::vector<char> needs_normal;
  int default_material = -1;
  for (const auto& s : shapes) {
    const auto& m = s.mesh;
    SD_CHECK(m.indices.size() == 3 * m.num_face_vertices.size(), << "tinyobj did not triangulate");
    for (size_t f = 0; f < m.num_face_vertices.size(); ++f) {
      Eigen::Vector3i face;
      for (int k = 0; k < 3; ++k) {
        const tinyobj::index_t idx = m.indices[3 * f + k];
        const auto key = std::make_tuple(idx.vertex_index, idx.texcoord_index, idx.normal_index);
        auto [it, inserted] = vertex_of.emplace(key, static_cast<int>(mesh.positions.size()));
        if (inserted) {
          const int v = idx.vertex_index;
          if (v < 0 || 3 * static_cast<size_t>(v) + 2 >= attrib.vertices.size())
            throw InputError(path, Msg() << "face references a missing vertex " << v + 1);
          mesh.positions.emplace_back(attrib.vertices[3 * v], attrib.vertices[3 * v + 1], attrib.vertices[3 * v + 2]);
          if (has_colors)
            mesh.colors.emplace_back(attrib.colors[3 * v], attrib.colors[3 * v + 1], attrib.colors[3 * v + 2], 1.0f);
          if (any_uv) {
            const int t = idx.texcoord_index;
            if (t >= 0 && 2 * static_cast<size_t>(t) + 1 < attrib.texcoords.size())
              mesh.uvs.emplace_back(attrib.texcoords[2 * t], 1.0f - attrib.texcoords[2 * t + 1]);  // OBJ v is up
            else
              mesh.uvs.emplace_back(0.0f, 0.0f);
          }
          if (any_normal) {
            const int n = idx.normal_index;
            const bool have = n >= 0 && 3 * static_cast<size_t>(n) + 2 < attrib.normals.size();
            Eigen::Vector3f nn = Eigen::Vector3f::Zero();
            if (have) nn = Eigen::Vector3f(attrib.normals[3 * n], attrib.normals[3 * n + 1], attrib.normals[3 * n + 2]);
            const float len = nn.norm();
            mesh.normals.push_back(len > 0 ? Eigen::Vector3f(nn / len) : nn);
            needs_normal.push_back(!(len > 0));
          }
        }
        face[k] = it->second;
      }
      mesh.faces.push_back(face);
      int mat = f < m.material_ids.size() ? m.material_ids[f] : -1;
      if (mat < 0 || static_cast<size_t>(mat) >= obj_materials.size()) {
        if (default_material < 0) {
          default_material = static_cast<int>(mesh.materials.size());
          mesh.materials.push_back(DefaultMaterial());
        }
        mat = default_material;
      }
      mesh.face_material.push_back(mat);
    }
  }
  if (mesh.faces.empty()) throw InputError(path, "no triangles (no `f` lines with 3 or more vertices)");
  // Vertices that came without a normal get the area-weighted normal of their faces.
  if (any_normal && std::find(needs_normal.begin(), needs_normal.end(), 1) != needs_normal.end()) {
    std::vector<Eigen::Vector3f> acc(mesh.positions.size(), Eigen::Vector3f::Zero());
    for (const auto& f : mesh.faces) {
      const Eigen::Vector3f n = (mesh.positions[f[1]] - mesh.positions[f[0]]).cross(mesh.positions[f[2]] - mesh.positions[f[0]]);
      for (int k = 0; k < 3; ++k) acc[f[k]] += n;
    }
    for (size_t i = 0; i < mesh.normals.size(); ++i)
      if (needs_normal[i]) mesh.normals[i] = acc[i].norm() > 0 ? Eigen::Vector3f(acc[i].normalized()) : Eigen::Vector3f::UnitZ();
  }
  if (const std::string bad = mesh.Validate(); !bad.empty()) throw InputError(path, bad);
  return mesh;
}

// ---------------------------------------------------------------------------------------------------------
// glTF

namespace {

// tinygltf calls this with the encoded bytes of every image. We keep the bytes undecoded and decode them
// ourselves afterwards, so a bad image gives our error naming the texture. width = -1 marks "encoded".
bool KeepEncodedImage(tinygltf::Image* image, const int /*image_idx*/, std::string* /*err*/, std::string* /*warn*/,
                      int /*req_width*/, int /*req_height*/, const unsigned char* bytes, int size, void* /*user*/) {
  image->image.assign(bytes, bytes + size);
  image->width = image->height = image->component = -1;
  return true;
}

class GltfReader {
 public:
  GltfReader(const fs::path& path, const tinygltf::Model& model) : path_(path), model_(model) {}

  TriangleMesh Read() {
    for (size_t i = 0; i < model_.materials.size(); ++i) mesh_.materials.push_back(ReadMaterial(static_cast<int>(i)));
    if (!model_.scenes.empty()) {
      const int s = model_.defaultScene >= 0 && static_cast<size_t>(model_.defaultScene) < model_.scenes.size()
                        ? model_.defaultScene : 0;
      for (int n : model_.scenes[s].nodes) VisitNode(n, Eigen::Matrix4d::Identity(), 0);
    } else {
      // No scene: the spec leaves rendering undefined; take every mesh untransformed.
      for (size_t m = 0; m < model_.meshes.size(); ++m) AddMesh(static_cast<int>(m), Eigen::Matrix4d::Identity());
    }
    if (mesh_.faces.empty()) throw InputError(path_, "no triangles in the default scene");
    PadAttributes(mesh_);
    if (const std::string bad = mesh_.Validate(); !bad.empty()) throw InputError(path_, bad);
    return std::move(mesh_);
  }

 private:
  static Eigen::Matrix4d NodeMatrix(const tinygltf::Node& node) {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    if (node.matrix.size() == 16) {
      for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) m(r, c) = node.matrix[4 * c + r];  // column-major
      return m;
    }
    // T * R * S
    if (node.scale.size() == 3) m = Eigen::Vector4d(node.scale[0], node.scale[1], node.scale[2], 1.0).asDiagonal();
    if (node.rotation.size() == 4) {
      const Eigen::Quaterniond q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);  // xyzw
      Eigen::Matrix4d r = Eigen::Matrix4d::Identity();
      r.topLeftCorner<3, 3>() = q.normalized().toRotationMatrix();
      m = r * m;
    }
    if (node.translation.size() == 3)
      m.topRightCorner<3, 1>() += Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]);
    return m;
  }

  void VisitNode(int index, const Eigen::Matrix4d& parent, int depth) {
    if (index < 0 || static_cast<size_t>(index) >= model_.nodes.size())
      throw InputError(path_, Msg() << "scene references missing node " << index);
    if (depth > 256) throw InputError(path_, "node hierarchy deeper than 256 levels (a cycle?)");
    const tinygltf::Node& node = model_.nodes[index];
    const Eigen::Matrix4d world = parent * NodeMatrix(node);
    if (node.mesh >= 0) AddMesh(node.mesh, world);
    for (int c : node.children) VisitNode(c, world, depth + 1);
  }

  // Reads element `i` of an accessor as floats (normalised integers mapped to 0..1 / -1..1 as the spec says).
  void ReadElement(const tinygltf::Accessor& acc, size_t i, float* out, int want) const {
    const int nc = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type));
    const int cs = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(acc.componentType));
    if (acc.bufferView < 0) {  // all zeros by the spec
      std::fill(out, out + want, 0.0f);
      return;
    }
    const auto& view = model_.bufferViews[acc.bufferView];
    const auto& buffer = model_.buffers[view.buffer];
    const size_t stride = view.byteStride ? view.byteStride : static_cast<size_t>(nc * cs);
    const size_t start = view.byteOffset + acc.byteOffset + i * stride;
    const unsigned char* p = buffer.data.data() + start;
    for (int c = 0; c < want; ++c) {
      if (c >= nc) {
        out[c] = c == 3 ? 1.0f : 0.0f;
        continue;
      }
      const unsigned char* q = p + c * cs;
      float v = 0;
      switch (acc.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: std::memcpy(&v, q, 4); break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: v = acc.normalized ? *q / 255.0f : *q; break;
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
          const auto s = static_cast<int8_t>(*q);
          v = acc.normalized ? std::max(s / 127.0f, -1.0f) : s;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          uint16_t s;
          std::memcpy(&s, q, 2);
          v = acc.normalized ? s / 65535.0f : s;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
          int16_t s;
          std::memcpy(&s, q, 2);
          v = acc.normalized ? std::max(s / 32767.0f, -1.0f) : s;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
          uint32_t s;
          std::memcpy(&s, q, 4);
          v = static_cast<float>(s);
          break;
        }
        default: throw InputError(path_, Msg() << "accessor has unsupported component type " << acc.componentType);
      }
      out[c] = v;
    }
  }

  const tinygltf::Accessor& CheckedAccessor(int index, const char* what) const {
    if (index < 0 || static_cast<size_t>(index) >= model_.accessors.size())
      throw InputError(path_, Msg() << what << " references missing accessor " << index);
    const auto& acc = model_.accessors[index];
    if (acc.sparse.isSparse) throw InputError(path_, Msg() << what << ": sparse accessors are not supported");
    if (acc.bufferView >= 0) {
      if (static_cast<size_t>(acc.bufferView) >= model_.bufferViews.size())
        throw InputError(path_, Msg() << what << " references missing bufferView " << acc.bufferView);
      const auto& view = model_.bufferViews[acc.bufferView];
      if (view.buffer < 0 || static_cast<size_t>(view.buffer) >= model_.buffers.size())
        throw InputError(path_, Msg() << what << " references missing buffer " << view.buffer);
      const int nc = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type));
      const int cs = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(acc.componentType));
      if (nc <= 0 || cs <= 0) throw InputError(path_, Msg() << what << ": bad accessor type");
      const size_t stride = view.byteStride ? view.byteStride : static_cast<size_t>(nc * cs);
      const size_t need = acc.count == 0 ? 0 : acc.byteOffset + (acc.count - 1) * stride + static_cast<size_t>(nc * cs);
      if (view.byteOffset + need > model_.buffers[view.buffer].data.size() || need > view.byteLength)
        throw InputError(path_, Msg() << what << " reads past the end of its buffer");
    }
    return acc;
  }

  void AddMesh(int mesh_index, const Eigen::Matrix4d& world) {
    if (mesh_index < 0 || static_cast<size_t>(mesh_index) >= model_.meshes.size())
      throw InputError(path_, Msg() << "node references missing mesh " << mesh_index);
    const Eigen::Matrix3d linear = world.topLeftCorner<3, 3>();
    const Eigen::Matrix3f normal_matrix = linear.inverse().transpose().cast<float>();
    const bool mirrored = linear.determinant() < 0;  // a reflection flips the winding
    for (const auto& prim : model_.meshes[mesh_index].primitives) {
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN)
        continue;  // points and lines carry no surface
      const auto pos_it = prim.attributes.find("POSITION");
      if (pos_it == prim.attributes.end()) continue;
      const auto& pos = CheckedAccessor(pos_it->second, "POSITION");
      if (pos.type != TINYGLTF_TYPE_VEC3) throw InputError(path_, "POSITION accessor is not VEC3");
      const size_t base = mesh_.positions.size();
      const size_t n = pos.count;
      float buf[4];
      for (size_t i = 0; i < n; ++i) {
        ReadElement(pos, i, buf, 3);
        const Eigen::Vector4d p = world * Eigen::Vector4d(buf[0], buf[1], buf[2], 1.0);
        mesh_.positions.push_back(p.head<3>().cast<float>());
      }
      if (auto it = prim.attributes.find("NORMAL"); it != prim.attributes.end()) {
        const auto& acc = CheckedAccessor(it->second, "NORMAL");
        if (acc.count != n) throw InputError(path_, "NORMAL count differs from POSITION count");
        mesh_.normals.resize(base, Eigen::Vector3f::UnitZ());
        for (size_t i = 0; i < n; ++i) {
          ReadElement(acc, i, buf, 3);
          const Eigen::Vector3f nn = normal_matrix * Eigen::Vector3f(buf[0], buf[1], buf[2]);
          mesh_.normals.push_back(nn.norm() > 0 ? Eigen::Vector3f(nn.normalized()) : Eigen::Vector3f::UnitZ());
        }
      } else if (!mesh_.normals.empty()) {
        mesh_.normals.resize(base + n, Eigen::Vector3f::UnitZ());
      }
      if (auto it = prim.attributes.find("TEXCOORD_0"); it != prim.attributes.end()) {
        const auto& acc = CheckedAccessor(it->second, "TEXCOORD_0");
        if (acc.count != n) throw InputError(path_, "TEXCOORD_0 count differs from POSITION count");
        mesh_.uvs.resize(base, Eigen::Vector2f::Zero());
        for (size_t i = 0; i < n; ++i) {
          ReadElement(acc, i, buf, 2);
          mesh_.uvs.emplace_back(buf[0], buf[1]);
        }
      }
      if (auto it = prim.attributes.find("COLOR_0"); it != prim.attributes.end()) {
        const auto& acc = CheckedAccessor(it->second, "COLOR_0");
        if (acc.count != n) throw InputError(path_, "COLOR_0 count differs from POSITION count");
        mesh_.colors.resize(base, Eigen::Vector4f::Ones());
        for (size_t i = 0; i < n; ++i) {
          ReadElement(acc, i, buf, 4);  // VEC3 gets alpha 1
          mesh_.colors.emplace_back(buf[0], buf[1], buf[2], buf[3]);
        }
      }
      // Attributes this primitive lacks but earlier ones had are padded by the next primitive or at the end.

      std::vector<uint32_t> idx;
      if (prim.indices >= 0) {
        const auto& acc = CheckedAccessor(prim.indices, "indices");
        if (acc.type != TINYGLTF_TYPE_SCALAR) throw InputError(path_, "index accessor is not SCALAR");
        idx.resize(acc.count);
        for (size_t i = 0; i < acc.count; ++i) {
          ReadElement(acc, i, buf, 1);
          // Checked as a double: a float or negative "index" (a malformed accessor) must not reach the cast.
          if (!(buf[0] >= 0 && buf[0] < static_cast<double>(n)))
            throw InputError(path_, Msg() << "index " << buf[0] << " out of range (" << n << " vertices)");
          idx[i] = static_cast<uint32_t>(buf[0]);
        }
      } else {
        idx.resize(n);
        for (size_t i = 0; i < n; ++i) idx[i] = static_cast<uint32_t>(i);
      }
      int material = prim.material;
      if (material < 0 || static_cast<size_t>(material) >= model_.materials.size()) material = DefaultMaterial();
      auto emit = [&](uint32_t a, uint32_t b, uint32_t c) {
        if (a == b || b == c || a == c) return;
        if (mirrored) std::swap(b, c);
        mesh_.faces.emplace_back(static_cast<int>(base + a), static_cast<int>(base + b), static_cast<int>(base + c));
        mesh_.face_material.push_back(material);
      };
      if (mode == TINYGLTF_MODE_TRIANGLES) {
        for (size_t i = 0; i + 2 < idx.size(); i += 3) emit(idx[i], idx[i + 1], idx[i + 2]);
      } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
        for (size_t i = 0; i + 2 < idx.size(); ++i)
          i % 2 ? emit(idx[i + 1], idx[i], idx[i + 2]) : emit(idx[i], idx[i + 1], idx[i + 2]);
      } else {
        for (size_t i = 1; i + 1 < idx.size(); ++i) emit(idx[0], idx[i], idx[i + 1]);
      }
    }
  }

  int DefaultMaterial() {
    if (default_material_ < 0) {
      default_material_ = static_cast<int>(mesh_.materials.size());
      mesh_.materials.push_back(sd::DefaultMaterial());
    }
    return default_material_;
  }

  Material ReadMaterial(int index) {
    const auto& gm = model_.materials[index];
    const auto& pbr = gm.pbrMetallicRoughness;
    Material mat;
    mat.name = gm.name;
    if (pbr.baseColorFactor.size() == 4)
      mat.base_color_factor = Eigen::Vector4d(pbr.baseColorFactor[0], pbr.baseColorFactor[1], pbr.baseColorFactor[2],
                                              pbr.baseColorFactor[3]).cast<float>();
    mat.metallic = static_cast<float>(pbr.metallicFactor);
    mat.roughness = static_cast<float>(pbr.roughnessFactor);
    const int tex = pbr.baseColorTexture.index;
    if (tex >= 0) {
      if (static_cast<size_t>(tex) >= model_.textures.size())
        throw InputError(path_, Msg() << "material '" << gm.name << "' references missing texture " << tex);
      const int source = model_.textures[tex].source;
      if (source < 0 || static_cast<size_t>(source) >= model_.images.size())
        throw InputError(path_, Msg() << "texture " << tex << " has no image source");
      std::tie(mat.base_color_texture, mat.base_color_texture_name) = Texture(source);
    }
    return mat;
  }

  std::pair<std::shared_ptr<const ImageU8>, std::string> Texture(int source) {
    if (auto it = textures_.find(source); it != textures_.end()) return it->second;
    const tinygltf::Image& gi = model_.images[source];
    const bool external = !gi.uri.empty() && gi.uri.rfind("data:", 0) != 0;
    const fs::path file = external ? path_.parent_path() / gi.uri : fs::path();
    std::string name = external ? file.filename().string() : gi.name;
    if (name.empty()) name = Msg() << "image" << source << (gi.mimeType == "image/jpeg" ? ".jpg" : ".png");
    std::shared_ptr<const ImageU8> img;
    if (gi.image.empty()) {
      // tinygltf only warns when an external image is missing; for us that is an error naming the file.
      if (external) {
        std::error_code ec;
        if (!fs::exists(file, ec)) throw InputError(path_, "texture file '" + gi.uri + "' not found (looked for " + file.string() + ")");
        img = std::make_shared<const ImageU8>(ReadImage(file));
      } else {
        throw InputError(path_, Msg() << "image " << source << " has no data");
      }
    } else if (gi.width == -1) {  // encoded bytes kept by KeepEncodedImage
      // Through DecodeImage, which checks what Debian's stb_image 2.27 would overflow on (a fuzzed glTF reached
      // stb's Huffman-table overrun through an embedded JPEG when this called stb itself).
      const std::string_view bytes(reinterpret_cast<const char*>(gi.image.data()), gi.image.size());
      img = std::make_shared<const ImageU8>(
          DecodeImage(bytes, Msg() << (external ? file : path_).string() << ": image " << source << " ('" << name << "')"));
    } else {
      SD_CHECK(gi.bits == 8 && gi.component > 0, << "unexpected decoded image layout");
      ImageU8 out(gi.width, gi.height, gi.component);
      std::copy(gi.image.begin(), gi.image.end(), out.data());
      img = std::make_shared<const ImageU8>(std::move(out));
    }
    return textures_[source] = {img, name};
  }

  const fs::path& path_;
  const tinygltf::Model& model_;
  TriangleMesh mesh_;
  int default_material_ = -1;
  std::map<int, std::pair<std::shared_ptr<const ImageU8>, std::string>> textures_;
};

}  // namespace

TriangleMesh LoadGltf(const fs::path& path) {
  RequireFile(path);
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(KeepEncodedImage, nullptr);
  tinygltf::Model model;
  std::string err, warn;
  bool ok = false;
  // GLB is recognised by its magic, not the extension. tinygltf parses the JSON recursively: its nesting is
  // bounded first (a glTF whose extras held 100,000-deep lists overflowed the stack).
  const std::string bytes = ReadFileToString(path);
  if (bytes.size() > std::numeric_limits<unsigned int>::max())
    throw InputError(path, Msg() << bytes.size() << " bytes: larger than a glTF file can be (4 GiB)");
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  std::string_view json_text = bytes;
  if (binary) {
    // Header (12 bytes), then the JSON chunk's length and type (8 bytes) and its text.
    uint32_t json_length = 0;
    if (bytes.size() >= 20) std::memcpy(&json_length, bytes.data() + 12, 4);
    json_text = std::string_view(bytes).substr(std::min<size_t>(20, bytes.size()), json_length);
  }
  CheckJsonNesting(json_text, path);
  const fs::path base_dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  if (binary)
    ok = loader.LoadBinaryFromMemory(&model, &err, &warn, reinterpret_cast<const unsigned char*>(bytes.data()),
                                     static_cast<unsigned int>(bytes.size()), base_dir.string());
  else
    ok = loader.LoadASCIIFromString(&model, &err, &warn, bytes.data(), static_cast<unsigned int>(bytes.size()), base_dir.string());
  if (!ok) {
    std::string why = err.empty() ? warn : err;
    while (!why.empty() && (why.back() == '\n' || why.back() == ' ')) why.pop_back();
    throw InputError(path, "cannot parse glTF: " + why);
  }
  TriangleMesh mesh = GltfReader(path, model).Read();
  // Binary accessors hold any float: a NaN or infinite position would reach the ray tracer as a NaN bound.
  for (size_t i = 0; i < mesh.positions.size(); ++i)
    if (!mesh.positions[i].allFinite())
      throw InputError(path, Msg() << "vertex " << i << " of the mesh is not finite (" << mesh.positions[i].transpose() << ")");
  return mesh;
}

TriangleMesh LoadMesh(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  if (ext == ".obj") return LoadObj(path);
  if (ext == ".gltf" || ext == ".glb") return LoadGltf(path);
  throw InputError(path, "unsupported mesh extension '" + ext + "' (use .obj, .gltf or .glb)");
}

TriangleMesh LoadGlbZUp(const fs::path& path) {
  TriangleMesh mesh = LoadGltf(path);
  for (auto& p : mesh.positions) p = GltfToZUp(p);
  for (auto& n : mesh.normals) n = GltfToZUp(n);
  return mesh;
}

// ---------------------------------------------------------------------------------------------------------
// GLB writer. Hand-written rather than through tinygltf's writer so the output is byte-deterministic and
// the texture bytes are exactly our PNG encoding.

namespace {

class GlbBuilder {
 public:
  // Appends bytes to the binary chunk (4-byte aligned) and returns the bufferView index.
  int AddView(const void* data, size_t size, int target) {
    while (bin_.size() % 4) bin_.push_back('\0');
    nlohmann::json view = {{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", size}};
    if (target) view["target"] = target;
    bin_.append(static_cast<const char*>(data), size);
    views_.push_back(view);
    return static_cast<int>(views_.size()) - 1;
  }
  int AddAccessor(const void* data, size_t count, int components, int component_type, const char* type, int target,
                  const nlohmann::json& extra = nlohmann::json::object()) {
    const size_t comp_size = component_type == 5126 || component_type == 5125 ? 4 : 0;
    SD_CHECK(comp_size == 4);
    const int view = AddView(data, count * components * comp_size, target);
    nlohmann::json acc = {{"bufferView", view}, {"componentType", component_type}, {"count", count}, {"type", type}};
    acc.update(extra);
    accessors_.push_back(acc);
    return static_cast<int>(accessors_.size()) - 1;
  }
  std::string Finish(nlohmann::json gltf) {
    while (bin_.size() % 4) bin_.push_back('\0');
    gltf["accessors"] = accessors_;
    gltf["bufferViews"] = views_;
    gltf["buffers"] = nlohmann::json::array({{{"byteLength", bin_.size()}}});
    std::string json = gltf.dump();
    while (json.size() % 4) json.push_back(' ');
    std::string out;
    auto u32 = [&out](uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
    const uint32_t total = 12 + 8 + static_cast<uint32_t>(json.size()) + 8 + static_cast<uint32_t>(bin_.size());
    u32(0x46546C67);  // "glTF"
    u32(2);
    u32(total);
    u32(static_cast<uint32_t>(json.size()));
    u32(0x4E4F534A);  // "JSON"
    out += json;
    u32(static_cast<uint32_t>(bin_.size()));
    u32(0x004E4942);  // "BIN\0"
    out += bin_;
    return out;
  }

 private:
  std::string bin_;
  nlohmann::json views_ = nlohmann::json::array(), accessors_ = nlohmann::json::array();
};

}  // namespace

void SaveGlb(const fs::path& path, const TriangleMesh& mesh, bool convert_z_up_to_gltf) {
  SD_CHECK(mesh.Validate().empty(), << "SaveGlb of an inconsistent mesh: " << mesh.Validate());
  GlbBuilder glb;
  nlohmann::json gltf = {{"asset", {{"version", "2.0"}, {"generator", "synthdrive"}}}};

  std::vector<Material> materials = mesh.materials;
  if (materials.empty()) materials.push_back(DefaultMaterial());
  nlohmann::json jmats = nlohmann::json::array(), jtextures = nlohmann::json::array(), jimages = nlohmann::json::array();
  std::map<const ImageU8*, int> texture_of;
  for (const auto& m : materials) {
    const auto& f = m.base_color_factor;
    nlohmann::json pbr = {{"baseColorFactor", {f[0], f[1], f[2], f[3]}},
                          {"metallicFactor", m.metallic},
                          {"roughnessFactor", m.roughness}};
    if (m.base_color_texture) {
      auto [it, inserted] = texture_of.emplace(m.base_color_texture.get(), static_cast<int>(jtextures.size()));
      if (inserted) {
        const std::string png = EncodeImage(*m.base_color_texture, "png");
        const int view = glb.AddView(png.data(), png.size(), 0);
        nlohmann::json image = {{"bufferView", view}, {"mimeType", "image/png"}};
        if (!m.base_color_texture_name.empty()) image["name"] = m.base_color_texture_name;
        jimages.push_back(image);
        jtextures.push_back({{"source", jimages.size() - 1}, {"sampler", 0}});
      }
      pbr["baseColorTexture"] = {{"index", it->second}};
    }
    nlohmann::json jm = {{"pbrMetallicRoughness", pbr}};
    if (!m.name.empty()) jm["name"] = m.name;
    if (f[3] < 1.0f) jm["alphaMode"] = "BLEND";
    jmats.push_back(jm);
  }

  // One primitive per used material, each with its own compacted vertex set (kept in the original order,
  // so a single-material mesh round-trips vertex for vertex).
  nlohmann::json prims = nlohmann::json::array();
  for (int mat = 0; mat < static_cast<int>(materials.size()); ++mat) {
    std::vector<int> remap(mesh.NumVertices(), -1);
    std::vector<size_t> faces;
    for (size_t f = 0; f < mesh.NumFaces(); ++f)
      if (mesh.MaterialOf(f) == mat) {
        faces.push_back(f);
        for (int k = 0; k < 3; ++k) remap[mesh.faces[f][k]] = 0;
      }
    if (faces.empty()) continue;
    std::vector<float> pos, nrm, uv, col;
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max()), hi = -lo;
    int next = 0;
    for (size_t v = 0; v < mesh.NumVertices(); ++v) {
      if (remap[v] < 0) continue;
      remap[v] = next++;
      const Eigen::Vector3f p = convert_z_up_to_gltf ? ZUpToGltf(mesh.positions[v]) : mesh.positions[v];
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
      pos.insert(pos.end(), {p.x(), p.y(), p.z()});
      if (!mesh.normals.empty()) {
        Eigen::Vector3f n = convert_z_up_to_gltf ? ZUpToGltf(mesh.normals[v]) : mesh.normals[v];
        n = n.norm() > 0 ? Eigen::Vector3f(n.normalized()) : Eigen::Vector3f::UnitY();  // glTF requires unit normals
        nrm.insert(nrm.end(), {n.x(), n.y(), n.z()});
      }
      if (!mesh.uvs.empty()) uv.insert(uv.end(), {mesh.uvs[v].x(), mesh.uvs[v].y()});
      if (!mesh.colors.empty())
        for (int c = 0; c < 4; ++c) col.push_back(mesh.colors[v][c]);
    }
    std::vector<uint32_t> idx;
    for (size_t f : faces)
      for (int k = 0; k < 3; ++k) idx.push_back(static_cast<uint32_t>(remap[mesh.faces[f][k]]));
    constexpr int kFloat = 5126, kUint = 5125, kArray = 34962, kElements = 34963;
    nlohmann::json attrs;
    attrs["POSITION"] = glb.AddAccessor(pos.data(), next, 3, kFloat, "VEC3", kArray,
                                        {{"min", {lo.x(), lo.y(), lo.z()}}, {"max", {hi.x(), hi.y(), hi.z()}}});
    if (!nrm.empty()) attrs["NORMAL"] = glb.AddAccessor(nrm.data(), next, 3, kFloat, "VEC3", kArray);
    if (!uv.empty()) attrs["TEXCOORD_0"] = glb.AddAccessor(uv.data(), next, 2, kFloat, "VEC2", kArray);
    if (!col.empty()) attrs["COLOR_0"] = glb.AddAccessor(col.data(), next, 4, kFloat, "VEC4", kArray);
    const int indices = glb.AddAccessor(idx.data(), idx.size(), 1, kUint, "SCALAR", kElements);
    prims.push_back({{"attributes", attrs}, {"indices", indices}, {"material", mat}, {"mode", 4}});
  }
  SD_CHECK(!prims.empty(), << "SaveGlb of a mesh without faces");

  gltf["scene"] = 0;
  gltf["scenes"] = {{{"nodes", {0}}}};
  gltf["nodes"] = {{{"mesh", 0}}};
  gltf["meshes"] = {{{"primitives", prims}}};
  gltf["materials"] = jmats;
  if (!jtextures.empty()) {
    gltf["textures"] = jtextures;
    gltf["images"] = jimages;
    // Linear filtering with mipmaps, repeat wrapping (the glTF defaults, spelled out for viewers).
    gltf["samplers"] = {{{"magFilter", 9729}, {"minFilter", 9987}, {"wrapS", 10497}, {"wrapT", 10497}}};
  }
  WriteFileAtomic(path, glb.Finish(std::move(gltf)));
}

// ---------------------------------------------------------------------------------------------------------
// PLY

void SavePly(const fs::path& path, const TriangleMesh& mesh) {
  SD_CHECK(mesh.Validate().empty(), << "SavePly of an inconsistent mesh: " << mesh.Validate());
  const bool has_n = !mesh.normals.empty(), has_c = !mesh.colors.empty();
  std::string out = Msg() << "ply\nformat binary_little_endian 1.0\ncomment synthdrive\n"
                          << "element vertex " << mesh.NumVertices() << "\n"
                          << "property float x\nproperty float y\nproperty float z\n";
  if (has_n) out += "property float nx\nproperty float ny\nproperty float nz\n";
  if (has_c) out += "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n";
  out += Msg() << "element face " << mesh.NumFaces() << "\nproperty list uchar int vertex_indices\nend_header\n";
  auto put = [&out](const void* p, size_t n) { out.append(static_cast<const char*>(p), n); };
  for (size_t v = 0; v < mesh.NumVertices(); ++v) {
    put(mesh.positions[v].data(), 12);
    if (has_n) put(mesh.normals[v].data(), 12);
    if (has_c) {
      // PLY viewers display these bytes directly, so colour channels are sRGB-encoded; alpha stays linear.
      uint8_t rgba[4];
      for (int c = 0; c < 4; ++c) {
        const float x = std::clamp(mesh.colors[v][c], 0.0f, 1.0f);
        rgba[c] = static_cast<uint8_t>(std::lround((c < 3 ? LinearToSrgb(x) : x) * 255.0f));
      }
      put(rgba, 4);
    }
  }
  for (const auto& f : mesh.faces) {
    const uint8_t three = 3;
    put(&three, 1);
    put(f.data(), 12);
  }
  WriteFileAtomic(path, out);
}

}  // namespace sd
