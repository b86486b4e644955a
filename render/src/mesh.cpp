// Meshes: built-in shapes and the OBJ (tinyobjloader) and glTF 2.0 (tinygltf) loaders.
// Triangles are wound counter-clockwise seen from their front, whose normal
// (v1 - v0) x (v2 - v0) is the side that charges and glows (a paint layer).

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <type_traits>

#include <tiny_gltf.h>
#include <tiny_obj_loader.h>

#include "phos/render/scene.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos::render {
namespace {

void FlipWinding(Mesh& mesh) {
  for (Eigen::Vector3i& t : mesh.triangles) std::swap(t[1], t[2]);
  for (Eigen::Vector3i& t : mesh.uv_triangles) std::swap(t[1], t[2]);
}

// A loader's message as one line: tinyobjloader and tinygltf end every
// complaint with a newline and may give several.
std::string OneLine(std::string message) {
  std::string line;
  std::size_t start = 0;
  while (start <= message.size()) {
    std::size_t end = message.find_first_of("\r\n", start);
    if (end == std::string::npos) end = message.size();
    std::string part = message.substr(start, end - start);
    while (!part.empty() && std::isspace(static_cast<unsigned char>(part.back()))) part.pop_back();
    if (!part.empty()) line += (line.empty() ? "" : "; ") + part;
    start = end + 1;
  }
  for (char& c : line)
    if (static_cast<unsigned char>(c) < 0x20) c = ' ';
  return line.empty() ? "unknown error" : line;
}

// What the loaders check after reading, whichever the format: the counts,
// indices in range, and vertices finite and within kMaxCoordinate_m.
void CheckCounts(std::size_t vertices, std::size_t triangles, const std::string& where, const std::string& file) {
  if (vertices > kMaxMeshVertices)
    ThrowUserError(where, "",
                   "mesh '" + file + "' has more than the limit of " + std::to_string(kMaxMeshVertices) + " vertices");
  if (triangles > kMaxMeshTriangles)
    ThrowUserError(
        where, "",
        "mesh '" + file + "' has more than the limit of " + std::to_string(kMaxMeshTriangles) + " triangles");
}

// A texture a mesh file names, relative to the file's folder: it must be a
// regular file (OpenImageIO decodes it when the renderer first looks it up;
// render/surface_textures.h says there whether it is an image).
std::filesystem::path TextureFile(const std::filesystem::path& base_dir, const std::string& name,
                                  const std::string& where, const std::string& field) {
  const std::filesystem::path file = base_dir / name;
  std::error_code ec;
  if (!std::filesystem::exists(file, ec))
    ThrowUserError(where, field, "texture file '" + file.string() + "' does not exist");
  if (!std::filesystem::is_regular_file(file, ec))
    ThrowUserError(where, field, "texture file '" + file.string() + "' is not a regular file");
  return file;
}

// Keeps one base colour per mesh: each primitive or face group's in turn;
// when they differ, none (an albedo varying per triangle is not modelled).
void MergeBaseColour(Mesh& mesh, const std::optional<BaseColour>& colour, bool first) {
  if (first) {
    mesh.base_colour = colour;
    return;
  }
  if (mesh.base_colours_differ.empty() && mesh.base_colour != colour) {
    mesh.base_colours_differ = "its parts have different materials" +
                               std::string(mesh.base_colour ? " (" + mesh.base_colour->field + ")" : "") +
                               (colour ? " (" + colour->field + ")" : "");
    mesh.base_colour.reset();
  }
}

// The name after "mtllib" in an OBJ, empty if none (the first one only).
std::string MtllibName(std::string_view text) {
  for (std::size_t a = 0; a < text.size();) {
    std::size_t b = text.find('\n', a);
    if (b == std::string_view::npos) b = text.size();
    std::string_view line = text.substr(a, b - a);
    if (line.substr(0, 7) == "mtllib " || line.substr(0, 7) == "mtllib\t") {
      std::string name(line.substr(7));
      while (!name.empty() && std::isspace(static_cast<unsigned char>(name.back()))) name.pop_back();
      while (!name.empty() && std::isspace(static_cast<unsigned char>(name.front()))) name.erase(0, 1);
      return name;
    }
    a = b + 1;
  }
  return "";
}

// A vertex line's three coordinates ("v x y z [w]"), each a finite number:
// tinyobjloader reads "nan", "inf" or "1e999" as 0 or infinity without a
// word, so a mesh with such a vertex rendered as if it were at the origin.
void CheckVertexLine(std::string_view line, std::size_t line_number, const std::string& where,
                     const std::string& name) {
  std::size_t i = 1;
  for (int k = 0; k < 3; ++k) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    const std::string token(line.substr(i, j - i));
    double value = 0;
    if (token.empty())
      ThrowUserError(
          where, "",
          "OBJ '" + name + "' line " + std::to_string(line_number) + ": a vertex has fewer than 3 coordinates");
    if (!ParseDouble(token, &value))
      ThrowUserError(where, "",
                     "OBJ '" + name + "' line " + std::to_string(line_number) + ": vertex coordinate '" +
                         token.substr(0, 40) + "' is not a finite number");
    i = j;
  }
}

// A face line's indices ("f v/vt/vn ..."), each a whole number that fits an
// int: tinyobjloader reads 99999999999999999999 as -1 (strtol saturates, the
// int wraps), the last vertex, and the face loaded in silence.
void CheckFaceLine(std::string_view line, std::size_t line_number, const std::string& where, const std::string& name) {
  for (std::size_t i = 1; i < line.size();) {
    if (line[i] == ' ' || line[i] == '\t' || line[i] == '/' || line[i] == '\r') {
      ++i;
      continue;
    }
    if (line[i] == '#') break;  // a comment to the end of the line
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '/' && line[j] != '\r') ++j;
    const std::string_view token = line.substr(i, j - i);
    const std::string_view digits = token.substr(token[0] == '-' ? 1 : 0);
    const bool whole = !digits.empty() && std::all_of(digits.begin(), digits.end(), [](char c) {
      return std::isdigit(static_cast<unsigned char>(c));
    });
    if (!whole || digits.size() > 10 || std::stoll(std::string(digits)) > std::numeric_limits<int>::max())
      ThrowUserError(where, "",
                     "OBJ '" + name + "' line " + std::to_string(line_number) + ": face index '" +
                         std::string(token.substr(0, 40)) + "' is not a whole number within the vertex range");
    i = j;
  }
}

