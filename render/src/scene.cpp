#include "phos/render/scene.h"

#include "phos/render/phosphor_map.h"
#include "phos/render/light_units.h"
#include "phos/render/spectral_upsampling.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>

#include <nlohmann/json.hpp>

#include "phos/model/photometry.h"
#include "phos/render/subsurface.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/math.h"

namespace phos::render {
namespace {

// Every coordinate, size and direction of a scene lies in
// [-kMaxCoordinate_m, kMaxCoordinate_m] (scene.h): Embree's float BVH
// asserted on 1e308.
Vec3 ReadVec3(const JsonField& field) {
  if (field.ArraySize() != 3) field.Fail("expected 3 values [x, y, z], got " + std::to_string(field.ArraySize()));
  return {field.At(0).NumberInRange(-kMaxCoordinate_m, kMaxCoordinate_m),
          field.At(1).NumberInRange(-kMaxCoordinate_m, kMaxCoordinate_m),
          field.At(2).NumberInRange(-kMaxCoordinate_m, kMaxCoordinate_m)};
}

// A direction: a vector that is not zero, normalized.
Vec3 ReadDirection(const JsonField& field) {
  const Vec3 v = ReadVec3(field);
  if (v.norm() == 0) field.Fail("must not be zero");
  return v.normalized();
}

double ReadLength(const JsonField& field, double lower) { return field.NumberInRange(lower, kMaxCoordinate_m); }

// A time of the scene: in [-kMaxTime_s, kMaxTime_s].
double ReadTime(const JsonField& field) { return field.NumberInRange(-kMaxTime_s, kMaxTime_s); }

Eigen::Quaterniond ReadRotation(const JsonField& field) {
  field.RejectUnknownKeys({"axis", "deg"});
  const Vec3 axis = ReadVec3(field["axis"]);
  if (axis.norm() == 0) field["axis"].Fail("the rotation axis must not be zero");
  return Eigen::Quaterniond(Eigen::AngleAxisd(field["deg"].NumberInRange(-1e6, 1e6) * kPi / 180, axis.normalized()));
}

RigidKey ReadRigidKey(const JsonField& field, bool with_time) {
  RigidKey key;
  if (with_time) {
    field.RejectUnknownKeys({"t_s", "translate", "rotate", "scale"});
    key.t_s = ReadTime(field["t_s"]);
  } else {
    field.RejectUnknownKeys({"translate", "rotate", "scale"});
  }
  if (auto f = field.Optional("translate")) key.translate = ReadVec3(*f);
  if (auto f = field.Optional("rotate")) key.rotate = ReadRotation(*f);
  if (auto f = field.Optional("scale")) {
    key.scale = f->Number();
    if (!(key.scale > 0)) f->Fail("expected a scale > 0, got " + DescribeJson(f->value()));
    key.scale = f->NumberInRange(kMinScale, kMaxScale);
  }
  return key;
}

template <typename Key>
void RequireIncreasingTimes(const JsonField& array, const std::vector<Key>& keys) {
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (!(keys[i].t_s > keys[i - 1].t_s))
      array.At(i)["t_s"].Fail("keyframe times must increase (after " + FormatDouble(keys[i - 1].t_s) + ")");
}

RigidMotion ReadMotion(const JsonField& object) {
  RigidMotion motion;
  if (auto f = object.Optional("transform")) motion.keys.push_back(ReadRigidKey(*f, false));
  if (auto f = object.Optional("animation")) {
    if (object.Has("transform")) f->Fail("give either 'transform' or 'animation', not both");
    if (f->ArraySize() == 0) f->Fail("expected at least one keyframe");
    for (std::size_t i = 0; i < f->ArraySize(); ++i) motion.keys.push_back(ReadRigidKey(f->At(i), true));
    RequireIncreasingTimes(*f, motion.keys);
  }
  return motion;
}

// A light's emission spectrum as band integrals, with its integral over all
// wavelengths (the shapes are normalized to 1; "bands" is as given).
LightSpectrum ReadLightSpectrum(const JsonField& field, const SpectralGrid& bands) {
  const std::string type = field["type"].String();
  SampledSpectrum spectrum;
  if (type == "led") {
    field.RejectUnknownKeys({"type", "center_nm", "fwhm_nm"});
    const double center = field["center_nm"].NumberInRange(100, 2000);
    const double fwhm = field["fwhm_nm"].NumberInRange(0.1, 500);
    spectrum = LedSpectrum(center, fwhm);
  } else if (type == "white_led") {
    field.RejectUnknownKeys({"type"});
    spectrum = WhiteLedSpectrum();
  } else if (type == "blackbody") {
    field.RejectUnknownKeys({"type", "temperature_k"});
    spectrum = BlackbodySpectrum(field["temperature_k"].NumberInRange(500, 50000), 300, 1000);
  } else if (type == "sun") {
    field.RejectUnknownKeys({"type"});
    spectrum = BlackbodySpectrum(5778, 300, 1000);  // the sun as a 5778 K blackbody
  } else if (type == "bands") {
    field.RejectUnknownKeys({"type", "values"});
    std::vector<double> values = field["values"].NumberArray(static_cast<std::size_t>(bands.band_count()), 0.0);
    for (std::size_t b = 0; b < values.size(); ++b)
      if (values[b] > kMaxIrradiance)
        field["values"].At(b).Fail("expected at most " + FormatDouble(kMaxIrradiance) + ", got " +
                                   FormatDouble(values[b]));
    const double total = std::accumulate(values.begin(), values.end(), 0.0);
    return {std::move(values), total};
  } else {
    field["type"].Fail("unknown spectrum type '" + type + "' (led, white_led, blackbody, sun, bands)");
  }
  return {IntegrateOverBands(spectrum, bands), IntegrateAll(spectrum)};
}

std::vector<double> ReadSpectrum(const JsonField& field, const SpectralGrid& bands) {
  return ReadLightSpectrum(field, bands).bands;
}

bool ReadBool(const JsonField& object, std::string_view key, bool fallback) {
  const auto field = object.Optional(key);
  if (!field) return fallback;
  if (!field->value().is_boolean()) field->Fail("expected true or false, got " + DescribeJson(field->value()));
  return field->value().get<bool>();
}

// The albedo from the mesh's material (Mesh::base_colour): its linear RGB
// factor upsampled to the bands (spectral_upsampling.h), and its texture, if
// any, looked up at each hit through the mesh's UV map.
void ReadBaseColour(const JsonField& o, const Mesh& mesh, const SpectralGrid& bands, Object& object) {
  const BaseColour& colour = *mesh.base_colour;
  object.albedo = RgbToBands(bands).Albedo({colour.factor[0], colour.factor[1], colour.factor[2]});
  if (colour.texture.empty()) return;
  if (!mesh.has_uvs())
    o["mesh"].Fail("the mesh (" + mesh.source + ") has an albedo texture (" + colour.field +
                   ") but no UV map (TEXCOORD_0 or vt on every corner)");
  object.albedo_texture = colour;
}

std::vector<double> ReadAlbedo(const JsonField& field, int band_count) {
  if (field.value().is_number()) return std::vector<double>(band_count, field.NumberInRange(0, 1));
  std::vector<double> albedo = field.NumberArray(static_cast<std::size_t>(band_count), 0.0);
  for (std::size_t b = 0; b < albedo.size(); ++b)
    if (albedo[b] > 1) field.At(b).Fail("expected an albedo in [0, 1], got " + FormatDouble(albedo[b]));
  return albedo;
}

std::shared_ptr<const Mesh> ReadShape(const JsonField& field) {
  const std::string type = field["type"].String();
  if (type == "quad") {
    field.RejectUnknownKeys({"type", "size"});
    const JsonField size_field = field["size"];
    if (size_field.ArraySize() != 2) size_field.Fail("expected 2 sizes");
    const std::vector<double> size = {ReadLength(size_field.At(0), 1e-9), ReadLength(size_field.At(1), 1e-9)};
    return std::make_shared<Mesh>(MakeQuad(size[0], size[1]));
  }
  if (type == "box") {
    field.RejectUnknownKeys({"type", "size", "inward"});
    const Vec3 size = ReadVec3(field["size"]);
    if (size.minCoeff() <= 0) field["size"].Fail("expected three sizes > 0");
    const bool inward = ReadBool(field, "inward", false);
    return std::make_shared<Mesh>(MakeBox(size, inward));
  }
  if (type == "sphere") {
    field.RejectUnknownKeys({"type", "radius", "subdivisions", "inward"});
    const double radius = ReadLength(field["radius"], 1e-9);
    const int subdivisions = field.Has("subdivisions") ? field["subdivisions"].Integer(0, 7) : 3;
    const bool inward = ReadBool(field, "inward", false);
    return std::make_shared<Mesh>(MakeSphere(radius, subdivisions, inward));
  }
  field["type"].Fail("unknown shape '" + type + "' (quad, box, sphere)");
}

// [{"t_s", "level"}, ...]: a light's or the sky's levels over time.
LightSchedule ReadSchedule(const JsonField& f) {
  LightSchedule schedule;
  for (std::size_t k = 0; k < f.ArraySize(); ++k) {
    const JsonField key = f.At(k);
    key.RejectUnknownKeys({"t_s", "level"});
    schedule.keys.push_back({ReadTime(key["t_s"]), key["level"].NumberInRange(0, kMaxLevel)});
  }
  if (schedule.keys.empty()) f.Fail("expected at least one {t_s, level}");
  RequireIncreasingTimes(f, schedule.keys);
  return schedule;
}

using MaterialCache = std::map<std::string, std::shared_ptr<const Material>>;

// "phosphor": a material file on the scene's band grid (loaded once per file).
// E_per_band *= factor, band by band, within the limit (`field` is named if not).
void ScaleSpectrum(const JsonField& field, Light& light, const std::vector<double>& factor) {
  for (std::size_t b = 0; b < light.E_per_band.size(); ++b) {
    double& e = light.E_per_band[b];
    e *= factor[b];
    if (!(e <= kMaxIrradiance))
      field.Fail(std::string("gives ").append(light.area() ? "a radiance" : "an irradiance") + " of " +
                 FormatDouble(e) + " in a band, more than the limit of " + FormatDouble(kMaxIrradiance));
  }
}

// A light's band values E_per_band: in a relative scene its spectrum times
// "intensity"; in a physical one its value in W, lm, cd or lx through its
// spectrum (light_units.h). Its kind is known.
void ReadLightLevel(const JsonField& l, Light& light, const SpectralGrid& bands, Units units) {
  RequireUnitsOfScene(l, units, "intensity");
  if (units == Units::kPhysical) {
    const PhysicalValue value = ReadPhysicalValue(l, QuantityOf(light.kind), light.kind == Light::Kind::kPoint);
    light.E_per_band = PhysicalBands(l, value, ReadLightSpectrum(l["spectrum"], bands), bands);
    return;
  }
  light.intensity = l["intensity"].NumberInRange(0, kMaxIrradiance);
  light.E_per_band = ReadSpectrum(l["spectrum"], bands);
  ScaleSpectrum(l["intensity"], light, std::vector<double>(light.E_per_band.size(), light.intensity));
}

// One entry of "lights": light `index` of the scene (its default name).
Light ReadLight(const JsonField& l, std::size_t index, const SpectralGrid& bands, Units units) {
  l.RejectUnknownKeys({"name", "type", "position", "direction", "intensity", "spectrum", "schedule", "path", "normal",
                       "thickness_m", "size_m", "tangent", "radius_m", "samples", "inner_cone_deg", "outer_cone_deg",
                       PHOS_PHYSICAL_LIGHT_KEYS});
  Light light;
  light.name = l.Has("name") ? l["name"].NonEmptyString() : "light " + std::to_string(index);
  auto only = [&](const char* key, const char* owners) {
    if (l.Has(key)) l[key].Fail(std::string("only ").append(owners).append(" light has '").append(key).append("'"));
  };
  const std::string type = l["type"].String();
  auto read_place = [&] {  // a position, or a path of positions
    if (l.Has("path")) {
      const JsonField path = l["path"];
      for (std::size_t k = 0; k < path.ArraySize(); ++k) {
        const JsonField key = path.At(k);
        key.RejectUnknownKeys({"t_s", "position"});
        RigidKey rigid;
        rigid.t_s = ReadTime(key["t_s"]);
        rigid.translate = ReadVec3(key["position"]);
        light.motion.keys.push_back(rigid);
      }
      if (light.motion.keys.empty()) path.Fail("expected at least one keyframe");
      RequireIncreasingTimes(path, light.motion.keys);
      if (l.Has("position")) l["position"].Fail("give either 'position' or 'path', not both");
    } else {
      light.position = ReadVec3(l["position"]);
    }
  };
  auto read_direction = [&] { light.direction = ReadDirection(l["direction"]); };
  if (type == "point") {
    light.kind = Light::Kind::kPoint;
    read_place();
  } else if (type == "directional") {
    light.kind = Light::Kind::kDirectional;
    read_direction();
  } else if (type == "spot") {
    light.kind = Light::Kind::kSpot;
    read_place();
    read_direction();
    if (auto f = l.Optional("inner_cone_deg")) light.inner_cone_deg = f->NumberInRange(0, 89.9);
    if (auto f = l.Optional("outer_cone_deg")) light.outer_cone_deg = f->NumberInRange(0.1, 90);
    if (!(light.inner_cone_deg < light.outer_cone_deg))
      l[l.Has("outer_cone_deg") ? "outer_cone_deg" : "inner_cone_deg"].Fail(
          "the outer cone (" + FormatDouble(light.outer_cone_deg) + " deg) must be wider than the inner (" +
          FormatDouble(light.inner_cone_deg) + " deg)");
  } else if (type == "sheet") {
    light.kind = Light::Kind::kSheet;
    read_direction();
    read_place();
    light.sheet_normal = ReadDirection(l["normal"]);
    light.sheet_thickness_m = ReadLength(l["thickness_m"], 1e-9);
  } else if (type == "quad" || type == "disk") {
    light.kind = type == "quad" ? Light::Kind::kQuad : Light::Kind::kDisk;
    read_place();
    light.normal = ReadDirection(l["normal"]);
    if (light.kind == Light::Kind::kQuad) {
      const JsonField size = l["size_m"];
      if (size.ArraySize() != 2) size.Fail("expected [width, height] in metres");
      light.width_m = ReadLength(size.At(0), 1e-6);
      light.height_m = ReadLength(size.At(1), 1e-6);
      // The width's direction: given, or the x axis (z if the light faces
      // along x), made perpendicular to the normal.
      Vec3 tangent = l.Has("tangent") ? ReadVec3(l["tangent"])
                                      : (std::abs(light.normal.x()) < 0.9 ? Vec3(1, 0, 0) : Vec3(0, 0, 1));
      tangent -= tangent.dot(light.normal) * light.normal;
      if (tangent.norm() < 1e-6 * (1 + tangent.norm())) l["tangent"].Fail("must not be parallel to 'normal'");
      light.tangent = tangent.normalized();
    } else {
      light.radius_m = ReadLength(l["radius_m"], 1e-6);
    }
    if (auto f = l.Optional("samples")) light.samples = f->Integer(1, 1024);
  } else {
    l["type"].Fail("unknown light type '" + type + "' (point, spot, directional, sheet, quad, disk, gltf)");
  }
  if (type != "spot") {
    only("inner_cone_deg", "a spot");
    only("outer_cone_deg", "a spot");
  }
  if (type != "sheet") only("thickness_m", "a sheet");
  if (type != "sheet" && !light.area()) only("normal", "a sheet, quad or disk");
  if (type != "quad") {
    only("size_m", "a quad");
    only("tangent", "a quad");
  }
  if (type != "disk") only("radius_m", "a disk");
  if (!light.area()) only("samples", "a quad or disk");
  ReadLightLevel(l, light, bands, units);
  if (auto f = l.Optional("schedule")) light.schedule = ReadSchedule(*f);
  return light;
}

// An object's "emission": {"intensity": radiance, "spectrum", "schedule",
// "samples"}: the front of each of its triangles is an area light.
Light ReadEmission(const JsonField& f, const std::string& object_name, std::size_t object, const SpectralGrid& bands,
                   Units units) {
  f.RejectUnknownKeys({"intensity", "spectrum", "schedule", "samples", PHOS_PHYSICAL_LIGHT_KEYS});
  Light light;
  light.kind = Light::Kind::kMesh;
  light.name = object_name;
  light.emitter_object = static_cast<int>(object);
  ReadLightLevel(f, light, bands, units);
  if (auto s = f.Optional("schedule")) light.schedule = ReadSchedule(*s);
  if (auto s = f.Optional("samples")) light.samples = s->Integer(1, 1024);
  return light;
}

// A file a scene names (`what`: "mesh", "phosphor", ...), relative to the
// scene's folder; one that is not there fails at its field, saying which
// folder it was looked in (a scene copied elsewhere loses its files).
std::filesystem::path SceneFile(const JsonField& f, const std::filesystem::path& base_dir, const char* what) {
  const std::filesystem::path file = base_dir / f.NonEmptyString();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) {
    const std::filesystem::path folder = std::filesystem::absolute(base_dir.empty() ? "." : base_dir, ec);
    f.Fail(std::string(what) + " file '" + file.string() +
           "' does not exist or is not a regular file (a scene's paths are relative to its own folder, " +
           folder.lexically_normal().string() + ")");
  }
  return file;
}

// A glTF light of a physical scene: `value` photometric units (its
// intensity times the entry's intensity_scale: cd, or lx for directional),
// its spectrum tinted band by band by its colour (`colour`, upsampled from
// `rgb`). The light shows value x the colour's luminance (Rec. 709 Y of the
// linear RGB), as a renderer multiplying colour by intensity would: a white
// light of 100 cd is 100 cd.
std::vector<double> GltfPhysicalBands(const JsonField& l, const LightSpectrum& spectrum,
                                      const std::vector<double>& colour, const Eigen::Vector3d& rgb, double value,
                                      const SpectralGrid& bands) {
  const double colour_luminance = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
  LightSpectrum tinted = spectrum;
  for (std::size_t b = 0; b < tinted.bands.size(); ++b) tinted.bands[b] *= colour[b];
  if (!(value * colour_luminance > 0)) return std::vector<double>(tinted.bands.size(), 0.0);
  // PhysicalBands names the field a problem is at: the entry's file.
  const PhysicalValue photometric{"file", value * colour_luminance, true, 1.0};
  return PhysicalBands(l, photometric, tinted, bands);
}

// {"type": "gltf", "file": ..., "spectrum": ..., "intensity_scale": s,
// "schedule": ...}: the KHR_lights_punctual lights of a glTF file, each with
// the entry's spectrum, times its glTF intensity times s, times its glTF
// colour upsampled to the bands (render/spectral_upsampling.h). In a
// physical scene the glTF intensity is in its own unit, cd for point and
// spot, lx for directional, and the range window applies (GltfPhysicalBands).
std::vector<Light> ReadGltfLights(const JsonField& l, const SpectralGrid& bands, const std::filesystem::path& base_dir,
                                  Units units) {
  l.RejectUnknownKeys({"type", "file", "spectrum", "intensity_scale", "schedule"});
  const std::filesystem::path file = SceneFile(l["file"], base_dir, "glTF");
  std::vector<PunctualLight> punctual = LoadGltfLights(file, l["file"].source() + ": " + l["file"].path());
  if (punctual.empty()) l["file"].Fail("'" + file.string() + "' has no KHR_lights_punctual light in its scene");
  const double scale = l.Has("intensity_scale") ? l["intensity_scale"].NumberInRange(0, kMaxIrradiance) : 1.0;
  const LightSpectrum spectrum = ReadLightSpectrum(l["spectrum"], bands);
  LightSchedule schedule;
  if (auto f = l.Optional("schedule")) schedule = ReadSchedule(*f);
  const RgbToBands upsample(bands);
  std::vector<Light> lights;
  for (PunctualLight& p : punctual) {
    Light light = std::move(p.light);
    const std::vector<double> colour = upsample.Albedo({p.colour[0], p.colour[1], p.colour[2]});
    if (units == Units::kPhysical) {
      light.E_per_band = GltfPhysicalBands(l, spectrum, colour, p.colour, light.intensity * scale, bands);
    } else {
      // glTF's range is the physical reading's: a relative scene keeps the
      // inverse square to infinity it always had.
      light.range_m = 0;
      std::vector<double> factor(colour.size());
      for (std::size_t b = 0; b < colour.size(); ++b) factor[b] = light.intensity * scale * colour[b];
      light.E_per_band = spectrum.bands;
      ScaleSpectrum(l.Has("intensity_scale") ? l["intensity_scale"] : l["file"], light, factor);
    }
    light.schedule = schedule;
    lights.push_back(std::move(light));
  }
  return lights;
}

// "phosphor" of object or volume `owner` (its name, for messages).
void ReadPhosphor(const JsonField& o, const std::filesystem::path& base_dir, const Scene& scene,
                  const std::string& owner, MaterialCache& materials, std::shared_ptr<const Material>& phosphor,
                  std::string& path) {
  if (!o.Has("phosphor")) return;
  const std::filesystem::path file = SceneFile(o["phosphor"], base_dir, "phosphor");
  auto& material = materials[file.string()];
  if (!material) material = std::make_shared<Material>(LoadMaterial(file));
  if (const std::string mismatch = BandGridMismatch(material->bands, scene.bands); !mismatch.empty())
    o["phosphor"].Fail("the material's bands_nm " + mismatch);
  if (const std::string mismatch = UnitsMismatch(*material, file.string(), scene.units); !mismatch.empty())
    o["phosphor"].Fail("'" + owner + "': " + mismatch);
  phosphor = material;
  path = file.string();
}

// The texels of a masked, mapped or "texels": "uv" phosphor are its UV map's:
// one that is not one-to-one (UvMapIsOneToOne) is refused at field f.
void RequireOneToOneUvMap(const JsonField& f, const Mesh& mesh) {
  if (!UvMapIsOneToOne(mesh))
    f.Fail("the mesh's UV map (" + mesh.source +
           ") is not one-to-one (UVs outside [0, 1], or triangles over the same place of UV space): its texels "
           "would each lie in several places");
}

// A phosphor's mask or map (`what`) lies on the mesh's UV map, and its texels
// are then the UV map's: `texels` must say "uv" (`adjective`: "masked", ...).
void RequireUvTexels(const JsonField& f, const Mesh& mesh, const std::string& texels, const char* what,
                     const char* adjective) {
  if (!mesh.has_uvs())
    f.Fail(std::string("the ") + what + " lies on the mesh's UV map, and the mesh (" + mesh.source + ") has none");
  if (texels == "auto")
    f.Fail(std::string("a ") + adjective + " phosphor's texels are its UV map's: use \"texels\": \"uv\"");
  RequireOneToOneUvMap(f, mesh);
}

// "phosphor_map": a decay map of `phos fit map` over the mesh's UV map
// (phosphor_map.h): one texel per map pixel along its longer side unless
// "uv_resolution" says fewer.
void ReadPhosphorMapField(const JsonField& f, const std::filesystem::path& base_dir, Object& object) {
  if (!object.phosphor) f.Fail("a map gives a phosphor's rates and levels per texel: give the material ('phosphor')");
  RequireUvTexels(f, *object.mesh, object.texels, "map", "mapped");
  const std::filesystem::path file = SceneFile(f, base_dir, "map");
  auto map = std::make_shared<PhosphorMap>(ReadPhosphorMap(file, f.source(), f.path()));
  const int nc = object.phosphor->state_count();
  if (map->states != nc)
    f.Fail("the map '" + file.string() + "' has " + std::to_string(map->states) + " state(s)" +
           (map->states == 2 ? " (kr2)" : "") + " and the material '" + object.phosphor->name + "' " +
           std::to_string(nc) + ": fit both with the same number (phos fit map --states)");
  const int finest = std::max(map->width, map->height);
  if (object.uv_resolution > finest)
    f.Fail("uv_resolution " + std::to_string(object.uv_resolution) + " is finer than the map's " +
           std::to_string(map->width) + " x " + std::to_string(map->height) +
           " pixels: texels would repeat its pixels (leave it out for one texel per pixel)");
  if (object.uv_resolution == 0) object.uv_resolution = finest;
  object.phosphor_map = std::move(map);
  object.texels = "uv";
}

// "unknown_ke" and "initial", which only a phosphor may have.
void ReadPhosphorPolicy(const JsonField& o, bool is_phosphor, bool& unknown_ke_as_zero, InitialState& initial) {
  if (auto f = o.Optional("unknown_ke")) {
    const std::string policy = f->String();
    if (policy != "error" && policy != "zero") f->Fail("expected \"error\" or \"zero\", got \"" + policy + "\"");
    unknown_ke_as_zero = policy == "zero";
  }
  if (auto f = o.Optional("initial")) {
    if (f->value().is_number()) {
      initial = {InitialState::Kind::kUniform, f->NumberInRange(0, 1)};
    } else {
      const std::string kind = f->String();
      if (kind == "zero")
        initial.kind = InitialState::Kind::kZero;
      else if (kind == "equilibrium")
        initial.kind = InitialState::Kind::kEquilibrium;
      else
        f->Fail("expected \"zero\", \"equilibrium\" or a number in [0, 1], got \"" + kind + "\"");
    }
    if (!is_phosphor) f->Fail("only a phosphorescent object or volume (with 'phosphor') has an initial state");
  }
}

// A volume's density grid: a number (uniform), one value per voxel (x
// fastest), or a procedural fill {"value", "shape": "box" | "ellipsoid"
// (inscribed in the bounds), "puffs": N Gaussian puffs of "radius_m" at
// places drawn with "seed", "below_y_m": empty above a level (a liquid)}.
std::vector<float> ReadDensity(const JsonField& f, const Volume& v) {
  const std::size_t n = static_cast<std::size_t>(v.nx) * v.ny * v.nz;
  if (f.value().is_number()) return std::vector<float>(n, static_cast<float>(f.NumberInRange(0, kMaxDensity)));
  if (f.value().is_array()) {
    const std::vector<double> values = f.NumberArray(n, 0.0);
    for (std::size_t j = 0; j < n; ++j)
      if (values[j] > kMaxDensity) f.At(j).Fail("expected a density in [0, " + FormatDouble(kMaxDensity) + "]");
    return std::vector<float>(values.begin(), values.end());
  }
  f.RejectUnknownKeys({"value", "shape", "puffs", "radius_m", "seed", "below_y_m"});
  const double value = f.Has("value") ? f["value"].NumberInRange(0, kMaxDensity) : 1.0;
  const std::string shape = f.Has("shape") ? f["shape"].String() : "box";
  if (shape != "box" && shape != "ellipsoid")
    f["shape"].Fail("expected \"box\" or \"ellipsoid\", got \"" + shape + "\"");
  const int puffs = f.Has("puffs") ? f["puffs"].Integer(1, 100000) : 0;
  const double radius = f.Has("radius_m") ? ReadLength(f["radius_m"], 1e-9) : 0.0;
  if (puffs > 0 && !f.Has("radius_m")) f.Fail("'puffs' needs 'radius_m'");
  // Each voxel sums every puff: bound the work before doing it.
  if (static_cast<double>(puffs) * static_cast<double>(n) > kMaxPuffEvaluations)
    f["puffs"].Fail(std::to_string(puffs) + " puffs over " + std::to_string(n) + " voxels is more than the limit of " +
                    FormatDouble(kMaxPuffEvaluations) + " puff evaluations; use fewer puffs or voxels");
  const double below_y_m = f.Has("below_y_m") ? f["below_y_m"].NumberInRange(-kMaxCoordinate_m, kMaxCoordinate_m) : 0.0;
  std::mt19937_64 random(f.Has("seed") ? static_cast<unsigned>(f["seed"].Integer(0, 1 << 30)) : 1u);
  std::vector<Vec3> centres;
  const Vec3 size = v.max_m - v.min_m, centre = 0.5 * (v.min_m + v.max_m);
  for (int k = 0; k < puffs; ++k) {
    // Puffs inside the shape, at least a radius from the bounds where it fits.
    std::uniform_real_distribution<double> u(0, 1);
    Vec3 q;
    for (int attempt = 0; attempt < 1000; ++attempt) {
      q = v.min_m + Vec3(u(random), u(random), u(random)).cwiseProduct(size);
      const Vec3 e = (q - centre).cwiseQuotient(0.5 * size);
      if (shape == "box" || e.squaredNorm() <= 1) break;
    }
    centres.push_back(q);
  }
  const Vec3 voxel = v.voxel_size_m();
  std::vector<float> density(n, 0.0f);
  for (int z = 0; z < v.nz; ++z)
    for (int y = 0; y < v.ny; ++y)
      for (int x = 0; x < v.nx; ++x) {
        const Vec3 p = v.min_m + Vec3(x + 0.5, y + 0.5, z + 0.5).cwiseProduct(voxel);
        double d = value;
        if (shape == "ellipsoid" && (p - centre).cwiseQuotient(0.5 * size).squaredNorm() > 1) d = 0;
        if (f.Has("below_y_m") && p.y() > below_y_m) d = 0;
        if (puffs > 0 && d > 0) {
          double sum = 0;
          for (const Vec3& c : centres) sum += std::exp(-0.5 * (p - c).squaredNorm() / (radius * radius));
          d *= std::min(1.0, sum);
        }
        density[(static_cast<std::size_t>(z) * v.ny + y) * v.nx + x] = static_cast<float>(d);
      }
  return density;
}

// "bands_nm": the band edges of the scene's spectra.
void ReadBands(const JsonField& f, SpectralGrid& bands) {
  if (f.ArraySize() > static_cast<std::size_t>(kMaxBands) + 1)
    f.Fail("more than the limit of " + std::to_string(kMaxBands) + " bands");
  bands.edges_nm = f.NumberArray(0, 1.0);
  if (bands.edges_nm.size() < 2) f.Fail("expected at least two band edges");
  for (std::size_t i = 0; i < bands.edges_nm.size(); ++i)
    if (bands.edges_nm[i] > kMaxWavelengthNm)
      f.At(i).Fail("expected a wavelength of at most " + FormatDouble(kMaxWavelengthNm) + " nm");
  for (std::size_t i = 1; i < bands.edges_nm.size(); ++i)
    if (!(bands.edges_nm[i] > bands.edges_nm[i - 1])) f.At(i).Fail("band edges must increase");
}

// "time": the sequence's start, end and frame rate.
void ReadTimes(const JsonField& time, Scene& scene) {
  time.RejectUnknownKeys({"start_s", "end_s", "fps"});
  if (time.Has("start_s")) scene.start_s = ReadTime(time["start_s"]);
  if (time.Has("end_s")) scene.end_s = ReadTime(time["end_s"]);
  if (time.Has("fps")) scene.fps = time["fps"].NumberInRange(1e-6, 1e4);
  if (!(scene.end_s >= scene.start_s)) time["end_s"].Fail("must not be before start_s");
  if ((scene.end_s - scene.start_s) * scene.fps > 1e6) time["fps"].Fail("more than a million frames");
}

void ReadCamera(const JsonField& camera, Camera& out) {
  camera.RejectUnknownKeys({"position", "look_at", "up", "fov_deg", "width", "height", "exposure", "path"});
  CameraKey first;
  first.position = ReadVec3(camera["position"]);
  first.look_at = ReadVec3(camera["look_at"]);
  if ((first.position - first.look_at).norm() == 0) camera["look_at"].Fail("must differ from position");
  out.keys.push_back(first);
  if (auto path = camera.Optional("path")) {
    out.keys.clear();
    for (std::size_t i = 0; i < path->ArraySize(); ++i) {
      const JsonField key = path->At(i);
      key.RejectUnknownKeys({"t_s", "position", "look_at"});
      out.keys.push_back({ReadTime(key["t_s"]), ReadVec3(key["position"]), ReadVec3(key["look_at"])});
      if ((out.keys.back().position - out.keys.back().look_at).norm() == 0)
        key["look_at"].Fail("must differ from position");
    }
    if (out.keys.empty()) path->Fail("expected at least one keyframe");
    RequireIncreasingTimes(*path, out.keys);
  }
  if (auto f = camera.Optional("up")) out.up = ReadVec3(*f);
  if (out.up.norm() == 0) camera["up"].Fail("must not be zero");
  if (auto f = camera.Optional("fov_deg")) out.fov_deg = f->NumberInRange(1, 170);
  if (auto f = camera.Optional("width")) out.width = f->Integer(1, 16384);
  if (auto f = camera.Optional("height")) out.height = f->Integer(1, 16384);
  if (auto f = camera.Optional("exposure")) {
    const nlohmann::json& value = f->value();
    if (value == "auto")
      out.exposure_auto = true;
    else if (value.is_number() && value.get<double>() >= 0 && value.get<double>() <= 1e9)
      out.exposure = value.get<double>();
    else
      f->Fail("expected \"auto\" or a number in [0, 1e9], got " + DescribeJson(value));
  }
  if (static_cast<double>(out.width) * out.height > kMaxPixels)
    camera.Fail(std::to_string(out.width) + " x " + std::to_string(out.height) + " pixels is more than the limit of " +
                std::to_string(kMaxPixels) + " pixels per frame");
}

void ReadRenderSettings(const JsonField& render, RenderSettings& s) {
  render.RejectUnknownKeys({"spp", "max_depth", "direct_spp", "seed", "max_step_s", "phosphor_irradiance"});
  if (render.Has("spp")) s.spp = render["spp"].Integer(1, 1 << 20);
  if (render.Has("max_depth")) s.max_depth = render["max_depth"].Integer(1, 1000);
  if (render.Has("direct_spp")) s.direct_spp = render["direct_spp"].Integer(1, 1024);
  if (render.Has("seed")) s.seed = static_cast<unsigned>(render["seed"].Integer(0, 1 << 30));
  if (render.Has("max_step_s")) s.max_step_s = render["max_step_s"].NumberInRange(1e-6, 1e9);
  s.phosphor_irradiance = ReadBool(render, "phosphor_irradiance", false);
}

// Meshes used twice are loaded once: by file and group.
using MeshCache = std::map<std::string, std::shared_ptr<const Mesh>>;

// An object's "mesh" (a file, with its "group") or "shape".
std::shared_ptr<const Mesh> ReadObjectMesh(const JsonField& o, const std::filesystem::path& base_dir,
                                           MeshCache& meshes) {
  if (o.Has("mesh") == o.Has("shape")) o.Fail("give exactly one of 'mesh' (a file) or 'shape'");
  if (!o.Has("mesh")) return ReadShape(o["shape"]);
  const std::filesystem::path file = SceneFile(o["mesh"], base_dir, "mesh");
  const std::string group = o.Has("group") ? o["group"].NonEmptyString() : "";
  const std::string key = file.string() + "#" + group;
  auto& mesh = meshes[key];
  if (!mesh) mesh = std::make_shared<Mesh>(LoadMesh(file, group, o["mesh"].source() + ": " + o["mesh"].path()));
  return mesh;
}

// A number, or one value per band, each above zero.
std::vector<double> ReadPerBand(const JsonField& field, double lower, int nb) {
  if (field.value().is_number()) return std::vector<double>(nb, field.NumberInRange(lower, 1e9));
  std::vector<double> values = field.NumberArray(static_cast<std::size_t>(nb), lower);
  for (std::size_t b = 0; b < values.size(); ++b)
    if (!(values[b] > 0)) field.At(b).Fail("must be above zero");
  return values;
}

// An object's albedo: from its "subsurface", its "albedo", its mesh's base
// colour or its phosphor's, in that order.
void ReadObjectAlbedo(const JsonField& o, const SpectralGrid& bands, Object& object) {
  const int nb = bands.band_count();
  if (auto f = o.Optional("subsurface")) {
    f->RejectUnknownKeys({"sigma_a_per_m", "sigma_s_prime_per_m", "eta"});
    if (o.Has("albedo")) o["albedo"].Fail("a translucent object's albedo follows from 'subsurface'; give one of them");
    Subsurface sss;
    sss.sigma_a_per_m = ReadPerBand((*f)["sigma_a_per_m"], 1e-9, nb);
    sss.sigma_s_prime_per_m = ReadPerBand((*f)["sigma_s_prime_per_m"], 1e-9, nb);
    if (f->Has("eta")) sss.eta = (*f)["eta"].NumberInRange(1.0, 3.0);
    for (int b = 0; b < nb; ++b)
      object.albedo.push_back(
          Dipole::From(sss.sigma_a_per_m[b], sss.sigma_s_prime_per_m[b], sss.eta).TotalReflectance());
    object.subsurface = sss;
  } else if (o.Has("albedo")) {
    // The scene's own word wins over the mesh file's material: an explicit
    // override, and scenes written before textures render as they did.
    object.albedo = ReadAlbedo(o["albedo"], nb);
  } else if (object.mesh->base_colour) {
    ReadBaseColour(o, *object.mesh, bands, object);
  } else if (!object.mesh->base_colours_differ.empty()) {
    o.Fail("missing 'albedo': the mesh (" + object.mesh->source + ") has no single base colour, " +
           object.mesh->base_colours_differ + "; give 'albedo' or pick one part with 'group'");
  } else if (object.phosphor && object.phosphor->albedo) {
    object.albedo = *object.phosphor->albedo;
  } else {
    o.Fail("missing 'albedo' (a number or one value per band)");
  }
}

// "two_sided", "texel_size_m", "texels" and "uv_resolution": how a
// phosphor's state is kept over the object.
void ReadObjectTexels(const JsonField& o, Object& object) {
  if (auto f = o.Optional("two_sided")) {
    object.two_sided = f->Boolean();
    if (object.two_sided && !object.phosphor)
      f->Fail("only a phosphor is one- or two-sided (every object reflects on both faces)");
  }
  if (auto f = o.Optional("texel_size_m")) object.texel_size_m = f->NumberInRange(1e-6, 1e6);
  if (auto f = o.Optional("texels")) {
    object.texels = f->String();
    if (object.texels != "auto" && object.texels != "uv")
      f->Fail("expected \"auto\" or \"uv\", got \"" + object.texels + "\"");
    if (object.texels == "uv" && !object.mesh->has_uvs())
      f->Fail("the mesh has no UV map (" + object.mesh->source + "); use \"auto\"");
    if (object.texels == "uv") RequireOneToOneUvMap(*f, *object.mesh);
  }
  if (auto f = o.Optional("uv_resolution")) object.uv_resolution = f->Integer(1, 16384);
}

// Gloss: the scene's factors over the mesh's glTF material's; its
// texture, if any, multiplies them at each hit.
void ReadObjectGloss(const JsonField& o, Object& object) {
  object.gloss = object.mesh->gloss;
  object.gloss_texture = object.mesh->gloss_texture;
  if (object.gloss_texture && !object.mesh->has_uvs())
    o["mesh"].Fail("the mesh (" + object.mesh->source + ") has a gloss texture (" + object.gloss_texture->field +
                   ") but no UV map (TEXCOORD_0 on every corner)");
  if (o.Has("metallic") || o.Has("roughness")) {
    Gloss gloss = object.gloss.value_or(Gloss{});
    if (auto f = o.Optional("metallic")) gloss.metallic = static_cast<float>(f->NumberInRange(0, 1));
    if (auto f = o.Optional("roughness")) {
      // The bound as a person writes it: kMinRoughness is a float, and
      // promoted it read "expected a number in [0.019999999552965164, 1]".
      constexpr double kMinRoughnessAsWritten = 0.02;
      static_assert(static_cast<float>(kMinRoughnessAsWritten) == kMinRoughness);
      gloss.roughness = std::max(kMinRoughness, static_cast<float>(f->NumberInRange(kMinRoughnessAsWritten, 1)));
    }
    object.gloss = gloss;
  }
  if (object.gloss && object.subsurface)
    o["subsurface"].Fail("a translucent object is not glossy too (drop 'metallic' and 'roughness')");
}

// "phosphor_mask": an image over the mesh's UV map.
void ReadPhosphorMask(const JsonField& f, const std::filesystem::path& base_dir, Object& object) {
  if (!object.phosphor) f.Fail("only a phosphor has a mask (give 'phosphor')");
  RequireUvTexels(f, *object.mesh, object.texels, "mask", "masked");
  const std::filesystem::path file = SceneFile(f, base_dir, "mask");
  object.phosphor_mask = file;
  object.texels = "uv";
}

// What the objects of a scene share as they are read.
struct ObjectsRead {
  MeshCache meshes;
  std::size_t triangles = 0;  // of the objects so far
};

// Entry i of "objects" (its emission, if any, is the caller's).
Object ReadObject(const JsonField& o, std::size_t i, const Scene& scene, const std::filesystem::path& base_dir,
                  MaterialCache& materials, ObjectsRead& read) {
  o.RejectUnknownKeys({"name",          "mesh",          "group",        "shape",        "albedo",
                       "phosphor",      "unknown_ke",    "initial",      "texel_size_m", "texels",
                       "uv_resolution", "transform",     "animation",    "subsurface",   "two_sided",
                       "emission",      "phosphor_mask", "phosphor_map", "metallic",     "roughness"});
  Object object;
  object.name = o.Has("name") ? o["name"].NonEmptyString() : "object " + std::to_string(i);
  // Names pick objects (--material, the editor, the warnings): two objects
  // of one name were both given a --material, silently.
  for (std::size_t k = 0; k < scene.objects.size(); ++k)
    if (scene.objects[k].name == object.name)
      (o.Has("name") ? o["name"] : o)
          .Fail("'" + object.name + "' is the name of objects[" + std::to_string(k) +
                "] too; give each object a name of its own");
  object.mesh = ReadObjectMesh(o, base_dir, read.meshes);
  if (object.mesh->triangles.empty()) o.Fail("the mesh has no triangles");
  read.triangles += object.mesh->triangles.size();
  if (read.triangles > kMaxSceneTriangles)
    o.Fail("the scene's objects up to this one have " + std::to_string(read.triangles) +
           " triangles, more than the limit of " + std::to_string(kMaxSceneTriangles) +
           " (a mesh used twice counts twice)");
  object.motion = ReadMotion(o);
  ReadPhosphor(o, base_dir, scene, object.name, materials, object.phosphor, object.phosphor_path);
  ReadObjectAlbedo(o, scene.bands, object);
  ReadPhosphorPolicy(o, object.phosphor != nullptr, object.unknown_ke_as_zero, object.initial);
  ReadObjectTexels(o, object);
  ReadObjectGloss(o, object);
  if (auto f = o.Optional("phosphor_mask")) ReadPhosphorMask(*f, base_dir, object);
  if (auto f = o.Optional("phosphor_map")) ReadPhosphorMapField(*f, base_dir, object);
  return object;
}

// Objects. Meshes and materials used twice are loaded once.
void ReadObjects(const JsonField& objects, const std::filesystem::path& base_dir, MaterialCache& materials,
                 Scene& scene) {
  ObjectsRead read;
  if (objects.ArraySize() == 0) objects.Fail("expected at least one object");
  // Each object costs memory in the geometry and the solver whatever its
  // size (5,000 phosphor spheres took 3.9 GiB): counted before any is read.
  if (objects.ArraySize() > kMaxObjects)
    objects.Fail("has " + std::to_string(objects.ArraySize()) + " objects, more than the limit of " +
                 std::to_string(kMaxObjects));
  for (std::size_t i = 0; i < objects.ArraySize(); ++i) {
    const JsonField o = objects.At(i);
    Object object = ReadObject(o, i, scene, base_dir, materials, read);
    if (auto f = o.Optional("emission"))
      scene.lights.push_back(ReadEmission(*f, object.name, i, scene.bands, scene.units));
    scene.objects.push_back(std::move(object));
  }
}

// Lights. The solver keeps each light's irradiance per texel: 10,000
// lights took 3.2 GiB. Counted before each is read, emitting objects
// and a glTF's lights included.
void ReadLights(const JsonField& lights, const std::filesystem::path& base_dir, Scene& scene) {
  const std::string too_many = "more than the limit of " + std::to_string(kMaxLights) + " lights";
  if (scene.lights.size() + lights.ArraySize() > kMaxLights)
    lights.Fail("has " + std::to_string(lights.ArraySize()) + " lights" +
                (scene.lights.empty() ? "" : " and the objects " + std::to_string(scene.lights.size()) + " more") +
                ", " + too_many);
  for (std::size_t i = 0; i < lights.ArraySize(); ++i) {
    const JsonField l = lights.At(i);
    if (l.Has("type") && l["type"].String() == "gltf") {
      for (Light& light : ReadGltfLights(l, scene.bands, base_dir, scene.units))
        scene.lights.push_back(std::move(light));
      if (scene.lights.size() > kMaxLights) l.Fail("the scene's lights up to this entry are " + too_many);
    } else {
      scene.lights.push_back(ReadLight(l, i, scene.bands, scene.units));
    }
  }
}

// The sky.
// (In a physical scene its radiance at the horizon, w_y = 0, in
// radiance_w_sr_m2 or luminance_cd_m2: light_units.h.)
Environment ReadEnvironment(const JsonField& f, const SpectralGrid& bands, Units units) {
  f.RejectUnknownKeys({"spectrum", "radiance", "gradient", "schedule", PHOS_PHYSICAL_LIGHT_KEYS});
  Environment env;
  RequireUnitsOfScene(f, units, "radiance");
  if (units == Units::kPhysical) {
    const PhysicalValue value = ReadPhysicalValue(f, LightQuantity::kRadiance, false);
    env.L_per_band = PhysicalBands(f, value, ReadLightSpectrum(f["spectrum"], bands), bands);
  } else {
    env.L_per_band = ReadSpectrum(f["spectrum"], bands);
    const double radiance = f["radiance"].NumberInRange(0, kMaxIrradiance);
    for (double& l : env.L_per_band) {
      l *= radiance;
      if (!(l <= kMaxIrradiance))
        f["radiance"].Fail("gives a radiance of " + FormatDouble(l) + " in a band, more than the limit of " +
                           FormatDouble(kMaxIrradiance));
    }
  }
  if (f.Has("gradient")) env.gradient = f["gradient"].NumberInRange(-1, 1);
  if (auto sf = f.Optional("schedule")) env.schedule = ReadSchedule(*sf);
  return env;
}

// Entry i of "volumes"; `voxels`: those of the volumes up to this one.
Volume ReadVolume(const JsonField& f, std::size_t i, const Scene& scene, const std::filesystem::path& base_dir,
                  MaterialCache& materials, double& voxels) {
  f.RejectUnknownKeys(
      {"name", "bounds", "resolution", "density", "sigma_t_per_m", "albedo", "g", "phosphor", "unknown_ke", "initial"});
  Volume v;
  v.name = f.Has("name") ? f["name"].NonEmptyString() : "volume " + std::to_string(i);
  const JsonField bounds = f["bounds"];
  bounds.RejectUnknownKeys({"min", "max"});
  v.min_m = ReadVec3(bounds["min"]);
  v.max_m = ReadVec3(bounds["max"]);
  if (!(v.max_m.array() > v.min_m.array()).all()) bounds["max"].Fail("must exceed 'min' on every axis");
  const JsonField resolution = f["resolution"];
  if (resolution.ArraySize() != 3) resolution.Fail("expected [nx, ny, nz]");
  v.nx = resolution.At(0).Integer(1, 4096);
  v.ny = resolution.At(1).Integer(1, 4096);
  v.nz = resolution.At(2).Integer(1, 4096);
  voxels += static_cast<double>(v.nx) * v.ny * v.nz;
  if (voxels > kMaxVoxels)
    resolution.Fail("the scene's volumes have " + FormatDouble(voxels) + " voxels, more than the limit of " +
                    std::to_string(kMaxVoxels));
  v.density = ReadDensity(f["density"], v);
  v.sigma_t_per_m = f["sigma_t_per_m"].NumberInRange(0, 1e9);
  ReadPhosphor(f, base_dir, scene, v.name, materials, v.phosphor, v.phosphor_path);
  if (f.Has("albedo"))
    v.albedo = ReadAlbedo(f["albedo"], scene.bands.band_count());
  else if (v.phosphor && v.phosphor->albedo)
    v.albedo = *v.phosphor->albedo;
  else
    f.Fail("missing 'albedo' (the single-scattering albedo: a number or one value per band)");
  if (auto g = f.Optional("g")) v.g = g->NumberInRange(-0.99, 0.99);
  ReadPhosphorPolicy(f, v.phosphor != nullptr, v.unknown_ke_as_zero, v.initial);
  for (const Light& light : scene.lights)
    if (light.area())
      f.Fail("media are lit by point, directional and sheet lights only; '" + light.name + "' is an area light");
  return v;
}

}  // namespace

