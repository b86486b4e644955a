#include "phos/render/scene.h"

#include <algorithm>
#include <cmath>
#include <map>

#include <nlohmann/json.hpp>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos::render {
namespace {

constexpr double kPi = 3.14159265358979323846;

Vec3 ReadVec3(const JsonField& field) {
  const std::vector<double> v = field.NumberArray(3);
  return {v[0], v[1], v[2]};
}

Eigen::Quaterniond ReadRotation(const JsonField& field) {
  field.RejectUnknownKeys({"axis", "deg"});
  const Vec3 axis = ReadVec3(field["axis"]);
  if (axis.norm() == 0) field["axis"].Fail("the rotation axis must not be zero");
  return Eigen::Quaterniond(Eigen::AngleAxisd(field["deg"].Number() * kPi / 180, axis.normalized()));
}

RigidKey ReadRigidKey(const JsonField& field, bool with_time) {
  RigidKey key;
  if (with_time) {
    field.RejectUnknownKeys({"t_s", "translate", "rotate", "scale"});
    key.t_s = field["t_s"].Number();
  } else {
    field.RejectUnknownKeys({"translate", "rotate", "scale"});
  }
  if (auto f = field.Optional("translate")) key.translate = ReadVec3(*f);
  if (auto f = field.Optional("rotate")) key.rotate = ReadRotation(*f);
  if (auto f = field.Optional("scale")) {
    key.scale = f->Number();
    if (!(key.scale > 0)) f->Fail("expected a scale > 0, got " + DescribeJson(f->value()));
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

// A light's emission spectrum, normalized to unit integral, as band integrals.
std::vector<double> ReadSpectrum(const JsonField& field, const SpectralGrid& bands) {
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
    return field["values"].NumberArray(static_cast<std::size_t>(bands.band_count()), 0.0);
  } else {
    field["type"].Fail("unknown spectrum type '" + type + "' (led, white_led, blackbody, sun, bands)");
  }
  return IntegrateOverBands(spectrum, bands);
}

bool ReadBool(const JsonField& object, std::string_view key, bool fallback) {
  const auto field = object.Optional(key);
  if (!field) return fallback;
  if (!field->value().is_boolean()) field->Fail("expected true or false, got " + DescribeJson(field->value()));
  return field->value().get<bool>();
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
    const std::vector<double> size = field["size"].NumberArray(2, 1e-9);
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
    const double radius = field["radius"].NumberAtLeast(1e-9);
    const int subdivisions = field.Has("subdivisions") ? field["subdivisions"].Integer(0, 7) : 3;
    const bool inward = ReadBool(field, "inward", false);
    return std::make_shared<Mesh>(MakeSphere(radius, subdivisions, inward));
  }
  field["type"].Fail("unknown shape '" + type + "' (quad, box, sphere)");
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
    const auto next = std::upper_bound(keys.begin(), keys.end(), t_s,
                                       [](double t, const RigidKey& key) { return t < key.t_s; });
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
  const auto next = std::upper_bound(keys.begin(), keys.end(), t_s,
                                     [](double t, const CameraKey& key) { return t < key.t_s; });
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
  return std::any_of(objects.begin(), objects.end(), [](const Object& o) { return o.phosphor != nullptr; });
}

Scene LoadScene(const std::filesystem::path& path) {
  return SceneFromJson(ReadJsonFile(path), path.parent_path(), path.string());
}

Scene SceneFromJson(const nlohmann::json& json, const std::filesystem::path& base_dir, const std::string& source) {
  const JsonField root(json, source);
  root.RejectUnknownKeys({"schema", "name", "description", "bands_nm", "time", "texel_size_m", "camera", "render",
                          "objects", "lights"});
  if (root["schema"].String() != "phos.scene/1")
    root["schema"].Fail("expected \"phos.scene/1\", got " + DescribeJson(root["schema"].value()));
  Scene scene;
  scene.source = source;
  scene.name = root.Has("name") ? root["name"].String() : std::filesystem::path(source).stem().string();
  scene.bands = SpectralGrid::Paper();
  if (auto f = root.Optional("bands_nm")) {
    scene.bands.edges_nm = f->NumberArray(0, 1.0);
    if (scene.bands.edges_nm.size() < 2) f->Fail("expected at least two band edges");
    for (std::size_t i = 1; i < scene.bands.edges_nm.size(); ++i)
      if (!(scene.bands.edges_nm[i] > scene.bands.edges_nm[i - 1])) f->At(i).Fail("band edges must increase");
  }
  const int nb = scene.bands.band_count();

  if (auto time = root.Optional("time")) {
    time->RejectUnknownKeys({"start_s", "end_s", "fps"});
    if (time->Has("start_s")) scene.start_s = (*time)["start_s"].Number();
    if (time->Has("end_s")) scene.end_s = (*time)["end_s"].Number();
    if (time->Has("fps")) scene.fps = (*time)["fps"].NumberInRange(1e-6, 1e4);
    if (!(scene.end_s >= scene.start_s)) (*time)["end_s"].Fail("must not be before start_s");
    if ((scene.end_s - scene.start_s) * scene.fps > 1e6) (*time)["fps"].Fail("more than a million frames");
  }
  if (auto f = root.Optional("texel_size_m")) scene.texel_size_m = f->NumberInRange(1e-6, 1e6);

  // Camera.
  const JsonField camera = root["camera"];
  camera.RejectUnknownKeys({"position", "look_at", "up", "fov_deg", "width", "height", "exposure", "path"});
  CameraKey first;
  first.position = ReadVec3(camera["position"]);
  first.look_at = ReadVec3(camera["look_at"]);
  if ((first.position - first.look_at).norm() == 0) camera["look_at"].Fail("must differ from position");
  scene.camera.keys.push_back(first);
  if (auto path = camera.Optional("path")) {
    scene.camera.keys.clear();
    for (std::size_t i = 0; i < path->ArraySize(); ++i) {
      const JsonField key = path->At(i);
      key.RejectUnknownKeys({"t_s", "position", "look_at"});
      scene.camera.keys.push_back({key["t_s"].Number(), ReadVec3(key["position"]), ReadVec3(key["look_at"])});
    }
    if (scene.camera.keys.empty()) path->Fail("expected at least one keyframe");
    RequireIncreasingTimes(*path, scene.camera.keys);
  }
  if (auto f = camera.Optional("up")) scene.camera.up = ReadVec3(*f);
  if (scene.camera.up.norm() == 0) camera["up"].Fail("must not be zero");
  if (auto f = camera.Optional("fov_deg")) scene.camera.fov_deg = f->NumberInRange(1, 170);
  if (auto f = camera.Optional("width")) scene.camera.width = f->Integer(1, 16384);
  if (auto f = camera.Optional("height")) scene.camera.height = f->Integer(1, 16384);
  if (auto f = camera.Optional("exposure")) scene.camera.exposure = f->NumberAtLeast(0);

  if (auto render = root.Optional("render")) {
    render->RejectUnknownKeys({"spp", "max_depth", "direct_spp", "seed", "max_step_s", "phosphor_irradiance"});
    RenderSettings& s = scene.settings;
    if (render->Has("spp")) s.spp = (*render)["spp"].Integer(1, 1 << 20);
    if (render->Has("max_depth")) s.max_depth = (*render)["max_depth"].Integer(1, 1000);
    if (render->Has("direct_spp")) s.direct_spp = (*render)["direct_spp"].Integer(1, 1024);
    if (render->Has("seed")) s.seed = static_cast<unsigned>((*render)["seed"].Integer(0, 1 << 30));
    if (render->Has("max_step_s")) s.max_step_s = (*render)["max_step_s"].NumberInRange(1e-6, 1e9);
    s.phosphor_irradiance = ReadBool(*render, "phosphor_irradiance", false);
  }

  // Objects. Meshes and materials used twice are loaded once.
  std::map<std::string, std::shared_ptr<const Mesh>> meshes;
  std::map<std::string, std::shared_ptr<const Material>> materials;
  const JsonField objects = root["objects"];
  if (objects.ArraySize() == 0) objects.Fail("expected at least one object");
  for (std::size_t i = 0; i < objects.ArraySize(); ++i) {
    const JsonField o = objects.At(i);
    o.RejectUnknownKeys({"name", "mesh", "group", "shape", "albedo", "phosphor", "unknown_ke", "initial",
                         "texel_size_m", "texels", "uv_resolution", "transform", "animation"});
    Object object;
    object.name = o.Has("name") ? o["name"].NonEmptyString() : "object " + std::to_string(i);
    if (o.Has("mesh") == o.Has("shape")) o.Fail("give exactly one of 'mesh' (a file) or 'shape'");
    if (o.Has("mesh")) {
      const std::filesystem::path file = base_dir / o["mesh"].NonEmptyString();
      const std::string group = o.Has("group") ? o["group"].NonEmptyString() : "";
      const std::string key = file.string() + "#" + group;
      auto& mesh = meshes[key];
      if (!mesh) mesh = std::make_shared<Mesh>(LoadMesh(file, group, o["mesh"].source() + ": " + o["mesh"].path()));
      object.mesh = mesh;
    } else {
      object.mesh = ReadShape(o["shape"]);
    }
    if (object.mesh->triangles.empty()) o.Fail("the mesh has no triangles");
    object.motion = ReadMotion(o);
    if (o.Has("phosphor")) {
      const std::filesystem::path file = base_dir / o["phosphor"].NonEmptyString();
      auto& material = materials[file.string()];
      if (!material) material = std::make_shared<Material>(LoadMaterial(file));
      if (!(material->bands == scene.bands))
        o["phosphor"].Fail("the material's bands_nm differ from the scene's; the renderer needs one band grid");
      object.phosphor = material;
      object.phosphor_path = file.string();
    }
    if (o.Has("albedo")) {
      object.albedo = ReadAlbedo(o["albedo"], nb);
    } else if (object.phosphor && object.phosphor->albedo) {
      object.albedo = *object.phosphor->albedo;
    } else {
      o.Fail("missing 'albedo' (a number or one value per band)");
    }
    if (auto f = o.Optional("unknown_ke")) {
      const std::string policy = f->String();
      if (policy != "error" && policy != "zero") f->Fail("expected \"error\" or \"zero\", got \"" + policy + "\"");
      object.unknown_ke_as_zero = policy == "zero";
    }
    if (auto f = o.Optional("initial")) {
      if (f->value().is_number()) {
        object.initial = {InitialState::Kind::kUniform, f->NumberInRange(0, 1)};
      } else {
        const std::string kind = f->String();
        if (kind == "zero") object.initial.kind = InitialState::Kind::kZero;
        else if (kind == "equilibrium") object.initial.kind = InitialState::Kind::kEquilibrium;
        else f->Fail("expected \"zero\", \"equilibrium\" or a number in [0, 1], got \"" + kind + "\"");
      }
      if (!object.phosphor) f->Fail("only a phosphorescent object (with 'phosphor') has an initial state");
    }
    if (auto f = o.Optional("texel_size_m")) object.texel_size_m = f->NumberInRange(1e-6, 1e6);
    if (auto f = o.Optional("texels")) {
      object.texels = f->String();
      if (object.texels != "auto" && object.texels != "uv")
        f->Fail("expected \"auto\" or \"uv\", got \"" + object.texels + "\"");
      if (object.texels == "uv" && !object.mesh->has_uvs())
        f->Fail("the mesh has no UV map (" + object.mesh->source + "); use \"auto\"");
    }
    if (auto f = o.Optional("uv_resolution")) object.uv_resolution = f->Integer(1, 16384);
    scene.objects.push_back(std::move(object));
  }

  // Lights.
  const JsonField lights = root["lights"];
  for (std::size_t i = 0; i < lights.ArraySize(); ++i) {
    const JsonField l = lights.At(i);
    l.RejectUnknownKeys({"name", "type", "position", "direction", "intensity", "spectrum", "schedule", "path"});
    Light light;
    light.name = l.Has("name") ? l["name"].NonEmptyString() : "light " + std::to_string(i);
    const std::string type = l["type"].String();
    if (type == "point") {
      light.kind = Light::Kind::kPoint;
      if (l.Has("path")) {
        const JsonField path = l["path"];
        for (std::size_t k = 0; k < path.ArraySize(); ++k) {
          const JsonField key = path.At(k);
          key.RejectUnknownKeys({"t_s", "position"});
          RigidKey rigid;
          rigid.t_s = key["t_s"].Number();
          rigid.translate = ReadVec3(key["position"]);
          light.motion.keys.push_back(rigid);
        }
        if (light.motion.keys.empty()) path.Fail("expected at least one keyframe");
        RequireIncreasingTimes(path, light.motion.keys);
        if (l.Has("position")) l["position"].Fail("give either 'position' or 'path', not both");
      } else {
        light.position = ReadVec3(l["position"]);
      }
    } else if (type == "directional") {
      light.kind = Light::Kind::kDirectional;
      light.direction = ReadVec3(l["direction"]);
      if (light.direction.norm() == 0) l["direction"].Fail("must not be zero");
      light.direction.normalize();
    } else {
      l["type"].Fail("unknown light type '" + type + "' (point, directional)");
    }
    light.intensity = l["intensity"].NumberAtLeast(0);
    light.E_per_band = ReadSpectrum(l["spectrum"], scene.bands);
    for (double& e : light.E_per_band) e *= light.intensity;
    if (auto f = l.Optional("schedule")) {
      for (std::size_t k = 0; k < f->ArraySize(); ++k) {
        const JsonField key = f->At(k);
        key.RejectUnknownKeys({"t_s", "level"});
        light.schedule.keys.push_back({key["t_s"].Number(), key["level"].NumberAtLeast(0)});
      }
      if (light.schedule.keys.empty()) f->Fail("expected at least one {t_s, level}");
      RequireIncreasingTimes(*f, light.schedule.keys);
    }
    scene.lights.push_back(std::move(light));
  }
  return scene;
}

}  // namespace phos::render