Mesh ParseObj(std::string_view text, const std::filesystem::path& base_dir, const std::string& name,
              const std::string& group, const std::string& where) {
  // Counts before allocation: a vertex is a line "v ...", and a face of k
  // corners "f ..." gives k - 2 triangles, fewer than its fields.
  std::size_t vertex_lines = 0, face_fields = 0, line_number = 0;
  for (std::size_t a = 0; a < text.size();) {
    std::size_t b = text.find('\n', a);
    if (b == std::string_view::npos) b = text.size();
    const std::string_view line = text.substr(a, b - a);
    ++line_number;
    if (line.size() >= 2 && line[0] == 'v' && (line[1] == ' ' || line[1] == '\t')) {
      ++vertex_lines;
      CheckVertexLine(line, line_number, where, name);
    }
    if (line.size() >= 2 && line[0] == 'f' && (line[1] == ' ' || line[1] == '\t')) {
      face_fields += static_cast<std::size_t>(std::count(line.begin(), line.end(), ' ') +
                                              std::count(line.begin(), line.end(), '\t'));
      CheckFaceLine(line, line_number, where, name);
    }
    a = b + 1;
  }
  CheckCounts(vertex_lines, face_fields, where, name);
  tinyobj::ObjReaderConfig config;
  config.triangulate = true;
  config.vertex_color = false;
  tinyobj::ObjReader reader;
  // The .mtl (its Kd and map_Kd are the base colour) is read by
  // ReadFileText, as a regular file within the size limit: a mtllib naming a
  // FIFO or /dev/zero must not hang the load.
  std::string mtl_text;
  const std::string mtllib = MtllibName(text);
  std::filesystem::path mtl_file;
  if (!mtllib.empty()) {
    mtl_file = base_dir / mtllib;
    std::error_code ec;
    if (!std::filesystem::exists(mtl_file, ec))
      ThrowUserError(where, "mtllib",
                     "OBJ '" + name + "' names material file '" + mtl_file.string() + "', which does not exist");
    try {
      mtl_text = ReadFileText(mtl_file);
    } catch (const UserError& e) {
      ThrowUserError(where, "mtllib", e.what());
    }
  }
  if (!reader.ParseFromString(std::string(text), mtl_text, config))
    ThrowUserError(where, "", "cannot read OBJ '" + name + "': " + OneLine(reader.Error()));
  Mesh mesh;
  mesh.source = name + (group.empty() ? "" : "#" + group);
  if (!mtl_file.empty()) mesh.also_read.push_back(mtl_file);
  mesh.v_up = true;
  const std::vector<tinyobj::real_t>& v = reader.GetAttrib().vertices;
  CheckCounts(v.size() / 3, 0, where, name);
  for (std::size_t i = 0; i + 2 < v.size(); i += 3) mesh.positions.emplace_back(v[i], v[i + 1], v[i + 2]);
  const std::vector<tinyobj::real_t>& vt = reader.GetAttrib().texcoords;
  CheckCounts(vt.size() / 2, 0, where, name);
  for (std::size_t i = 0; i + 1 < vt.size(); i += 2) mesh.uvs.emplace_back(vt[i], vt[i + 1]);
  bool every_corner_has_uv = !mesh.uvs.empty();
  bool found = group.empty();
  std::string names;
  const std::vector<tinyobj::material_t>& materials = reader.GetMaterials();
  const std::string mtl_where = where + " (" + (base_dir / mtllib).string() + ")";
  // Kd and map_Kd of material m, or none for faces without one.
  auto base_colour_of = [&](int m) -> std::optional<BaseColour> {
    if (m < 0 || m >= static_cast<int>(materials.size())) return std::nullopt;
    const tinyobj::material_t& material = materials[m];
    BaseColour colour;
    colour.field = "newmtl " + material.name;
    colour.v_up = true;
    colour.factor = Eigen::Vector3f(material.diffuse[0], material.diffuse[1], material.diffuse[2]);
    if (!colour.factor.allFinite() || colour.factor.minCoeff() < 0 || colour.factor.maxCoeff() > 1)
      ThrowUserError(mtl_where, colour.field + ": Kd", "expected values in [0, 1]");
    if (!material.diffuse_texname.empty()) {
      colour.field += ": map_Kd";
      colour.texture = TextureFile(base_dir, material.diffuse_texname, mtl_where, colour.field);
      if (material.diffuse_texopt.clamp) colour.wraps = {TextureWrap::kClampToEdge, TextureWrap::kClampToEdge};
      // A texture under a black Kd: the file left Kd out (tinyobjloader
      // reads a missing Kd as 0); no exporter means black.
      if (colour.factor.isZero()) colour.factor.setOnes();
    }
    return colour;
  };
  bool first_face = true;
  for (const tinyobj::shape_t& shape : reader.GetShapes()) {
    if (names.size() < 200) names += (names.empty() ? "" : ", ") + shape.name;
    if (!group.empty() && shape.name != group) continue;
    found = true;
    for (int m : shape.mesh.material_ids) {
      MergeBaseColour(mesh, base_colour_of(m), first_face);
      first_face = false;
    }
    const auto& indices = shape.mesh.indices;
    CheckCounts(0, mesh.triangles.size() + indices.size() / 3, where, name);
    for (std::size_t i = 0; i + 2 < indices.size(); i += 3) {
      Eigen::Vector3i t(indices[i].vertex_index, indices[i + 1].vertex_index, indices[i + 2].vertex_index);
      if (t.minCoeff() < 0 || t.maxCoeff() >= static_cast<int>(mesh.positions.size()))
        ThrowUserError(where, "", "OBJ '" + name + "' has a face with a vertex index out of range");
      mesh.triangles.push_back(t);
      const Eigen::Vector3i uv(indices[i].texcoord_index, indices[i + 1].texcoord_index, indices[i + 2].texcoord_index);
      every_corner_has_uv =
          every_corner_has_uv && uv.minCoeff() >= 0 && uv.maxCoeff() < static_cast<int>(mesh.uvs.size());
      mesh.uv_triangles.push_back(uv);
    }
  }
  if (!every_corner_has_uv) {  // a partial UV map is no map
    mesh.uvs.clear();
    mesh.uv_triangles.clear();
  }
  if (!found) ThrowUserError(where, "", "OBJ '" + name + "' has no group '" + group + "' (groups: " + names + ")");
  return mesh;
}