Eigen::Affine3d RigidMotion::At(double t_s) const {
  Eigen::Affine3d transform = Eigen::Affine3d::Identity();
  if (keys.empty()) return transform;
  const RigidKey* a = &keys.front();
  const RigidKey* b = a;
  double w = 0;
  if (t_s >= keys.back().t_s) {
    a = b = &keys.back();
  } else if (t_s > keys.front().t_s) {
    const auto next =
        std::upper_bound(keys.begin(), keys.end(), t_s, [](double t, const RigidKey& key) { return t < key.t_s; });
    b = &*next;
    a = &*(next - 1);
    w = (t_s - a->t_s) / (b->t_s - a->t_s);
  }
  transform.translate((1 - w) * a->translate + w * b->translate);
  transform.rotate(a->rotate.slerp(w, b->rotate));
  transform.scale((1 - w) * a->scale + w * b->scale);
  return transform;
}

bool RigidMotion::Moves() const {
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (!keys[i].translate.isApprox(keys[0].translate, 0) || !keys[i].rotate.isApprox(keys[0].rotate, 0) ||
        keys[i].scale != keys[0].scale)
      return true;
  return false;
}

bool RigidMotion::MovesBetween(double t0_s, double t1_s) const {
  if (!Moves()) return false;
  // Constant before the first and after the last keyframe.
  return t1_s > keys.front().t_s && t0_s < keys.back().t_s;
}

