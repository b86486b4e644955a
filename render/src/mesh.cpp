// Meshes: built-in shapes and the OBJ (tinyobjloader) and glTF 2.0 (tinygltf) loaders.
// Triangles are wound counter-clockwise seen from their front, whose normal
// (v1 - v0) x (v2 - v0) is the side that charges and glows (a paint layer).

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>

#include <tiny_gltf.h>
#include <tiny_obj_loader.h>

#include "phos/render/scene.h"
#include "phos/util/error.h"

namespace phos::render {
namespace {

void FlipWinding(Mesh& mesh) {
  for (Eigen::Vector3i& t : mesh.triangles) std::swap(t[1], t[2]);
  for (Eigen::Vector3i& t : mesh.uv_triangles) std::swap(t[1], t[2]);
}

Mesh LoadObj(const std::filesystem::path& path, const std::string& group, const std::string& where) {
  tinyobj::ObjReaderConfig config;
  config.triangulate = true;
  config.vertex_color = false;
  config.mtl_search_path = path.parent_path().string();
  tinyobj::ObjReader reader;
  if (!reader.ParseFromFile(path.string(), config)) {
    std::string message = reader.Error();
    while (!message.empty() && (message.back() == '\n' || message.back() == '\r')) message.pop_back();
    ThrowUserError(where, "", "cannot read OBJ '" + path.string() + "': " + (message.empty() ? "unknown error" : message));
  }
  Mesh mesh;
  mesh.source = path.string() + (group.empty() ? "" : "#" + group);
  const std::vector<tinyobj::real_t>& v = reader.GetAttrib().vertices;
  for (std::size_t i = 0; i + 2 < v.size(); i += 3) mesh.positions.emplace_back(v[i], v[i + 1], v[i + 2]);
  const std::vector<tinyobj::real_t>& vt = reader.GetAttrib().texcoords;
  for (std::size_t i = 0; i + 1 < vt.size(); i += 2) mesh.uvs.emplace_back(vt[i], vt[i + 1]);
  bool every_corner_has_uv = !mesh.uvs.empty();
  bool found = group.empty();
  std::string names;
  for (const tinyobj::shape_t& shape : reader.GetShapes()) {
    names += (names.empty() ? "" : ", ") + shape.name;
    if (!group.empty() && shape.name != group) continue;
    found = true;
    const auto& indices = shape.mesh.indices;
    for (std::size_t i = 0; i + 2 < indices.size(); i += 3) {
      Eigen::Vector3i t(indices[i].vertex_index, indices[i + 1].vertex_index, indices[i + 2].vertex_index);
      if (t.minCoeff() < 0 || t.maxCoeff() >= static_cast<int>(mesh.positions.size()))
        ThrowUserError(where, "", "OBJ '" + path.string() + "' has a face with a vertex index out of range");
      mesh.triangles.push_back(t);
      const Eigen::Vector3i uv(indices[i].texcoord_index, indices[i + 1].texcoord_index, indices[i + 2].texcoord_index);
      every_corner_has_uv = every_corner_has_uv && uv.minCoeff() >= 0 && uv.maxCoeff() < static_cast<int>(mesh.uvs.size());
      mesh.uv_triangles.push_back(uv);
    }
  }
  if (!every_corner_has_uv) {  // a partial UV map is no map
    mesh.uvs.clear();
    mesh.uv_triangles.clear();
  }
  if (!found) ThrowUserError(where, "", "OBJ '" + path.string() + "' has no group '" + group + "' (groups: " + names + ")");
  return mesh;
}

// Reads accessor `index` of a glTF model as `components` values per element.
template <typename Out>
std::vector<Out> ReadAccessor(const tinygltf::Model& model, int index, int components, const std::string& where,
                              const std::string& what) {
  if (index < 0 || index >= static_cast<int>(model.accessors.size()))
    ThrowUserError(where, what, "accessor index out of range");
  const tinygltf::Accessor& accessor = model.accessors[index];
  if (accessor.bufferView < 0 || accessor.bufferView >= static_cast<int>(model.bufferViews.size()))
    ThrowUserError(where, what, "accessor without a valid bufferView");
  const tinygltf::BufferView& view = model.bufferViews[accessor.bufferView];
  const tinygltf::Buffer& buffer = model.buffers.at(view.buffer);
  const int component_bytes = tinygltf::GetComponentSizeInBytes(accessor.componentType);
  const int element_components = tinygltf::GetNumComponentsInType(accessor.type);
  if (component_bytes <= 0 || element_components != components)
    ThrowUserError(where, what, "unexpected accessor type");
  const std::size_t stride = view.byteStride ? view.byteStride : static_cast<std::size_t>(component_bytes * components);
  const std::size_t begin = view.byteOffset + accessor.byteOffset;
  if (accessor.count > 0 &&
      begin + stride * (accessor.count - 1) + static_cast<std::size_t>(component_bytes * components) > buffer.data.size())
    ThrowUserError(where, what, "accessor reaches past the end of its buffer");
  std::vector<Out> out;
  out.reserve(accessor.count * components);
  for (std::size_t e = 0; e < accessor.count; ++e) {
    const unsigned char* p = buffer.data.data() + begin + e * stride;
    for (int c = 0; c < components; ++c, p += component_bytes) {
      switch (accessor.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, p, 4); out.push_back(static_cast<Out>(f)); break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { std::uint32_t u; std::memcpy(&u, p, 4); out.push_back(static_cast<Out>(u)); break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { std::uint16_t u; std::memcpy(&u, p, 2); out.push_back(static_cast<Out>(u)); break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: out.push_back(static_cast<Out>(*p)); break;
        default: ThrowUserError(where, what, "unsupported component type " + std::to_string(accessor.componentType));
      }
    }
  }
  return out;
}

Eigen::Affine3d NodeTransform(const tinygltf::Node& node) {
  Eigen::Affine3d transform = Eigen::Affine3d::Identity();
  if (node.matrix.size() == 16) {
    transform.matrix() = Eigen::Map<const Eigen::Matrix4d>(node.matrix.data());  // column-major, as glTF
    return transform;
  }
  if (node.translation.size() == 3) transform.translate(Vec3(node.translation[0], node.translation[1], node.translation[2]));
  if (node.rotation.size() == 4)  // glTF quaternions are x, y, z, w
    transform.rotate(Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]));
  if (node.scale.size() == 3) transform.scale(Vec3(node.scale[0], node.scale[1], node.scale[2]));
  return transform;
}

Mesh LoadGltf(const std::filesystem::path& path, const std::string& group, const std::string& where) {
  tinygltf::TinyGLTF loader;
  tinygltf::Model model;
  std::string error, warning;
  const bool binary = path.extension() == ".glb";
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &error, &warning, path.string())
                         : loader.LoadASCIIFromFile(&model, &error, &warning, path.string());
  if (!ok) ThrowUserError(where, "", "cannot read glTF '" + path.string() + "': " + (error.empty() ? "unknown error" : error));
  Mesh mesh;
  mesh.source = path.string() + (group.empty() ? "" : "#" + group);
  bool found = group.empty();
  bool all_uv = true;
  const std::string file_where = where + " (" + path.string() + ")";
  // Walks the node tree of the default scene, applying each node's transform.
  std::function<void(int, const Eigen::Affine3d&, int)> visit = [&](int index, const Eigen::Affine3d& parent, int depth) {
    if (index < 0 || index >= static_cast<int>(model.nodes.size()) || depth > 64)
      ThrowUserError(file_where, "nodes", "node index out of range or a cycle");
    const tinygltf::Node& node = model.nodes[index];
    const Eigen::Affine3d transform = parent * NodeTransform(node);
    if (node.mesh >= 0 && node.mesh < static_cast<int>(model.meshes.size()) &&
        (group.empty() || model.meshes[node.mesh].name == group)) {
      found = true;
      for (const tinygltf::Primitive& primitive : model.meshes[node.mesh].primitives) {
        if (primitive.mode != TINYGLTF_MODE_TRIANGLES && primitive.mode != -1) continue;  // points and lines carry no surface
        const auto position = primitive.attributes.find("POSITION");
        if (position == primitive.attributes.end()) ThrowUserError(file_where, "meshes", "a primitive without POSITION");
        const std::vector<float> p = ReadAccessor<float>(model, position->second, 3, file_where, "POSITION");
        const int base = static_cast<int>(mesh.positions.size());
        const int count = static_cast<int>(p.size() / 3);
        for (int i = 0; i < count; ++i)
          mesh.positions.push_back((transform * Vec3(p[3 * i], p[3 * i + 1], p[3 * i + 2])).cast<float>());
        const auto texcoord = primitive.attributes.find("TEXCOORD_0");
        const int uv_base = static_cast<int>(mesh.uvs.size());
        bool with_uv = texcoord != primitive.attributes.end();
        if (with_uv) {
          const std::vector<float> uv = ReadAccessor<float>(model, texcoord->second, 2, file_where, "TEXCOORD_0");
          with_uv = static_cast<int>(uv.size() / 2) == count;
          for (int i = 0; with_uv && i < count; ++i) mesh.uvs.emplace_back(uv[2 * i], uv[2 * i + 1]);
        }
        all_uv = all_uv && with_uv;
        std::vector<int> indices;
        if (primitive.indices >= 0) {
          indices = ReadAccessor<int>(model, primitive.indices, 1, file_where, "indices");
        } else {
          for (int i = 0; i < count; ++i) indices.push_back(i);
        }
        for (std::size_t i = 0; i + 2 < indices.size(); i += 3) {
          Eigen::Vector3i t(indices[i], indices[i + 1], indices[i + 2]);
          if (t.minCoeff() < 0 || t.maxCoeff() >= count) ThrowUserError(file_where, "indices", "vertex index out of range");
          mesh.triangles.push_back(t.array() + base);
          if (with_uv) mesh.uv_triangles.push_back(t.array() + uv_base);
        }
        // A mirroring transform turns the winding around; keep fronts in front.
        if (transform.linear().determinant() < 0)
          for (std::size_t t = mesh.triangles.size() - indices.size() / 3; t < mesh.triangles.size(); ++t) {
            std::swap(mesh.triangles[t][1], mesh.triangles[t][2]);
            if (with_uv) std::swap(mesh.uv_triangles[t][1], mesh.uv_triangles[t][2]);
          }
      }
    }
    for (int child : node.children) visit(child, transform, depth + 1);
  };
  if (!model.scenes.empty()) {
    const int scene = model.defaultScene >= 0 ? model.defaultScene : 0;
    for (int node : model.scenes.at(scene).nodes) visit(node, Eigen::Affine3d::Identity(), 0);
  } else {
    for (std::size_t node = 0; node < model.nodes.size(); ++node) visit(static_cast<int>(node), Eigen::Affine3d::Identity(), 0);
  }
  if (!found) ThrowUserError(where, "", "glTF '" + path.string() + "' has no mesh named '" + group + "'");
  if (!all_uv || mesh.uv_triangles.size() != mesh.triangles.size()) {  // a partial UV map is no map
    mesh.uvs.clear();
    mesh.uv_triangles.clear();
  }
  return mesh;
}

}  // namespace