// Reads accessor `index` of a glTF model as `components` values per element,
// at most max_elements of them. Every offset is checked against the buffer
// before it is used, without overflow (a count of 2^62 wrapped the old sum).
template <typename Out>
std::vector<Out> ReadAccessor(const tinygltf::Model& model, int index, int components, std::size_t max_elements,
                              const std::string& where, const std::string& what) {
  if (index < 0 || index >= static_cast<int>(model.accessors.size()))
    ThrowUserError(where, what, "accessor index out of range");
  const tinygltf::Accessor& accessor = model.accessors[index];
  if (accessor.sparse.isSparse) ThrowUserError(where, what, "sparse accessors are not supported");
  if (accessor.bufferView < 0 || accessor.bufferView >= static_cast<int>(model.bufferViews.size()))
    ThrowUserError(where, what, "accessor without a valid bufferView");
  const tinygltf::BufferView& view = model.bufferViews[accessor.bufferView];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size()))
    ThrowUserError(where, what,
                   "bufferView " + std::to_string(accessor.bufferView) + " names a buffer that does not exist");
  const tinygltf::Buffer& buffer = model.buffers[view.buffer];
  const int component_bytes = tinygltf::GetComponentSizeInBytes(accessor.componentType);
  const int element_components = tinygltf::GetNumComponentsInType(accessor.type);
  if (component_bytes <= 0 || element_components != components) ThrowUserError(where, what, "unexpected accessor type");
  const bool integer = accessor.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT ||
                       accessor.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
                       accessor.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
  if (accessor.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT && !integer)
    ThrowUserError(where, what, "unsupported component type " + std::to_string(accessor.componentType));
  if (std::is_integral_v<Out> && !integer) ThrowUserError(where, what, "indices must be unsigned integers");
  if (accessor.count > max_elements)
    ThrowUserError(where, what,
                   "accessor count " + std::to_string(accessor.count) + " is more than the limit of " +
                       std::to_string(max_elements));
  const std::size_t element_bytes = static_cast<std::size_t>(component_bytes) * static_cast<std::size_t>(components);
  const std::size_t stride = view.byteStride ? view.byteStride : element_bytes;
  const std::size_t size = buffer.data.size();
  // begin + stride (count - 1) + element_bytes <= size, each step checked.
  if (view.byteOffset > size || accessor.byteOffset > size - view.byteOffset)
    ThrowUserError(where, what, "accessor starts past the end of its buffer");
  const std::size_t begin = view.byteOffset + accessor.byteOffset;
  if (accessor.count > 0 &&
      (element_bytes > size - begin || (accessor.count - 1) > (size - begin - element_bytes) / stride))
    ThrowUserError(where, what, "accessor reaches past the end of its buffer");
  // Within its bufferView too (glTF 2.0, 3.6.2.4): past it, it read the next
  // view's bytes (indices as positions) without a word.
  const std::size_t view_bytes = view.byteLength;
  if (accessor.byteOffset > view_bytes ||
      (accessor.count > 0 && (element_bytes > view_bytes - accessor.byteOffset ||
                              (accessor.count - 1) > (view_bytes - accessor.byteOffset - element_bytes) / stride)))
    ThrowUserError(where, what,
                   "accessor reaches past the end of bufferView " + std::to_string(accessor.bufferView) + " (" +
                       std::to_string(view_bytes) + " bytes)");
  std::vector<Out> out;
  out.reserve(accessor.count * static_cast<std::size_t>(components));
  for (std::size_t e = 0; e < accessor.count; ++e) {
    const unsigned char* p = buffer.data.data() + begin + e * stride;
    for (int c = 0; c < components; ++c, p += component_bytes) {
      switch (accessor.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: {
          float f;
          std::memcpy(&f, p, 4);
          out.push_back(static_cast<Out>(f));
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
          std::uint32_t u;
          std::memcpy(&u, p, 4);
          // An index past INT_MAX is out of range anyway: -1 says so below.
          if constexpr (std::is_integral_v<Out>)
            out.push_back(u > 0x7fffffffu ? Out(-1) : static_cast<Out>(u));
          else
            out.push_back(static_cast<Out>(u));
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          std::uint16_t u;
          std::memcpy(&u, p, 2);
          out.push_back(static_cast<Out>(u));
          break;
        }
        default: out.push_back(static_cast<Out>(*p)); break;  // unsigned byte
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
  if (node.translation.size() == 3)
    transform.translate(Vec3(node.translation[0], node.translation[1], node.translation[2]));
  if (node.rotation.size() == 4)  // glTF quaternions are x, y, z, w
    transform.rotate(Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]));
  if (node.scale.size() == 3) transform.scale(Vec3(node.scale[0], node.scale[1], node.scale[2]));
  return transform;
}

// tinygltf's file access, for external buffers: regular files within the
// size limit only (ReadFileText), no "~" expansion.
bool GltfFileExists(const std::string& path, void*) {
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}
std::string GltfExpandPath(const std::string& path, void*) { return path; }
// user: null, or the std::vector<std::filesystem::path> of the files read.
bool GltfReadFile(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  try {
    const std::string text = ReadFileText(path);
    out->assign(text.begin(), text.end());
    if (user) static_cast<std::vector<std::filesystem::path>*>(user)->push_back(path);
    return true;
  } catch (const UserError& e) {
    if (err) *err += std::string(e.what()) + "\n";
    return false;
  }
}
bool GltfNoWrite(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err += "phos writes no glTF files\n";
  return false;
}
// Images are not decoded here: a texture is read through OpenImageIO's
// TextureSystem when rendering (surface_textures.h), and a crafted image
// must not cost time at load. A data: URI's bytes, decoded by tinygltf, are
// kept (they exist nowhere else); a file's are dropped (the render opens it
// by name), and a bufferView's are taken from its buffer once its range is
// checked (GltfEmbeddedImage): tinygltf hands them over unchecked.
bool GltfKeepDataUriImage(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                          const unsigned char* bytes, int size, void*) {
  if (image->bufferView < 0 && image->uri.empty() && bytes != nullptr && size > 0)
    image->image.assign(bytes, bytes + size);
  return true;
}