double LightSchedule::LevelAt(double t_s) const {
  double level = keys.empty() ? 1.0 : 0.0;
  for (const Key& key : keys)
    if (key.t_s <= t_s) level = key.level;
  return level;
}

std::vector<double> LightSchedule::ChangesBetween(double t0_s, double t1_s) const {
  std::vector<double> times;
  for (const Key& key : keys)
    if (key.t_s > t0_s && key.t_s < t1_s) times.push_back(key.t_s);
  return times;
}

CameraKey Camera::At(double t_s) const {
  if (keys.size() == 1 || t_s <= keys.front().t_s) return keys.front();
  if (t_s >= keys.back().t_s) return keys.back();
  const auto next =
      std::upper_bound(keys.begin(), keys.end(), t_s, [](double t, const CameraKey& key) { return t < key.t_s; });
  const CameraKey& a = *(next - 1);
  const CameraKey& b = *next;
  const double w = (t_s - a.t_s) / (b.t_s - a.t_s);
  return {t_s, (1 - w) * a.position + w * b.position, (1 - w) * a.look_at + w * b.look_at};
}

std::vector<double> Scene::FrameTimes() const {
  std::vector<double> times;
  const double step = 1.0 / fps;
  const auto count = static_cast<long long>(std::floor((end_s - start_s) / step + 1e-9));
  for (long long i = 0; i <= count; ++i) times.push_back(start_s + static_cast<double>(i) * step);
  return times;
}