Mesh MakeQuad(double size_x, double size_z) {
  Mesh mesh;
  mesh.source = "shape quad";
  const float x = static_cast<float>(size_x / 2), z = static_cast<float>(size_z / 2);
  mesh.positions = {{-x, 0, -z}, {x, 0, -z}, {x, 0, z}, {-x, 0, z}};
  mesh.triangles = {{0, 2, 1}, {0, 3, 2}};  // normal +y
  return mesh;
}

Mesh MakeBox(const Vec3& size, bool inward) {
  Mesh mesh;
  mesh.source = "shape box";
  const Eigen::Vector3f h = (size / 2).cast<float>();
  for (int i = 0; i < 8; ++i)
    mesh.positions.emplace_back(i & 1 ? h.x() : -h.x(), i & 2 ? h.y() : -h.y(), i & 4 ? h.z() : -h.z());
  // Faces as quads wound counter-clockwise seen from outside.
  const int quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& q : quads) {
    mesh.triangles.emplace_back(q[0], q[1], q[2]);
    mesh.triangles.emplace_back(q[0], q[2], q[3]);
  }
  if (inward) FlipWinding(mesh);
  return mesh;
}

Mesh MakeSphere(double radius, int subdivisions, bool inward) {
  Mesh mesh;
  mesh.source = "shape sphere";
  // An icosahedron, each face split in four `subdivisions` times, vertices on the sphere.
  const double t = (1 + std::sqrt(5.0)) / 2;
  std::vector<Vec3> p = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& v : p) v.normalize();
  std::vector<Eigen::Vector3i> faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                        {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                        {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                        {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7}, {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> midpoints;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      const auto it = midpoints.find(key);
      if (it != midpoints.end()) return it->second;
      p.push_back((p[a] + p[b]).normalized());
      return midpoints[key] = static_cast<int>(p.size()) - 1;
    };
    std::vector<Eigen::Vector3i> next;
    for (const Eigen::Vector3i& f : faces) {
      const int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      next.insert(next.end(), {{f[0], ab, ca}, {f[1], bc, ab}, {f[2], ca, bc}, {ab, bc, ca}});
    }
    faces = std::move(next);
  }
  for (const Vec3& v : p) mesh.positions.push_back((radius * v).cast<float>());
  mesh.triangles = std::move(faces);
  if (inward) FlipWinding(mesh);
  return mesh;
}

Mesh LoadMesh(const std::filesystem::path& path, const std::string& group, const std::string& where) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
  if (!std::filesystem::exists(path)) ThrowUserError(where, "", "mesh file '" + path.string() + "' does not exist");
  Mesh mesh;
  if (extension == ".obj") mesh = LoadObj(path, group, where);
  else if (extension == ".gltf" || extension == ".glb") mesh = LoadGltf(path, group, where);
  else ThrowUserError(where, "", "unknown mesh format '" + extension + "' (.obj, .gltf, .glb)");
  for (const Eigen::Vector3f& v : mesh.positions)
    if (!v.allFinite()) ThrowUserError(where, "", "mesh '" + path.string() + "' has a vertex that is not finite");
  return mesh;
}

}  // namespace phos::render