// An embedded image's bytes (a data: URI's, kept by GltfKeepDataUriImage,
// or a bufferView's, its range checked here) and its file extension.
std::shared_ptr<const EmbeddedImage> GltfEmbeddedImage(const tinygltf::Model& model, int source,
                                                       const std::string& where) {
  const tinygltf::Image& image = model.images[source];
  const std::string field = "images[" + std::to_string(source) + "]";
  auto embedded = std::make_shared<EmbeddedImage>();
  if (image.mimeType == "image/png") {
    embedded->extension = ".png";
  } else if (image.mimeType == "image/jpeg") {
    embedded->extension = ".jpg";
  } else {
    ThrowUserError(where, field + ".mimeType", "expected image/png or image/jpeg, got '" + image.mimeType + "'");
  }
  if (image.bufferView >= 0) {
    if (image.bufferView >= static_cast<int>(model.bufferViews.size()))
      ThrowUserError(where, field + ".bufferView", "bufferView index out of range");
    const tinygltf::BufferView& view = model.bufferViews[image.bufferView];
    const std::string view_field = "bufferViews[" + std::to_string(image.bufferView) + "]";
    if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size()))
      ThrowUserError(where, view_field + ".buffer", "buffer index out of range");
    const std::vector<unsigned char>& data = model.buffers[view.buffer].data;
    if (view.byteLength == 0 || view.byteLength > data.size() || view.byteOffset > data.size() - view.byteLength)
      ThrowUserError(where, view_field, "the image's bytes lie outside its buffer");
    const auto* first = reinterpret_cast<const char*>(data.data() + view.byteOffset);
    embedded->bytes.assign(first, first + view.byteLength);
  } else {
    if (image.image.empty()) ThrowUserError(where, field + ".uri", "the data: URI holds no image");
    embedded->bytes.assign(image.image.begin(), image.image.end());
  }
  return embedded;
}

// The image of a glTF texture reference, through TEXCOORD_0: a file beside
// the glTF, a data: URI or a .glb's bufferView (PNG or JPEG). `texture.field`
// names the reference in messages.
void GltfTextureImage(const tinygltf::Model& model, const tinygltf::TextureInfo& info,
                      const std::filesystem::path& base_dir, const std::string& where, TextureSource& texture) {
  const std::string& field = texture.field;
  if (info.texCoord != 0) ThrowUserError(where, field + ".texCoord", "only TEXCOORD_0 is supported");
  if (info.index >= static_cast<int>(model.textures.size()))
    ThrowUserError(where, field + ".index", "texture index out of range");
  const int source = model.textures[info.index].source;
  if (source < 0 || source >= static_cast<int>(model.images.size()))
    ThrowUserError(where, "textures[" + std::to_string(info.index) + "].source", "image index out of range");
  const tinygltf::Image& image = model.images[source];
  if (image.bufferView >= 0 || image.uri.empty() || image.uri.rfind("data:", 0) == 0) {
    texture.texture = "images[" + std::to_string(source) + "] (embedded)";
    texture.embedded = GltfEmbeddedImage(model, source, where);
  } else {
    texture.texture = TextureFile(base_dir, image.uri, where, "images[" + std::to_string(source) + "].uri");
  }
}

// The sampler of the texture `info` refers to (glTF 2.0, 5.26), null without
// one; an index past the file's samplers is a UserError. `field` names it
// for messages.
const tinygltf::Sampler* GltfSampler(const tinygltf::Model& model, const tinygltf::TextureInfo& info,
                                     const std::string& where, std::string& field) {
  const int sampler = model.textures[info.index].sampler;
  if (sampler < 0) return nullptr;
  if (sampler >= static_cast<int>(model.samplers.size()))
    ThrowUserError(where, "textures[" + std::to_string(info.index) + "].sampler", "sampler index out of range");
  field = "samplers[" + std::to_string(sampler) + "]";
  return &model.samplers[sampler];
}

// How a sampler wraps: its wrapS and wrapT (33071 CLAMP_TO_EDGE, 33648
// MIRRORED_REPEAT, 10497 REPEAT, the default, also without a sampler).
TextureWraps GltfTextureWraps(const tinygltf::Sampler& sampler, const std::string& field, const std::string& where) {
  auto wrap = [&](int mode, const char* name) {
    switch (mode) {
      case TINYGLTF_TEXTURE_WRAP_REPEAT: return TextureWrap::kRepeat;
      case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE: return TextureWrap::kClampToEdge;
      case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT: return TextureWrap::kMirroredRepeat;
      default:
        ThrowUserError(
            where, field + "." + name,
            "expected 10497 (REPEAT), 33071 (CLAMP_TO_EDGE) or 33648 (MIRRORED_REPEAT), got " + std::to_string(mode));
    }
  };
  return {wrap(sampler.wrapS, "wrapS"), wrap(sampler.wrapT, "wrapT")};
}

// How a sampler filters: its magFilter and minFilter (scene.h,
// TextureFilter; 9728 NEAREST, 9729 LINEAR, 9984 to 9987 the MIP-mapped
// minifications; without a sampler or a filter, the renderer's own:
// bilinear, trilinear).
TextureFilter GltfTextureFilter(const tinygltf::Sampler& sampler, const std::string& field, const std::string& where) {
  TextureFilter filter;
  switch (sampler.magFilter) {
    case -1:
    case TINYGLTF_TEXTURE_FILTER_LINEAR: break;
    case TINYGLTF_TEXTURE_FILTER_NEAREST: filter.interpolation = TexelInterpolation::kClosest; break;
    default:
      ThrowUserError(where, field + ".magFilter",
                     "expected 9728 (NEAREST) or 9729 (LINEAR), got " + std::to_string(sampler.magFilter));
  }
  switch (sampler.minFilter) {
    case -1:
    case TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_LINEAR:
    case TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_LINEAR: break;
    case TINYGLTF_TEXTURE_FILTER_NEAREST:
    case TINYGLTF_TEXTURE_FILTER_LINEAR: filter.mip = MipLevels::kNone; break;
    case TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_NEAREST:
    case TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_NEAREST: filter.mip = MipLevels::kNearestLevel; break;
    default:
      ThrowUserError(where, field + ".minFilter",
                     "expected 9728, 9729 or 9984 to 9987 (NEAREST, LINEAR, the MIPMAP ones), got " +
                         std::to_string(sampler.minFilter));
  }
  return filter;
}