bool Scene::HasPhosphors() const {
  return std::any_of(objects.begin(), objects.end(), [](const Object& o) { return o.phosphor != nullptr; }) ||
         std::any_of(volumes.begin(), volumes.end(), [](const Volume& v) { return v.phosphor != nullptr; });
}

bool Scene::AnyLightOnAt(double t_s) const {
  return std::any_of(lights.begin(), lights.end(), [&](const Light& l) { return l.schedule.LevelAt(t_s) > 0; }) ||
         (environment && environment->schedule.LevelAt(t_s) > 0);
}

std::string UnitsMismatch(const Material& material, const std::string& file, Units scene_units) {
  if (material.units == scene_units) return "";
  const bool physical = scene_units == Units::kPhysical;
  return std::string("the material '") + file + "' is " + UnitsName(material.units) + " and the scene " +
         UnitsName(scene_units) + ": a render is in one unit throughout; " +
         (physical ? "give the object a physical material (\"units\": \"physical\", docs/formats.md)"
                   : "say \"units\": \"physical\" in the scene and give its lights in W, lm, cd or lx");
}

std::string BandGridMismatch(const SpectralGrid& material_bands, const SpectralGrid& scene_bands) {
  if (material_bands == scene_bands) return "";
  return material_bands.EdgesName() + " differ from the scene's " + scene_bands.EdgesName() +
         "; the renderer needs one band grid: give the scene the material's bands_nm, or make the material "
         "on the scene's";
}

