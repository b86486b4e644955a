#pragma once
// A scene (`phos.scene/1`, docs/formats.md): meshes with materials, lights
// with spectra and time schedules, rigid animation, a camera and a time range.
// Everything spectral lives on one band grid, the scene's, which every
// phosphor material must share: the coupled solver then needs no resampling.
//
// Units: metres, seconds, nanometres. A relative scene (the default) gives
// irradiance in the units the materials' ke were fitted in (Table 8.1:
// normalized irradiance), so a point light's intensity is irradiance * m^2
// at normal incidence, and a directional light's is irradiance at normal
// incidence. A physical scene ("units": "physical", docs/formats.md) holds
// band irradiance in W/m², intensity in W/sr and radiance in W/(sr m²), its
// lights given in W or in lm, cd, lx (light_units.h), and only physical
// materials.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json_fwd.hpp>

#include "phos/model/material.h"
#include "phos/model/spectral.h"
#include "phos/util/math.h"

namespace phos::render {

struct PhosphorMap;  // phosphor_map.h

using Vec3 = Eigen::Vector3d;

// Limits of what a scene and its meshes may hold, checked at load time and
// before anything is allocated (docs/fuzzing.md, "Limits"). Coordinates go
// into Embree's float BVH, whose assertions abort on values like 1e308; the
// counts bound memory and time. A message that refuses a value names its limit.
inline constexpr double kMaxCoordinate_m = 1e6;  // |x| of every position, size, bound, vertex (after transforms)
inline constexpr double kMinScale = 1e-6, kMaxScale = 1e6;              // a transform's scale
inline constexpr double kMaxTime_s = 1e9;                               // |t| of every time in a scene
inline constexpr double kMaxLevel = 1e6;                                // a light's or the sky's schedule level
inline constexpr double kMaxDensity = 1e6;                              // a volume's density
inline constexpr std::size_t kMaxVoxels = std::size_t{1} << 24;         // over all volumes of a scene (16.8 million)
inline constexpr double kMaxPuffEvaluations = 1e8;                      // voxels x puffs of a procedural density
inline constexpr std::size_t kMaxPixels = std::size_t{1} << 26;         // width x height (67 million, 8192 x 8192)
inline constexpr std::size_t kMaxMeshVertices = std::size_t{1} << 24;   // per mesh file (16.8 million)
inline constexpr std::size_t kMaxMeshTriangles = std::size_t{1} << 24;  // per mesh file
inline constexpr std::size_t kMaxGltfInstances = std::size_t{1} << 16;  // node visits of a glTF scene graph (65536)
inline constexpr std::size_t kMaxObjects = 1024;                        // objects of a scene
inline constexpr std::size_t kMaxSceneTriangles = std::size_t{1}
                                                  << 24;  // over all objects (a mesh used twice counts twice)
inline constexpr std::size_t kMaxLights = 4096;           // lights of a scene, emitting objects included
// Texels over all phosphorescent objects (33.5 million; a UV map's
// resolution^2 each), and texels x lights (268 million: the coupled solver
// keeps each light's irradiance per texel, 4 bytes each). 4 quads of 1e6 m
// at texel_size_m 1e-3 asked for 134 million texels, 6.4 GiB.
inline constexpr std::size_t kMaxTexels = std::size_t{1} << 25;
inline constexpr std::size_t kMaxTexelLights = std::size_t{1} << 28;

// An object's glossiness (render/bsdf.h): metallic in [0, 1], roughness in
// [0.02, 1] (glTF's pbrMetallicRoughness factors).
struct Gloss {
  float metallic = 0.0f;
  float roughness = 1.0f;
};
inline constexpr float kMinRoughness = 0.02f;

// How a texture is read past [0, 1] in u (s) and v (t): a glTF sampler's
// wrapS and wrapT (REPEAT, the default, CLAMP_TO_EDGE, MIRRORED_REPEAT); an
// OBJ/MTL map_Kd repeats unless it says -clamp on.
enum class TextureWrap { kRepeat, kClampToEdge, kMirroredRepeat };
struct TextureWraps {
  TextureWrap s = TextureWrap::kRepeat, t = TextureWrap::kRepeat;
  bool operator==(const TextureWraps&) const = default;
};

// How a texture's texels are filtered: a glTF sampler's magFilter and
// minFilter (glTF 2.0, 5.26). OpenImageIO's TextureSystem has one
// interpolation for magnified and minified lookups, so magFilter picks it
// (NEAREST: the closest texel, a pixel-art sign stays crisp; LINEAR or none:
// bilinear) and minFilter picks the MIP levels (NEAREST or LINEAR: none,
// the full image only; *_MIPMAP_NEAREST: the one nearest level;
// *_MIPMAP_LINEAR or none: trilinear, between two levels).
enum class TexelInterpolation { kBilinear, kClosest };
enum class MipLevels { kTrilinear, kNearestLevel, kNone };
struct TextureFilter {
  TexelInterpolation interpolation = TexelInterpolation::kBilinear;
  MipLevels mip = MipLevels::kTrilinear;
  bool operator==(const TextureFilter&) const = default;
};

// Where a texture is read, given the mesh's UV: glTF's KHR_texture_transform
// (uv' = T R S uv: scaled, then rotated, then offset; the rotation in
// radians, counter-clockwise in glTF's UV space, where v runs down). The
// identity for OBJ/MTL and for glTF without the extension.
struct UvTransform {
  Eigen::Matrix2f linear = Eigen::Matrix2f::Identity();  // R S
  Eigen::Vector2f offset = Eigen::Vector2f::Zero();
  Eigen::Vector2f operator()(const Eigen::Vector2f& uv) const { return linear * uv + offset; }
  bool operator==(const UvTransform&) const = default;
};

// An image inside a glTF file (a data: URI, or a bufferView of a .glb): its
// bytes, which a render writes to a file of its own in the user's cache
// before OpenImageIO opens it (surface_textures.h).
struct EmbeddedImage {
  std::string bytes;
  std::string extension;  // ".png" or ".jpg", from the image's mimeType
};

// A texture image a mesh file names, and how it is read: what a base colour
// and a gloss texture share.
struct TextureSource {
  std::filesystem::path texture;                  // empty: none; embedded: the glTF's images[j], for messages
  std::shared_ptr<const EmbeddedImage> embedded;  // null: the texture (if any) is a file of its own
  std::string field;                              // where the file says so, for messages
  TextureWraps wraps;
  TextureFilter filter;
  UvTransform uv_transform;
  // The same image (the same file, or embedded images of the same bytes),
  // read the same way; `field`, words for messages, aside.
  bool SameReading(const TextureSource& other) const {
    const bool same_image = embedded || other.embedded
                                ? embedded && other.embedded && embedded->bytes == other.embedded->bytes
                                : texture == other.texture;
    return same_image && wraps == other.wraps && filter == other.filter && uv_transform == other.uv_transform;
  }
};

// A glTF metallicRoughnessTexture (glTF 2.0, material.pbrMetallicRoughness):
// roughness in its G channel and metallic in its B channel, linear (not
// sRGB), each times the object's Gloss factor at every hit.
struct GlossTexture : TextureSource {};

// The base colour a mesh file declares (glTF pbrMetallicRoughness
// baseColorFactor and baseColorTexture, OBJ/MTL Kd and map_Kd): a linear RGB
// factor, times the texture's sRGB-decoded texel when there is one.
struct BaseColour : TextureSource {
  Eigen::Vector3f factor = Eigen::Vector3f::Ones();  // linear RGB in [0, 1]
  bool v_up = false;                                 // OBJ: v = 0 is the image's bottom row; glTF: its top row
  bool operator==(const BaseColour& other) const {
    return factor == other.factor && v_up == other.v_up && SameReading(other);
  }
};

// A triangle mesh in object space.
struct Mesh {
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3i> triangles;
  // The mesh's own UV map, if it has one: per triangle, indices into uvs.
  std::vector<Eigen::Vector2f> uvs;
  std::vector<Eigen::Vector3i> uv_triangles;
  std::string source;          // file it came from, or the built-in shape (for messages: "file.obj#group")
  std::filesystem::path file;  // the file LoadMesh read (empty: a built-in shape or parsed text)
  // The other files it led to: an OBJ's .mtl, a glTF's external buffers and
  // images (a render range's inputs include their content).
  std::vector<std::filesystem::path> also_read;
  // The base colour of the mesh's material, when the file gives one; a mesh
  // whose triangles have different ones keeps none and says so.
  std::optional<BaseColour> base_colour;
  std::string base_colours_differ;  // non-empty: why no single base colour was kept
  bool v_up = false;                // OBJ: v = 0 is an image's bottom row; glTF and built-in shapes: its top row
  std::optional<Gloss> gloss;       // glTF: its first material's metallic-roughness, when glossy
  std::optional<GlossTexture> gloss_texture;  // glTF: its first material's metallicRoughnessTexture
  // glTF: the parts of its materials phos does not draw, by field
  // ("materials[0].normalTexture"); phos render warns of them.
  std::vector<std::string> unread_material;
  bool has_uvs() const { return !uv_triangles.empty() && uv_triangles.size() == triangles.size(); }
};

// Rigid motion: keyframes of translation and rotation, linear in translation
// and spherical-linear in rotation, held constant outside the keyframes.
struct RigidKey {
  double t_s = 0.0;
  Vec3 translate = Vec3::Zero();
  Eigen::Quaterniond rotate = Eigen::Quaterniond::Identity();
  double scale = 1.0;
};
struct RigidMotion {
  std::vector<RigidKey> keys;  // sorted by t_s; empty = identity
  Eigen::Affine3d At(double t_s) const;
  bool Moves() const;  // more than one distinct key
  // Times in [t0, t1] where the motion changes (keyframes): the solver does not
  // step across a change of velocity.
  bool MovesBetween(double t0_s, double t1_s) const;
};

// Initial state of a phosphor's texels at the scene's start time.
struct InitialState {
  enum class Kind { kZero, kEquilibrium, kUniform } kind = Kind::kZero;
  double r0 = 0.0;  // kUniform: every state of every texel
};

// A translucent material (subsurface.h): absorption and reduced scattering
// per band, relative index of refraction.
struct Subsurface {
  std::vector<double> sigma_a_per_m, sigma_s_prime_per_m;  // per band
  double eta = 1.3;
};

struct Object {
  std::string name;
  std::shared_ptr<const Mesh> mesh;
  RigidMotion motion;
  std::vector<double> albedo;  // per band, diffuse reflectance in [0, 1]
  // An albedo that varies across the surface (Sec. 8.5: "parameters per
  // material or, if spatial variation is desired, in textures"): the mesh's
  // base colour texture, looked up at each hit through its UV map. `albedo`
  // then holds the factor alone. Unset: the albedo is `albedo` everywhere.
  std::optional<BaseColour> albedo_texture;
  std::shared_ptr<const Material> phosphor;  // null: not phosphorescent (carries no state)
  // Glow paint on a base (a watch's hands, a sign's letters): the first
  // channel of this image over the mesh's UV map, in [0, 1], is the share
  // of each texel the phosphor covers. Texels where it is 0 carry no state
  // and glow not at all; the others glow by their share. Unset: everywhere.
  std::optional<std::filesystem::path> phosphor_mask;
  // A phosphor measured across a surface (phosphor_map.h): per texel, the
  // map's rates, and its amplitudes as a share of the material's level.
  // Pixels without a decay carry no state, as a mask's bare texels. Null:
  // the material everywhere.
  std::shared_ptr<const PhosphorMap> phosphor_map;
  std::string phosphor_path;
  bool unknown_ke_as_zero = false;  // the scene's explicit assumption, never phos's guess
  InitialState initial;
  // A phosphor coated on both faces of a thin sheet (a sticker in a window):
  // each texel's one state is charged by the irradiance on either face and
  // glows from both. false: the front face only (Sec. 8.3.4's layer on one
  // side), the side the triangles' counter-clockwise winding faces.
  bool two_sided = false;
  // Glossy (glTF metallic-roughness, render/bsdf.h): a GGX lobe over the
  // diffuse base. Unset: Lambertian, as before.
  std::optional<Gloss> gloss;
  // Gloss that varies across the surface: the texture's roughness and
  // metallic times gloss's factors at each hit (set only with gloss).
  std::optional<GlossTexture> gloss_texture;
  double texel_size_m = 0.0;  // edge of the automatic atlas's texels (0: scene default)
  // Texels: "auto" (per-triangle atlas), "uv" (the mesh's UV map) or "" (the
  // UV map when the mesh has one, else auto). uv_resolution: texels per UV
  // unit along each axis (0: from the texel size and the surface area).
  std::string texels;
  int uv_resolution = 0;
  // Translucent: the dss transport scatters light beneath the surface with
  // the dipole; albedo is then the dipole's total diffuse reflectance.
  std::optional<Subsurface> subsurface;
};

// Piecewise-constant level of a light: level of the last key at or before t.
struct LightSchedule {
  struct Key {
    double t_s;
    double level;
  };
  std::vector<Key> keys;  // sorted; empty = always on at 1
  double LevelAt(double t_s) const;
  // The switch times strictly inside (t0, t1).
  std::vector<double> ChangesBetween(double t0_s, double t1_s) const;
};

struct Light {
  // kSheet: a laser sheet (Fig. 8.17): a directional beam travelling along
  // `direction`, confined to the slab of sheet_thickness_m about the plane
  // with normal sheet_normal through PositionAt(t); a `path` sweeps it.
  // kQuad, kDisk: an area light, a flat Lambertian emitter of radiance
  // E_per_band (per steradian) on the side `normal` faces, centred at
  // PositionAt(t): a quad of width_m along `tangent` by height_m along
  // normal x tangent, or a disk of radius_m. It has no body: it casts no
  // shadow, and only the camera and the path tracer's bounces see it.
  // kSpot: a point light shining along `direction` within a cone, its
  // intensity falling off between inner_cone_deg and outer_cone_deg as
  // glTF's KHR_lights_punctual spot does.
  // kMesh: an emissive object (Object::emission): the front of every
  // triangle of object `emitter_object` emits radiance E_per_band. Unlike a
  // quad or disk it has a body: the object shadows and is hit as any other.
  enum class Kind { kPoint, kDirectional, kSheet, kQuad, kDisk, kSpot, kMesh } kind = Kind::kPoint;
  std::string name;
  // Band integrals of spectrum * intensity: a point or spot light's intensity
  // (irradiance * m^2), a directional or sheet light's irradiance, an area
  // light's radiance (irradiance / sr: a wide light close by gives pi times it).
  std::vector<double> E_per_band;
  double intensity = 1.0;
  LightSchedule schedule;
  RigidMotion motion;                              // a point light moves with the translation of its keys
  Vec3 position = Vec3::Zero();                    // point: object space of `motion`
  Vec3 direction = Vec3(0, -1, 0);                 // directional, sheet: the direction light travels; spot: its axis
  double inner_cone_deg = 0, outer_cone_deg = 45;  // spot: half-angles from the axis, inner < outer <= 90
  Vec3 sheet_normal = Vec3(1, 0, 0);
  double sheet_thickness_m = 0;
  // Area lights.
  Vec3 normal = Vec3(0, -1, 0);  // unit: the side that emits
  Vec3 tangent = Vec3(1, 0, 0);  // quad: unit, perpendicular to normal, along its width
  double width_m = 0, height_m = 0, radius_m = 0;
  // Shadow rays per shaded point (texel or pixel) for its soft shadow,
  // stratified over the light (geometry.h, UnitIrradiance).
  int samples = 16;
  int emitter_object = -1;  // kMesh: index into Scene::objects
  // Point, spot: glTF KHR_lights_punctual's range, the distance where the
  // light is cut off smoothly by the window (1 - (d / range)^4) clamped to
  // [0, 1]; 0: none, the inverse square to infinity.
  double range_m = 0;
  bool area() const { return kind == Kind::kQuad || kind == Kind::kDisk || kind == Kind::kMesh; }
  // At a position, its irradiance falling with the square of the distance.
  bool positional() const { return kind == Kind::kPoint || kind == Kind::kSpot; }
  Vec3 PositionAt(double t_s) const { return motion.At(t_s) * position; }
  Vec3 DirectionAt(double t_s) const { return (motion.At(t_s).linear() * direction).normalized(); }
};

// A participating medium on a regular grid (docs/render.md, "Media"):
// density per voxel (trilinear between voxel centres), extinction
// sigma_t = density * sigma_t_per_m, single-scattering albedo per band and a
// Henyey-Greenstein phase function. A phosphorescent medium (dust, a glowing
// liquid) carries one rate-equation state per voxel where density > 0: its
// particles charge under the light that reaches them and glow with radiance
// Lp, so a ray gains sigma_t Lp per metre (an optically thick cloud looks
// like a phosphor surface in the same state).
struct Volume {
  std::string name;
  Vec3 min_m = Vec3::Zero(), max_m = Vec3::Ones();
  int nx = 1, ny = 1, nz = 1;
  std::vector<float> density;  // [(z * ny + y) * nx + x], >= 0
  double sigma_t_per_m = 1.0;
  std::vector<double> albedo;  // per band, single-scattering albedo in [0, 1]
  double g = 0.0;              // Henyey-Greenstein asymmetry in (-1, 1)
  std::shared_ptr<const Material> phosphor;
  std::string phosphor_path;
  bool unknown_ke_as_zero = false;
  InitialState initial;
  std::size_t voxel_count() const { return density.size(); }
  Vec3 voxel_size_m() const { return (max_m - min_m).cwiseQuotient(Vec3(nx, ny, nz)); }
};

// A sky: radiance L(w) = L_per_band (1 + gradient w_y) from every direction
// no surface blocks (a sign at dusk, a painted wall by a window); its level
// follows a schedule like a light's. The unoccluded irradiance on a surface
// with normal n is L_per_band (pi + 2 pi / 3 gradient n_y).
struct Environment {
  std::vector<double> L_per_band;
  double gradient = 0.0;  // in [-1, 1]: brighter overhead when > 0
  LightSchedule schedule;
  float Shape(float w_y) const { return static_cast<float>(1 + gradient * w_y); }
  double UnoccludedIrradiance(double n_y) const { return kPi * (1 + 2.0 / 3.0 * gradient * n_y); }
};

struct CameraKey {
  double t_s = 0.0;
  Vec3 position = Vec3(0, 0, 5);
  Vec3 look_at = Vec3::Zero();
};
struct Camera {
  std::vector<CameraKey> keys;  // at least one
  Vec3 up = Vec3(0, 1, 0);
  double fov_deg = 45.0;  // vertical
  int width = 320, height = 240;
  double exposure = 1.0;  // scale applied before tone mapping (PNG only)
  // "exposure": "auto": chosen once per sequence from its frames after dark
  // (render/exposure.h); `exposure` is then unused.
  bool exposure_auto = false;
  CameraKey At(double t_s) const;
};

struct RenderSettings {
  int spp = 16;        // path tracer samples per pixel
  int max_depth = 8;   // path tracer bounces
  int direct_spp = 1;  // direct transport: jittered samples per pixel
  unsigned seed = 1;
  double max_step_s = 0.0;  // coupled solver's longest step while something moves (0: 1/fps)
  // The phosphors' own glow charges the other phosphors (docs/render.md, "Glow
  // on glow"). Costs steps of max_step_s in the dark too, since darkness is
  // then no longer dark.
  bool phosphor_irradiance = false;
};

struct Scene {
  std::string source;  // the file
  std::string name;
  // "units": relative (the default) or physical: then band radiances are in
  // W/(sr m²) and every phosphor is a physical material.
  Units units = Units::kRelative;
  SpectralGrid bands;
  std::vector<Object> objects;
  std::vector<Light> lights;
  std::vector<Volume> volumes;
  std::optional<Environment> environment;
  Camera camera;
  double start_s = 0.0, end_s = 10.0, fps = 1.0;
  double texel_size_m = 0.0;  // default texel edge (0: scene diagonal / 200)
  RenderSettings settings;