// The KHR_texture_transform of a texture reference, the identity without
// one: offset [x, y], rotation (radians, counter-clockwise in UV) and scale
// [x, y], composed as the extension's matrix T R S; its texCoord, when
// given, must be 0 (phos reads TEXCOORD_0 only).
UvTransform GltfUvTransform(const tinygltf::TextureInfo& info, const std::string& where, const std::string& field) {
  const auto extension = info.extensions.find("KHR_texture_transform");
  if (extension == info.extensions.end()) return {};
  const tinygltf::Value& value = extension->second;
  const std::string at = field + ".extensions.KHR_texture_transform";
  auto number = [&](const tinygltf::Value& v, const std::string& name) {
    const double x = v.IsNumber() ? v.GetNumberAsDouble() : std::nan("");
    if (!(std::isfinite(x) && std::abs(x) <= 1e6)) ThrowUserError(where, at + "." + name, "expected a finite number");
    return static_cast<float>(x);
  };
  auto pair = [&](const char* name, float fallback) -> Eigen::Vector2f {
    if (!value.Has(name)) return Eigen::Vector2f::Constant(fallback);
    const tinygltf::Value& v = value.Get(name);
    if (!v.IsArray() || v.ArrayLen() != 2) ThrowUserError(where, at + "." + name, "expected 2 numbers");
    return {number(v.Get(0), name), number(v.Get(1), name)};
  };
  if (value.Has("texCoord") && number(value.Get("texCoord"), "texCoord") != 0)
    ThrowUserError(where, at + ".texCoord", "only TEXCOORD_0 is supported");
  const Eigen::Vector2f offset = pair("offset", 0.0f), scale = pair("scale", 1.0f);
  const float rotation = value.Has("rotation") ? number(value.Get("rotation"), "rotation") : 0.0f;
  // Counter-clockwise in glTF's UV space, whose v runs down: u' = c u + s v,
  // v' = -s u + c v, as Khronos's sample renderer and the extension's sample
  // model (TextureTransformTest) have it. The GLSL listing in the extension's
  // README turns the other way (a y-up rotation; glTF issue 1563).
  Eigen::Matrix2f rotate;
  rotate << std::cos(rotation), std::sin(rotation), -std::sin(rotation), std::cos(rotation);
  UvTransform transform;
  transform.linear = rotate * scale.asDiagonal();
  transform.offset = offset;
  return transform;
}

// A glTF texture reference read whole: its image, wraps, filters and transform.
void ReadGltfTexture(const tinygltf::Model& model, const tinygltf::TextureInfo& info,
                     const std::filesystem::path& base_dir, const std::string& where, TextureSource& texture) {
  GltfTextureImage(model, info, base_dir, where, texture);
  std::string sampler_field;
  if (const tinygltf::Sampler* sampler = GltfSampler(model, info, where, sampler_field)) {
    texture.wraps = GltfTextureWraps(*sampler, sampler_field, where);
    texture.filter = GltfTextureFilter(*sampler, sampler_field, where);
  }
  texture.uv_transform = GltfUvTransform(info, where, texture.field);
}

// The base colour of glTF material `index` (pbrMetallicRoughness
// baseColorFactor, linear, and baseColorTexture, sRGB), none without one.
std::optional<BaseColour> GltfBaseColour(const tinygltf::Model& model, int index, const std::filesystem::path& base_dir,
                                         const std::string& where) {
  if (index < 0) return std::nullopt;
  const std::string field = "materials[" + std::to_string(index) + "]";
  if (index >= static_cast<int>(model.materials.size())) ThrowUserError(where, field, "material index out of range");
  const tinygltf::PbrMetallicRoughness& pbr = model.materials[index].pbrMetallicRoughness;
  BaseColour colour;
  colour.field = field + ".pbrMetallicRoughness.baseColorFactor";
  if (pbr.baseColorFactor.size() < 3) ThrowUserError(where, colour.field, "expected 4 numbers");
  colour.factor = Eigen::Vector3d(pbr.baseColorFactor[0], pbr.baseColorFactor[1], pbr.baseColorFactor[2]).cast<float>();
  if (!colour.factor.allFinite() || colour.factor.minCoeff() < 0 || colour.factor.maxCoeff() > 1)
    ThrowUserError(where, colour.field, "expected values in [0, 1]");
  const tinygltf::TextureInfo& info = pbr.baseColorTexture;
  if (info.index < 0) return colour;
  colour.field = field + ".pbrMetallicRoughness.baseColorTexture";
  ReadGltfTexture(model, info, base_dir, where, colour);
  return colour;
}

// A glTF material's metallic-roughness factors as a Gloss, when they make it
// glossy (metallic > 0 or roughness < 1, or a metallicRoughnessTexture); a
// rough dielectric (metallic 0, roughness 1, which glTF's spec draws nearly
// as a Lambertian surface) stays Lambertian.
std::optional<Gloss> GltfGloss(const tinygltf::Model& model, int index, const std::string& where) {
  if (index < 0 || index >= static_cast<int>(model.materials.size())) return std::nullopt;
  const tinygltf::PbrMetallicRoughness& pbr = model.materials[index].pbrMetallicRoughness;
  const std::string field = "materials[" + std::to_string(index) + "].pbrMetallicRoughness";
  if (!(pbr.metallicFactor >= 0 && pbr.metallicFactor <= 1))
    ThrowUserError(where, field + ".metallicFactor", "expected a value in [0, 1]");
  if (!(pbr.roughnessFactor >= 0 && pbr.roughnessFactor <= 1))
    ThrowUserError(where, field + ".roughnessFactor", "expected a value in [0, 1]");
  if (pbr.metallicFactor == 0 && pbr.roughnessFactor == 1 && pbr.metallicRoughnessTexture.index < 0)
    return std::nullopt;
  return Gloss{static_cast<float>(pbr.metallicFactor),
               std::max(kMinRoughness, static_cast<float>(pbr.roughnessFactor))};
}

// A glTF material's metallicRoughnessTexture, none without one.
std::optional<GlossTexture> GltfGlossTexture(const tinygltf::Model& model, int index,
                                             const std::filesystem::path& base_dir, const std::string& where) {
  if (index < 0 || index >= static_cast<int>(model.materials.size())) return std::nullopt;
  const tinygltf::TextureInfo& info = model.materials[index].pbrMetallicRoughness.metallicRoughnessTexture;
  if (info.index < 0) return std::nullopt;
  GlossTexture gloss;
  gloss.field = "materials[" + std::to_string(index) + "].pbrMetallicRoughness.metallicRoughnessTexture";
  ReadGltfTexture(model, info, base_dir, where, gloss);
  return gloss;
}