Scene LoadScene(const std::filesystem::path& path) {
  return SceneFromJson(ReadJsonFile(path), path.parent_path(), path.string());
}

Scene SceneFromJson(const nlohmann::json& json, const std::filesystem::path& base_dir, const std::string& source) {
  const JsonField root(json, source);
  root.RejectUnknownKeys({"schema", "name", "description", "units", "bands_nm", "time", "texel_size_m", "camera",
                          "render", "objects", "lights", "volumes", "environment"});
  if (root["schema"].String() != "phos.scene/1")
    root["schema"].Fail("expected \"phos.scene/1\", got " + DescribeJson(root["schema"].value()));
  Scene scene;
  scene.source = source;
  scene.name = root.Has("name") ? root["name"].String() : std::filesystem::path(source).stem().string();
  scene.units = ReadUnits(root);
  scene.bands = SpectralGrid::Paper();
  if (auto f = root.Optional("bands_nm")) ReadBands(*f, scene.bands);
  if (auto time = root.Optional("time")) ReadTimes(*time, scene);
  if (auto f = root.Optional("texel_size_m")) scene.texel_size_m = f->NumberInRange(1e-6, 1e6);
  ReadCamera(root["camera"], scene.camera);
  if (auto render = root.Optional("render")) ReadRenderSettings(*render, scene.settings);
  MaterialCache materials;  // of objects and volumes: each file loaded once
  ReadObjects(root["objects"], base_dir, materials, scene);
  ReadLights(root["lights"], base_dir, scene);
  if (auto f = root.Optional("environment")) scene.environment = ReadEnvironment(*f, scene.bands, scene.units);
  if (auto volumes = root.Optional("volumes")) {
    double voxels = 0;  // over every volume: they are all in memory at once
    for (std::size_t i = 0; i < volumes->ArraySize(); ++i)
      scene.volumes.push_back(ReadVolume(volumes->At(i), i, scene, base_dir, materials, voxels));
  }
  CheckTexelLimits(scene);
  return scene;
}

}  // namespace phos::render