  // The frame times from start_s to end_s at fps.
  std::vector<double> FrameTimes() const;
  bool HasPhosphors() const;
  // Whether a light or the sky shines at t_s (level > 0). Frames where none
  // does are after dark: only the glow is seen, and "exposure": "auto" meters them.
  bool AnyLightOnAt(double t_s) const;
};

// The end of the error for a phosphor whose ke is unknown in a band the
// scene's lights reach: what a scene can do about it.
inline constexpr const char* kUnknownKeRemedy =
    "measure ke there, or take it as not charging there: phos render --unknown-ke zero (every phosphor), or say "
    "\"unknown_ke\": \"zero\" on the object (docs/render.md); or keep the lights out of that band";

// What is wrong when a phosphor material's bands_nm are not the scene's:
// "[...] nm differ from the scene's [...] nm; ..." with the two ways out
// ("" when they agree). The renderer keeps one
// grid for every spectrum it holds.
std::string BandGridMismatch(const SpectralGrid& material_bands, const SpectralGrid& scene_bands);

// What is wrong when a phosphor material (read from `file`) is not in the
// scene's units, relative or physical ("" when they agree): one line naming
// the file, both units and the way out.
std::string UnitsMismatch(const Material& material, const std::string& file, Units scene_units);

// Loads and validates a scene. Paths inside it are relative to its folder.
// Any problem is a UserError naming the file and the field.
Scene LoadScene(const std::filesystem::path& path);
Scene SceneFromJson(const nlohmann::json& json, const std::filesystem::path& base_dir, const std::string& source);

// Whether a mesh's UV map can hold its texels (docs/render.md, "The
// coupled solver"): every UV in [0, 1] and no two triangles over the same
// place of UV space (at most 0.1% of the covered cells of a 512 x 512 grid,
// for the rounding of a real unwrap). A map that tiles a texture (UVs
// past 1, as a glTF's repeating sampler wants) or reuses one region of it
// on several faces would give one texel's state to several places.
bool UvMapIsOneToOne(const Mesh& mesh);

// The texels TexelAtlas lays out on each object (0 where not a phosphor), as
// the atlas computes them at the scene's start, without allocating any: of a
// UV atlas its resolution^2 cells. CheckTexelLimits refuses a scene past
// kMaxTexels or kMaxTexelLights in one line naming the largest object's
// texel_size_m (or uv_resolution); the loader and TexelAtlas both call it, so
// render --check refuses what the render would.
std::vector<std::size_t> CountTexels(const Scene& scene);
void CheckTexelLimits(const Scene& scene);

// Built-in shapes (also usable from scene files as {"shape": ...}).
Mesh MakeQuad(double size_x, double size_z);                    // in the y = 0 plane, normal +y
Mesh MakeBox(const Vec3& size, bool inward);                    // centred at the origin
Mesh MakeSphere(double radius, int subdivisions, bool inward);  // icosphere
// Loads OBJ (tinyobjloader) or glTF 2.0 (.gltf/.glb, tinygltf), triangulated,
// with node transforms applied (glTF). A non-empty `group` keeps only the OBJ
// group (o/g) or glTF mesh of that name. Problems are UserErrors naming
// `where`, one line each. The file, a glTF's external buffers and an OBJ's
// .mtl are read as regular files of at most kMaxInputFileBytes; the base
// colour (Mesh::base_colour) comes from the glTF material or the MTL's Kd
// and map_Kd, its texture checked to be a regular file but not decoded here
// (surface_textures.h reads it when rendering).
Mesh LoadMesh(const std::filesystem::path& path, const std::string& group, const std::string& where);
// The same from the file's bytes in memory (the fuzz harnesses): `format` is
// ".obj", ".gltf" or ".glb", `base_dir` where a glTF's external buffers are.
Mesh ParseMesh(std::string_view data, const std::string& format, const std::filesystem::path& base_dir,
               const std::string& name, const std::string& group, const std::string& where);

// The lights of a glTF 2.0 file's KHR_lights_punctual extension, placed by
// their nodes (position: the node's origin; direction: its -z axis): point,
// spot (cone angles from innerConeAngle and outerConeAngle) and directional,
// with glTF's intensity (candela, or lux for directional) in `intensity`,
// its range in range_m, and E_per_band empty: the scene gives the spectrum
// (and, in a relative scene, the scale to its irradiance units). Problems
// are UserErrors naming `where`.
struct PunctualLight {
  Light light;
  Eigen::Vector3d colour = Eigen::Vector3d::Ones();  // linear RGB in [0, 1]
};
std::vector<PunctualLight> LoadGltfLights(const std::filesystem::path& path, const std::string& where);
std::vector<PunctualLight> ParseGltfLights(std::string_view data, bool binary, const std::filesystem::path& base_dir,
                                           const std::string& name, const std::string& where);

}  // namespace phos::render