// The parts of glTF material `index` that phos does not draw, each named by
// the field that holds it ("materials[0].normalTexture"), added to `unread`
// once: normal, occlusion and emissive maps, an emissive factor, alpha
// blending or masking, double-sidedness (a scene object's "two_sided" says
// that for a phosphor) and the material's extensions. A render names them in
// a warning rather than drawing the surface otherwise in silence.
void NoteUnreadGltfMaterial(const tinygltf::Model& model, int index, std::vector<std::string>& unread) {
  if (index < 0 || index >= static_cast<int>(model.materials.size())) return;
  const tinygltf::Material& material = model.materials[index];
  const std::string field = "materials[" + std::to_string(index) + "].";
  std::vector<std::string> parts;
  if (material.normalTexture.index >= 0) parts.push_back(field + "normalTexture");
  if (material.occlusionTexture.index >= 0) parts.push_back(field + "occlusionTexture");
  if (material.emissiveTexture.index >= 0) parts.push_back(field + "emissiveTexture");
  if (std::any_of(material.emissiveFactor.begin(), material.emissiveFactor.end(), [](double v) { return v != 0; }))
    parts.push_back(field + "emissiveFactor");
  if (material.alphaMode == "BLEND" || material.alphaMode == "MASK")
    parts.push_back(field + "alphaMode " + material.alphaMode);
  if (material.doubleSided) parts.push_back(field + "doubleSided");
  for (const auto& extension : material.extensions) parts.push_back(field + "extensions." + extension.first);
  for (std::string& part : parts)
    if (std::find(unread.begin(), unread.end(), part) == unread.end()) unread.push_back(std::move(part));
}

// tinygltf reads an offset, length, stride or count that is not an unsigned
// integer (a bufferView's byteOffset of -4) as its default in silence: the
// accessor then read other bytes of the buffer. Each is checked in the JSON
// first; a syntax error is left to tinygltf, which names it.
void CheckGltfUnsignedFields(std::string_view json, const std::string& where) {
  const nlohmann::json document = nlohmann::json::parse(json, nullptr, false);
  if (document.is_discarded() || !document.is_object()) return;
  const std::pair<const char*, std::vector<const char*>> lists[] = {
      {"bufferViews", {"buffer", "byteOffset", "byteLength", "byteStride"}},
      {"accessors", {"bufferView", "byteOffset", "count"}},
      {"buffers", {"byteLength"}}};
  for (const auto& [list, keys] : lists) {
    const auto items = document.find(list);
    if (items == document.end() || !items->is_array()) continue;
    for (std::size_t i = 0; i < items->size(); ++i) {
      const nlohmann::json& item = (*items)[i];
      if (!item.is_object()) continue;
      for (const char* key : keys) {
        const auto value = item.find(key);
        if (value != item.end() && !value->is_number_unsigned())
          ThrowUserError(where, std::string(list) + "[" + std::to_string(i) + "]." + key,
                         "expected a whole number >= 0, got " + DescribeJson(*value));
      }
    }
  }
}

// The extensions phos reads: a file that requires any other is refused,
// since it would be drawn wrong (glTF 2.0 spec, 3.12: a loader must not load
// an asset whose required extension it does not support).
constexpr const char* kSupportedGltfExtensions[] = {"KHR_lights_punctual", "KHR_texture_transform"};

// The glTF's model through tinygltf, with its limits checked.
// read: null, or where to add the files the glTF led to (external buffers, images).
tinygltf::Model ReadGltfModel(std::string_view data, bool binary, const std::filesystem::path& base_dir,
                              const std::string& name, const std::string& where,
                              std::vector<std::filesystem::path>* read = nullptr) {
  if (data.size() > kMaxInputFileBytes)
    ThrowUserError(where, "",
                   "glTF '" + name + "' is more than the limit of " + std::to_string(kMaxInputFileBytes) + " bytes");
  // tinygltf turns JSON values (extras, extensions) into its own by recursion,
  // one stack frame per level: 20,000 nested arrays overflowed the stack.
  // A .glb's JSON is its first chunk (glTF 2.0, 4.4.3: a 12-byte header, then
  // the chunk's length and type); a malformed header is left to tinygltf.
  std::string_view json = data;
  if (binary) {
    std::uint32_t chunk_bytes = 0;
    if (data.size() >= 20) std::memcpy(&chunk_bytes, data.data() + 12, 4);
    json = data.size() >= 20 ? data.substr(20, chunk_bytes) : std::string_view();
  }
  CheckJsonNesting(json, where + " (" + name + ")");
  CheckGltfUnsignedFields(json, where + " (" + name + ")");
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks({&GltfFileExists, &GltfExpandPath, &GltfReadFile, &GltfNoWrite, read});
  loader.SetImageLoader(&GltfKeepDataUriImage, nullptr);
  tinygltf::Model model;
  std::string error, warning;
  const bool ok = binary ? loader.LoadBinaryFromMemory(&model, &error, &warning,
                                                       reinterpret_cast<const unsigned char*>(data.data()),
                                                       static_cast<unsigned int>(data.size()), base_dir.string())
                         : loader.LoadASCIIFromString(&model, &error, &warning, data.data(),
                                                      static_cast<unsigned int>(data.size()), base_dir.string());
  if (!ok) ThrowUserError(where, "", "cannot read glTF '" + name + "': " + OneLine(error));
  for (const std::string& extension : model.extensionsRequired)
    if (std::find(std::begin(kSupportedGltfExtensions), std::end(kSupportedGltfExtensions), extension) ==
        std::end(kSupportedGltfExtensions))
      ThrowUserError(where + " (" + name + ")", "extensionsRequired",
                     "the file requires the extension '" + extension +
                         "', which phos does not read (it reads KHR_lights_punctual and KHR_texture_transform)");
  return model;
}

// Calls f(node, world transform) for every node instance of the default
// scene (or of every root node when there is no scene), parents first.
void VisitGltfNodes(const tinygltf::Model& model, const std::string& file_where,
                    const std::function<void(const tinygltf::Node&, const Eigen::Affine3d&)>& f) {
  std::size_t instances = 0;
  std::function<void(int, const Eigen::Affine3d&, int)> visit = [&](int index, const Eigen::Affine3d& parent,
                                                                    int depth) {
    if (index < 0 || index >= static_cast<int>(model.nodes.size()) || depth > 64)
      ThrowUserError(file_where, "nodes", "node index out of range or a cycle");
    // A node graph that shares children multiplies its instances (2^40 ran out of memory).
    if (++instances > kMaxGltfInstances)
      ThrowUserError(
          file_where, "nodes",
          "the node graph has more than the limit of " + std::to_string(kMaxGltfInstances) + " node instances");
    const tinygltf::Node& node = model.nodes[index];
    const Eigen::Affine3d transform = parent * NodeTransform(node);
    f(node, transform);
    for (int child : node.children) visit(child, transform, depth + 1);
  };
  if (!model.scenes.empty()) {
    const int scene = model.defaultScene >= 0 ? model.defaultScene : 0;
    if (scene >= static_cast<int>(model.scenes.size()))
      ThrowUserError(file_where, "scene", "the default scene " + std::to_string(scene) + " does not exist");
    for (int node : model.scenes[scene].nodes) visit(node, Eigen::Affine3d::Identity(), 0);
  } else {
    for (std::size_t node = 0; node < model.nodes.size(); ++node)
      visit(static_cast<int>(node), Eigen::Affine3d::Identity(), 0);
  }
}

Mesh ParseGltf(std::string_view data, bool binary, const std::filesystem::path& base_dir, const std::string& name,
               const std::string& group, const std::string& where) {
  std::vector<std::filesystem::path> read;
  const tinygltf::Model model = ReadGltfModel(data, binary, base_dir, name, where, &read);
  Mesh mesh;
  mesh.source = name + (group.empty() ? "" : "#" + group);
  mesh.also_read = std::move(read);
  bool found = group.empty();
  bool all_uv = true;
  const std::string file_where = where + " (" + name + ")";
  bool first_primitive = true;
  VisitGltfNodes(model, file_where, [&](const tinygltf::Node& node, const Eigen::Affine3d& transform) {
    if (node.mesh >= 0 && node.mesh < static_cast<int>(model.meshes.size()) &&
        (group.empty() || model.meshes[node.mesh].name == group)) {
      found = true;
      for (const tinygltf::Primitive& primitive : model.meshes[node.mesh].primitives) {
        if (primitive.mode != TINYGLTF_MODE_TRIANGLES && primitive.mode != -1)
          continue;  // points and lines carry no surface
        MergeBaseColour(mesh, GltfBaseColour(model, primitive.material, base_dir, file_where), first_primitive);
        NoteUnreadGltfMaterial(model, primitive.material, mesh.unread_material);
        if (first_primitive) {
          mesh.gloss = GltfGloss(model, primitive.material, file_where);
          mesh.gloss_texture = GltfGlossTexture(model, primitive.material, base_dir, file_where);
        }
        first_primitive = false;
        const auto position = primitive.attributes.find("POSITION");
        if (position == primitive.attributes.end())
          ThrowUserError(file_where, "meshes", "a primitive without POSITION");
        const std::vector<float> p = ReadAccessor<float>(
            model, position->second, 3, kMaxMeshVertices - mesh.positions.size(), file_where, "POSITION");
        const int base = static_cast<int>(mesh.positions.size());
        const int count = static_cast<int>(p.size() / 3);
        for (int i = 0; i < count; ++i)
          mesh.positions.push_back((transform * Vec3(p[3 * i], p[3 * i + 1], p[3 * i + 2])).cast<float>());
        const auto texcoord = primitive.attributes.find("TEXCOORD_0");
        const int uv_base = static_cast<int>(mesh.uvs.size());
        bool with_uv = texcoord != primitive.attributes.end();
        if (with_uv) {
          const std::vector<float> uv = ReadAccessor<float>(
              model, texcoord->second, 2, kMaxMeshVertices - mesh.uvs.size(), file_where, "TEXCOORD_0");
          with_uv = static_cast<int>(uv.size() / 2) == count;
          for (int i = 0; with_uv && i < count; ++i) mesh.uvs.emplace_back(uv[2 * i], uv[2 * i + 1]);
        }
        all_uv = all_uv && with_uv;
        std::vector<int> indices;
        if (primitive.indices >= 0) {
          indices = ReadAccessor<int>(model, primitive.indices, 1, 3 * (kMaxMeshTriangles - mesh.triangles.size()),
                                      file_where, "indices");
        } else {
          CheckCounts(0, mesh.triangles.size() + static_cast<std::size_t>(count) / 3, file_where, name);
          for (int i = 0; i < count; ++i) indices.push_back(i);
        }
        for (std::size_t i = 0; i + 2 < indices.size(); i += 3) {
          Eigen::Vector3i t(indices[i], indices[i + 1], indices[i + 2]);
          if (t.minCoeff() < 0 || t.maxCoeff() >= count)
            ThrowUserError(file_where, "indices", "vertex index out of range");
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
  });
  if (!found) ThrowUserError(where, "", "glTF '" + name + "' has no mesh named '" + group + "'");
  if (!all_uv || mesh.uv_triangles.size() != mesh.triangles.size()) {  // a partial UV map is no map
    mesh.uvs.clear();
    mesh.uv_triangles.clear();
  }
  return mesh;
}

}  // namespace

bool UvMapIsOneToOne(const Mesh& mesh) {
  if (!mesh.has_uvs()) return false;
  constexpr float kSlack = 1e-4f;  // a unwrap's float rounding at the square's edges
  for (const Eigen::Vector2f& uv : mesh.uvs)
    if (!(uv.minCoeff() >= -kSlack && uv.maxCoeff() <= 1 + kSlack)) return false;
  // Cell centres strictly inside each triangle (either orientation: a
  // mirrored island is still one-to-one), counted per cell.
  constexpr int kGrid = 512;
  std::vector<std::uint8_t> covers(std::size_t(kGrid) * kGrid, 0);
  std::size_t covered = 0, overlapping = 0;
  for (const Eigen::Vector3i& t : mesh.uv_triangles) {
    const Eigen::Vector2f a = mesh.uvs[t[0]] * kGrid, b = mesh.uvs[t[1]] * kGrid, c = mesh.uvs[t[2]] * kGrid;
    const float area2 = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    if (!(std::abs(area2) > 1e-9f)) continue;
    const float sign = area2 > 0 ? 1.0f : -1.0f, inside = 1e-5f * std::abs(area2);
    auto edge = [&](const Eigen::Vector2f& p, const Eigen::Vector2f& q, const Eigen::Vector2f& r) {
      return sign * ((q - p).x() * (r - p).y() - (q - p).y() * (r - p).x());
    };
    const Eigen::Vector2f lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
    const int x0 = std::clamp(static_cast<int>(std::floor(lo.x())), 0, kGrid - 1),
              x1 = std::clamp(static_cast<int>(std::ceil(hi.x())), 0, kGrid - 1);
    const int y0 = std::clamp(static_cast<int>(std::floor(lo.y())), 0, kGrid - 1),
              y1 = std::clamp(static_cast<int>(std::ceil(hi.y())), 0, kGrid - 1);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2f q(x + 0.5f, y + 0.5f);
        if (edge(a, b, q) > inside && edge(b, c, q) > inside && edge(c, a, q) > inside) {
          std::uint8_t& n = covers[std::size_t(y) * kGrid + x];
          if (n == 0) ++covered;
          if (n == 1) ++overlapping;
          n = static_cast<std::uint8_t>(std::min(2, n + 1));
        }
      }
  }
  return overlapping * 1000 <= covered;
}

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
  std::vector<Vec3> p = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& v : p) v.normalize();
  std::vector<Eigen::Vector3i> faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                        {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                        {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                        {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
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

Mesh ParseMesh(std::string_view data, const std::string& format, const std::filesystem::path& base_dir,
               const std::string& name, const std::string& group, const std::string& where) {
  Mesh mesh;
  if (format == ".obj")
    mesh = ParseObj(data, base_dir, name, group, where);
  else if (format == ".gltf" || format == ".glb")
    mesh = ParseGltf(data, format == ".glb", base_dir, name, group, where);
  else
    ThrowUserError(where, "", "unknown mesh format '" + format + "' (.obj, .gltf, .glb)");
  for (const Eigen::Vector3f& v : mesh.positions) {
    if (!v.allFinite()) ThrowUserError(where, "", "mesh '" + name + "' has a vertex that is not finite");
    if (v.cwiseAbs().maxCoeff() > kMaxCoordinate_m)
      ThrowUserError(where, "",
                     "mesh '" + name + "' has a vertex beyond the limit of " + FormatDouble(kMaxCoordinate_m) +
                         " m from the origin on an axis");
  }
  for (const Eigen::Vector2f& uv : mesh.uvs)
    if (!uv.allFinite()) ThrowUserError(where, "", "mesh '" + name + "' has a texture coordinate that is not finite");
  return mesh;
}

std::vector<PunctualLight> ParseGltfLights(std::string_view data, bool binary, const std::filesystem::path& base_dir,
                                           const std::string& name, const std::string& where) {
  const tinygltf::Model model = ReadGltfModel(data, binary, base_dir, name, where);
  const std::string file_where = where + " (" + name + ")";
  std::vector<PunctualLight> lights;
  VisitGltfNodes(model, file_where, [&](const tinygltf::Node& node, const Eigen::Affine3d& transform) {
    const auto extension = node.extensions.find("KHR_lights_punctual");
    if (extension == node.extensions.end() || !extension->second.Has("light")) return;
    const tinygltf::Value& index_value = extension->second.Get("light");
    const int index = index_value.IsInt() ? index_value.GetNumberAsInt() : -1;
    if (index < 0 || index >= static_cast<int>(model.lights.size()))
      ThrowUserError(file_where, "nodes", "a KHR_lights_punctual light index out of range");
    const tinygltf::Light& source = model.lights[index];
    PunctualLight punctual;
    Light& light = punctual.light;
    light.name = source.name.empty() ? name + " light " + std::to_string(lights.size()) : source.name;
    // A light shines down its node's -z axis from its node's origin.
    light.position = transform * Vec3::Zero();
    light.direction = (transform.linear() * Vec3(0, 0, -1)).normalized();
    if (!light.position.allFinite() || !light.direction.allFinite() ||
        light.position.cwiseAbs().maxCoeff() > kMaxCoordinate_m)
      ThrowUserError(file_where, "lights", "light '" + light.name + "' has no finite place or direction");
    if (source.type == "point") {
      light.kind = Light::Kind::kPoint;
    } else if (source.type == "directional") {
      light.kind = Light::Kind::kDirectional;
    } else if (source.type == "spot") {
      light.kind = Light::Kind::kSpot;
      const double inner = source.spot.innerConeAngle, outer = source.spot.outerConeAngle;
      if (!(inner >= 0 && inner < outer && outer <= kPi / 2))
        ThrowUserError(file_where, "lights",
                       "spot '" + light.name + "' needs 0 <= innerConeAngle < outerConeAngle <= pi / 2");
      light.inner_cone_deg = inner * 180 / kPi;
      light.outer_cone_deg = outer * 180 / kPi;
    } else {
      ThrowUserError(file_where, "lights", "light '" + light.name + "' has an unknown type '" + source.type + "'");
    }
    if (!(source.intensity >= 0 && source.intensity <= kMaxIrradiance))
      ThrowUserError(file_where, "lights",
                     "light '" + light.name + "' has an intensity outside [0, " + FormatDouble(kMaxIrradiance) + "]");
    light.intensity = source.intensity;
    // KHR_lights_punctual: range, when defined, is > 0 and bounds a point or
    // spot light's reach; tinygltf reads an absent one as 0.
    if (!(source.range >= 0 && source.range <= kMaxCoordinate_m))
      ThrowUserError(file_where, "lights",
                     "light '" + light.name + "' has a range outside (0, " + FormatDouble(kMaxCoordinate_m) + "] m");
    if (light.positional()) light.range_m = source.range;
    if (source.color.size() == 3) punctual.colour = Eigen::Vector3d(source.color[0], source.color[1], source.color[2]);
    if (!(punctual.colour.array() >= 0).all() || !(punctual.colour.array() <= 1).all())
      ThrowUserError(file_where, "lights", "light '" + light.name + "' has a color outside [0, 1]");
    lights.push_back(std::move(punctual));
  });
  return lights;
}

std::vector<PunctualLight> LoadGltfLights(const std::filesystem::path& path, const std::string& where) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (extension != ".gltf" && extension != ".glb")
    ThrowUserError(where, "", "lights come from glTF files only (.gltf, .glb), not '" + path.string() + "'");
  std::string data;
  try {
    data = ReadFileText(path);
  } catch (const UserError& e) {
    ThrowUserError(where, "", std::string("glTF ") + e.what());
  }
  return ParseGltfLights(data, extension == ".glb", path.parent_path(), path.string(), where);
}

Mesh LoadMesh(const std::filesystem::path& path, const std::string& group, const std::string& where) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) ThrowUserError(where, "", "mesh file '" + path.string() + "' does not exist");
  if (extension != ".obj" && extension != ".gltf" && extension != ".glb")
    ThrowUserError(where, "", "unknown mesh format '" + extension + "' (.obj, .gltf, .glb)");
  std::string data;
  try {
    data = ReadFileText(path);
  } catch (const UserError& e) {
    ThrowUserError(where, "", std::string("mesh ") + e.what());
  }
  Mesh mesh = ParseMesh(data, extension, path.parent_path(), path.string(), group, where);
  mesh.file = path;
  return mesh;
}

}  // namespace phos::render
