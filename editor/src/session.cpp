#include "phos/editor/session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <limits>

#include <Eigen/LU>
#include <fcntl.h>
#include <stb/stb_image_write.h>
#include <sys/stat.h>
#include <unistd.h>

#include "phos/render/renderer.h"
#include "phos/render/solver.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/math.h"

namespace phos::editor {
namespace {

constexpr int kTimelineFrames = 200;
// Bounds on what the page may ask, so that |T|^2 and the weights stay finite.
constexpr double kMaxRadiance = 1e6;
constexpr double kMaxWeight = 1e6;

// Export paths: at most this long, each name at most kMaxNameBytes (the
// system's 255, less room for the temporary's suffix).
constexpr std::size_t kMaxPathBytes = 1024;
constexpr std::size_t kMaxNameBytes = 200;

// A request's text in a message: a name of 60 KiB is not repeated whole.
std::string Shorten(const std::string& text) { return text.size() <= 80 ? text : text.substr(0, 77) + "..."; }

// The names of a path relative to root, or a UserError: absolute, "..",
// control characters (a NUL would cut the name short where it reaches the
// system) and names longer than the system takes are refused before any file
// is touched.
std::vector<std::string> NamesUnderRoot(const std::string& relative_path, const std::filesystem::path& root) {
  const auto outside = [&] {
    ThrowUserError("", "path",
                   "'" + Shorten(relative_path) + "' is outside the project's working folder " + root.string());
  };
  if (relative_path.empty())
    ThrowUserError("", "path", "expected a path inside the working folder, such as edited/wall.json");
  if (relative_path.size() > kMaxPathBytes)
    ThrowUserError(
        "", "path",
        "has " + std::to_string(relative_path.size()) + " characters, more than " + std::to_string(kMaxPathBytes));
  for (unsigned char ch : relative_path)
    if (ch < 0x20 || ch == 0x7f)
      ThrowUserError("", "path", "contains a control character (code " + std::to_string(ch) + ")");
  if (relative_path.front() == '/') outside();
  std::vector<std::string> names;
  for (std::size_t start = 0; start <= relative_path.size();) {
    const std::size_t end = std::min(relative_path.find('/', start), relative_path.size());
    const std::string name = relative_path.substr(start, end - start);
    if (name == "..") outside();
    if (name.size() > kMaxNameBytes)
      ThrowUserError("", "path",
                     "the name '" + Shorten(name) + "' is longer than " + std::to_string(kMaxNameBytes) + " bytes");
    if (!name.empty() && name != ".") names.push_back(name);
    start = end + 1;
  }
  if (names.empty()) outside();  // the folder itself
  return names;
}

struct FileDescriptor {
  int fd = -1;
  ~FileDescriptor() {
    if (fd >= 0) ::close(fd);
  }
};

// Writes text at root/names without following a symbolic link anywhere
// under root: each folder is opened with O_NOFOLLOW (and made if missing),
// the temporary beside the file is created with O_CREAT | O_EXCL |
// O_NOFOLLOW (whatever is already at its name, a planted link included, is
// never opened: another name is tried), written, synced and renamed over the
// file (a link in the file's place is replaced, not followed).
std::filesystem::path WriteUnderRoot(const std::filesystem::path& root, const std::vector<std::string>& names,
                                     const std::string& text) {
  std::filesystem::path shown = root;
  const auto fail = [&](const std::string& what) {
    ThrowUserError(shown.string(), "", what + " (" + std::strerror(errno) + ")");
  };
  FileDescriptor folder{::open(root.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)};
  if (folder.fd < 0) fail("cannot open the working folder");
  for (std::size_t k = 0; k + 1 < names.size(); ++k) {
    shown /= names[k];
    const int flags = O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC;
    int next = ::openat(folder.fd, names[k].c_str(), flags);
    if (next < 0 && errno == ENOENT) {
      if (::mkdirat(folder.fd, names[k].c_str(), 0755) != 0 && errno != EEXIST) fail("cannot create the folder");
      next = ::openat(folder.fd, names[k].c_str(), flags);
    }
    if (next < 0 && (errno == ELOOP || errno == ENOTDIR))
      ThrowUserError(shown.string(), "", "is a symbolic link or not a folder; exports do not follow links");
    if (next < 0) fail("cannot open the folder");
    ::close(folder.fd);
    folder.fd = next;
  }
  const std::string& name = names.back();
  shown /= name;
  std::string temporary;
  FileDescriptor file;
  for (int attempt = 0; attempt < 100 && file.fd < 0; ++attempt) {
    // Appended, not "." + std::to_string(...): GCC 12 warns on that
    // operator+ (-Wrestrict, a false positive: GCC bug 105329).
    temporary = "." + name + ".tmp";
    if (attempt > 0)
      temporary.append(".").append(std::to_string(::getpid())).append(".").append(std::to_string(attempt));
    file.fd = ::openat(folder.fd, temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
    if (file.fd < 0 && errno != EEXIST) fail("cannot create a temporary file beside it");
  }
  if (file.fd < 0) fail("cannot create a temporary file beside it");
  const auto abandon = [&](const std::string& what) {
    const int error = errno;
    ::unlinkat(folder.fd, temporary.c_str(), 0);
    errno = error;
    fail(what);
  };
  for (std::size_t written = 0; written < text.size();) {
    const ssize_t n = ::write(file.fd, text.data() + written, text.size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) abandon("cannot write");
    written += static_cast<std::size_t>(n);
  }
  if (::fsync(file.fd) != 0) abandon("cannot write");
  ::close(file.fd);
  file.fd = -1;
  if (::renameat(folder.fd, temporary.c_str(), folder.fd, name.c_str()) != 0) abandon("cannot replace");
  return shown;
}

}  // namespace

EditSession::EditSession(const std::filesystem::path& scene, const std::filesystem::path& presets_dir,
                         const std::filesystem::path& root)
    : scene_(render::LoadScene(scene)), root_(std::filesystem::weakly_canonical(root)) {
  geometry_ = std::make_unique<render::SceneGeometry>(scene_);
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(presets_dir, ec))
    if (entry.path().extension() == ".json") presets_[entry.path().stem().string()] = entry.path();
  const double span = scene_.end_s - scene_.start_s;
  dt_s_ = span > 0 ? span / kTimelineFrames : 0.1;
  for (int k = 0; k < kTimelineFrames; ++k) timeline_.push_back(scene_.start_s + dt_s_ * k);
  for (const render::Object& o : scene_.objects) {
    base_.push_back(o.phosphor);
    base_unknown_ke_as_zero_.push_back(o.unknown_ke_as_zero);
  }
  solved_.assign(scene_.objects.size(), nullptr);
  preset_.assign(scene_.objects.size(), "");
  // Band radiance -> linear sRGB: the renderer's own conversion (one pixel per band).
  const int nb = scene_.bands.band_count();
  render::Image unit(nb, 1, nb);
  for (int b = 0; b < nb; ++b) unit.at(b, 0)[b] = 1.0f;
  const render::Image rgb = render::BandsToLinearSrgb(unit, scene_.bands);
  xyz_to_rgb_weights_.assign(3 * nb, 0.0);
  for (int b = 0; b < nb; ++b)
    for (int c = 0; c < 3; ++c) xyz_to_rgb_weights_[c * nb + b] = rgb.at(b, 0)[c];
  for (int b = 0; b < nb; ++b) {
    const double centre = scene_.bands.center_nm(b);
    wide_band_.push_back(centre < 490 ? 0 : centre < 580 ? 1 : 2);
  }
}

std::vector<double> EditSession::BandsToRgb(const std::vector<double>& bands) const {
  const int nb = scene_.bands.band_count();
  std::vector<double> rgb(3, 0.0);
  for (int c = 0; c < 3; ++c)
    for (int b = 0; b < nb; ++b) rgb[c] += xyz_to_rgb_weights_[c * nb + b] * bands[b];
  return rgb;
}

std::vector<double> EditSession::RgbToBands(const std::vector<double>& rgb) const {
  // A non-negative band spectrum with exactly the asked colour. By
  // Caratheodory's theorem a colour in the cone of the bands' colours is a
  // non-negative mix of at most three bands: try every three (56 for 8 bands)
  // and keep the mix of least energy (the most spread). A colour no spectrum
  // makes (outside the cone) falls back to flat radiance over three wide
  // bands, clipped at zero.
  const int nb = scene_.bands.band_count();
  const Eigen::Vector3d target(rgb[0], rgb[1], rgb[2]);
  std::vector<double> best;
  double best_energy = std::numeric_limits<double>::infinity();
  for (int a = 0; a < nb; ++a)
    for (int b = a + 1; b < nb; ++b)
      for (int c = b + 1; c < nb; ++c) {
        Eigen::Matrix3d M;
        for (int k = 0; k < 3; ++k) {
          M(k, 0) = xyz_to_rgb_weights_[k * nb + a];
          M(k, 1) = xyz_to_rgb_weights_[k * nb + b];
          M(k, 2) = xyz_to_rgb_weights_[k * nb + c];
        }
        const Eigen::FullPivLU<Eigen::Matrix3d> lu(M);
        if (!lu.isInvertible()) continue;
        const Eigen::Vector3d x = lu.solve(target);
        if (x.minCoeff() < -1e-12 * std::max(1.0, target.norm())) continue;
        const double energy = x.squaredNorm();
        if (energy < best_energy) {
          best_energy = energy;
          best.assign(nb, 0.0);
          best[a] = std::max(0.0, x[0]);
          best[b] = std::max(0.0, x[1]);
          best[c] = std::max(0.0, x[2]);
        }
      }
  if (!best.empty()) return best;
  double width[3] = {0, 0, 0};
  for (int b = 0; b < nb; ++b) width[wide_band_[b]] += scene_.bands.width_nm(b);
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  for (int b = 0; b < nb; ++b)
    for (int c = 0; c < 3; ++c)
      if (width[wide_band_[b]] > 0)
        M(c, wide_band_[b]) += xyz_to_rgb_weights_[c * nb + b] * scene_.bands.width_nm(b) / width[wide_band_[b]];
  const Eigen::Vector3d wide = M.fullPivLu().solve(target).cwiseMax(0.0);
  std::vector<double> bands(nb);
  for (int b = 0; b < nb; ++b)
    bands[b] = width[wide_band_[b]] > 0 ? wide[wide_band_[b]] * scene_.bands.width_nm(b) / width[wide_band_[b]] : 0.0;
  return bands;
}

int EditSession::ObjectIndex(const std::string& name) const {
  for (std::size_t o = 0; o < scene_.objects.size(); ++o)
    if (scene_.objects[o].name == name) return static_cast<int>(o);
  ThrowUserError("", "object", "the scene has no object '" + Shorten(name) + "'");
}

void EditSession::AddConstraint(int x, int y, double t_s) {
  if (constraints_.size() >= kMaxConstraints)
    ThrowUserError(
        "", "constraints",
        "the session has " + std::to_string(constraints_.size()) + " constraints, the limit; remove one first");
  const render::Camera& camera = scene_.camera;
  if (x < 0 || y < 0 || x >= camera.width || y >= camera.height)
    ThrowUserError("", "x, y",
                   "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is outside the " +
                       std::to_string(camera.width) + "x" + std::to_string(camera.height) + " image");
  if (!(t_s >= scene_.start_s && t_s <= scene_.end_s))
    ThrowUserError("", "t_s", FormatDouble(t_s) + " s is outside the scene's time range");
  // The camera ray through the pixel's centre (the renderer's own camera).
  geometry_->SetTime(scene_.start_s);  // the last frame shown left it at its time
  const render::CameraRays rays(scene_, scene_.start_s);
  const render::Hit hit = geometry_->Intersect(rays.origin(), rays.Direction(x + 0.5f, y + 0.5f));
  if (!hit || !scene_.objects[hit.object].phosphor)
    ThrowUserError("", "x, y",
                   "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") shows " +
                       (hit ? "'" + scene_.objects[hit.object].name + "', which is not phosphorescent" : "nothing"));
  if (!hit.front)
    ThrowUserError("", "x, y", "that is the back of '" + scene_.objects[hit.object].name + "', which does not glow");
  PlacedConstraint c;
  c.object = hit.object;
  c.position = hit.position;
  c.t_s = t_s;
  // The irradiance there over the timeline, from every light (shadow rays), once.
  const int nb = scene_.bands.band_count();
  for (double t : timeline_) {
    std::vector<double> E(nb, 0.0);
    const double mid = t + 0.5 * dt_s_;
    for (const render::Light& light : scene_.lights) {
      const double level = light.schedule.LevelAt(mid);
      if (level <= 0) continue;
      const double unit = render::UnitIrradiance(*geometry_, render::PoseAt(light, mid), hit.position, hit.normal);
      for (int b = 0; b < nb; ++b) E[b] += level * light.E_per_band[b] * unit;
    }
    c.irradiance.push_back(E);
  }
  const std::string where =
      "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") on '" + scene_.objects[hit.object].name + "'";
  bool lit = false;
  for (const auto& E : c.irradiance)
    for (double e : E) lit = lit || e > 0;
  // An edge pixel's point can be shadowed by the neighbouring wall: nothing
  // charges there, and a target at it could only be met with Lambda = 0.
  if (!lit)
    ThrowUserError("", "x, y",
                   where +
                       ": no light reaches that point at any time (an edge, or in shadow), so nothing "
                       "can charge it; click inside the lit surface");
  // The target starts as what the point looks like now.
  const render::Object& object = scene_.objects[hit.object];
  Problem probe;
  probe.bands = scene_.bands;
  probe.dt_s = dt_s_;
  probe.points.push_back({c.irradiance, object.albedo});
  const Material& now = *(solved_[hit.object] ? solved_[hit.object] : base_[hit.object]);
  Material known = now;
  AssumeUnknownKeZero(known);  // only a curve to start the target from
  c.look_bands = PredictRadiance(probe, known, {t_s - scene_.start_s})[0];
  for (double& v : c.look_bands) v = std::max(v, 0.0);
  c.rgb = BandsToRgb(c.look_bands);
  for (double& v : c.rgb) v = std::max(v, 0.0);
  c.look_rgb = c.rgb;
  if (*std::max_element(c.rgb.begin(), c.rgb.end()) <= 0)
    ThrowUserError("", "x, y",
                   where + " is black at t = " + FormatShort(t_s, 4) +
                       " s, and a target of zero would give it Lambda = 0 (no glow); place it at a time "
                       "when the point is lit or glows");
  constraints_.push_back(c);
  Resolve();
}

void EditSession::UpdateConstraint(std::size_t index, const nlohmann::json& fields) {
  if (index >= constraints_.size()) ThrowUserError("", "index", "no constraint " + std::to_string(index));
  PlacedConstraint c = constraints_[index];
  const JsonField f(fields, "request");
  f.RejectUnknownKeys({"index", "rgb", "t_s", "weight", "kind"});
  if (f.Has("rgb")) {
    const JsonField rgb = f["rgb"];
    if (rgb.ArraySize() != 3) rgb.Fail("expected 3 values (R, G, B), got " + std::to_string(rgb.ArraySize()));
    for (std::size_t k = 0; k < 3; ++k) c.rgb[k] = rgb.At(k).NumberInRange(0, kMaxRadiance);
    // The weight is 1 / |T|^2 and the solve meets a zero target with Lambda = 0:
    // the object would silently stop glowing.
    if (*std::max_element(c.rgb.begin(), c.rgb.end()) <= 0)
      rgb.Fail(
          "a target of [0, 0, 0] would give the object Lambda = 0 (no glow at all); give the colour it should have");
  }
  if (f.Has("t_s")) c.t_s = f["t_s"].NumberInRange(scene_.start_s, scene_.end_s);
  if (f.Has("weight")) c.weight = f["weight"].NumberInRange(0, kMaxWeight);
  if (f.Has("kind")) {
    const std::string kind = f["kind"].String();
    if (kind == "target")
      c.kind = Constraint::Kind::kTarget;
    else if (kind == "at_least")
      c.kind = Constraint::Kind::kAtLeast;
    else if (kind == "at_most")
      c.kind = Constraint::Kind::kAtMost;
    else
      f["kind"].Fail("expected target, at_least or at_most");
  }
  constraints_[index] = c;  // only once every field is valid
  Resolve();
}

void EditSession::RemoveConstraint(std::size_t index) {
  if (index >= constraints_.size()) ThrowUserError("", "index", "no constraint " + std::to_string(index));
  constraints_.erase(constraints_.begin() + static_cast<std::ptrdiff_t>(index));
  Resolve();
}

void EditSession::SetPreset(const std::string& object, const std::string& preset) {
  const int o = ObjectIndex(object);
  if (!scene_.objects[o].phosphor) ThrowUserError("", "object", "'" + object + "' is not phosphorescent");
  const auto it = presets_.find(preset);
  if (it == presets_.end()) ThrowUserError("", "preset", "no preset '" + Shorten(preset) + "'");
  auto material = std::make_shared<Material>(LoadMaterial(it->second));
  if (const std::string mismatch = render::BandGridMismatch(material->bands, scene_.bands); !mismatch.empty())
    ThrowUserError(it->second.string(), "bands_nm", mismatch);
  base_[o] = material;
  preset_[o] = preset;
  Resolve();
}

void EditSession::SetStates(std::optional<int> states) {
  if (states && (*states < 1 || *states > 3)) ThrowUserError("", "states", "expected 1, 2 or 3 (or null)");
  states_ = states;
  Resolve();
}

int EditSession::StatesFor(const Material& wears) const {
  return states_ ? *states_ : std::clamp(wears.state_count(), 1, kMaxEditStates);
}

void EditSession::SetPropagation(double falloff) {
  if (!(falloff >= 0 && falloff <= 10)) ThrowUserError("", "falloff", "expected a number in [0, 10]");
  falloff_ = falloff;
  Resolve();
}

void EditSession::Resolve() {
  const auto start = std::chrono::steady_clock::now();
  // What each object wore before any edit (the scene's material, or a
  // preset): the solve starts from it, so a solve depends on the constraints
  // and settings alone, never on the edits before it (undoing one gives the
  // session it undid).
  const std::vector<std::shared_ptr<const Material>>& wears = base_;
  solutions_.clear();
  std::fill(solved_.begin(), solved_.end(), nullptr);
  // One problem per edited object: its constraints' points share its material.
  std::map<int, Problem> problems;
  for (std::size_t i = 0; i < constraints_.size(); ++i) {
    const PlacedConstraint& c = constraints_[i];
    Problem& p = problems[c.object];
    p.source = "editor: '" + scene_.objects[c.object].name + "'";
    p.bands = scene_.bands;
    p.dt_s = dt_s_;
    p.states = StatesFor(*wears[c.object]);
    if (wears[c.object]->state_count() == p.states) p.start = *wears[c.object];
    p.points.push_back({c.irradiance, scene_.objects[c.object].albedo});
    Constraint constraint;
    constraint.kind = c.kind;
    constraint.point = static_cast<int>(p.points.size()) - 1;
    constraint.t_s = constraint.until_s = c.t_s - scene_.start_s;
    if (c.kind != Constraint::Kind::kTarget) constraint.until_s = scene_.end_s - scene_.start_s;  // "until the end"
    constraint.radiance = c.LookBands() ? *c.LookBands() : RgbToBands(c.rgb);
    // Relative error counts: a faint glow matters as much as a lit look.
    double norm2 = 0;
    for (double v : constraint.radiance) norm2 += v * v;
    constraint.weight = c.weight / std::max(norm2, 1e-12);
    constraint.label = "constraint " + std::to_string(i + 1);
    p.constraints.push_back(constraint);
  }
  for (auto& [object, problem] : problems) {
    Solution solution = Solve(problem);
    auto material = std::make_shared<Material>(solution.material);
    if (!solution.kept_start) {  // a material kept as it was keeps its name and albedo
      material->name = scene_.objects[object].name + " (edited)";
      material->albedo.reset();
    }
    solved_[object] = material;
    solutions_[object] = std::move(solution);
  }
  ApplyMaterials();
  last_solve_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void EditSession::ApplyMaterials() {
  // Edited objects wear their solution; the others, their base material, or a
  // blend toward the most similar edited object's solution (edit propagation).
  Eigen::AlignedBox3f scene_box;
  std::vector<Eigen::Vector3f> centre(scene_.objects.size()), normal(scene_.objects.size());
  for (std::size_t o = 0; o < scene_.objects.size(); ++o) {
    Eigen::AlignedBox3f box;
    Eigen::Vector3f area_normal = Eigen::Vector3f::Zero();
    for (int t = 0; t < geometry_->triangle_count(static_cast<int>(o)); ++t) {
      for (int k = 0; k < 3; ++k) box.extend(geometry_->Vertex(static_cast<int>(o), t, k));
      area_normal += geometry_->Area(static_cast<int>(o), t) * geometry_->FrontNormal(static_cast<int>(o), t);
    }
    centre[o] = box.center();
    normal[o] = area_normal.norm() > 0 ? Eigen::Vector3f(area_normal.normalized()) : Eigen::Vector3f::Zero();
    scene_box.extend(box);
  }
  const double diagonal = scene_box.diagonal().norm();
  for (std::size_t o = 0; o < scene_.objects.size(); ++o) {
    render::Object& object = scene_.objects[o];
    if (!object.phosphor) continue;
    std::shared_ptr<const Material> material = solved_[o] ? solved_[o] : base_[o];
    if (!solved_[o] && falloff_ > 0) {
      double best_w = 0;
      std::shared_ptr<const Material> source;
      for (const auto& [edited, solution] : solutions_) {
        double d_albedo = 0;
        for (std::size_t b = 0; b < object.albedo.size(); ++b)
          d_albedo += std::pow(object.albedo[b] - scene_.objects[edited].albedo[b], 2);
        const double d_position = (centre[o] - centre[edited]).norm() / diagonal;
        // Closed objects average their normals to ~0: then orientation says nothing.
        const double d_normal = 0.5 * (1.0 - normal[o].dot(normal[edited])) * normal[o].norm() * normal[edited].norm();
        const double w = std::exp(-(d_albedo + d_position * d_position + d_normal) / (falloff_ * falloff_));
        if (w > best_w) {
          best_w = w;
          source = solved_[edited];
        }
      }
      if (source && best_w > 0.01) {
        auto blended = std::make_shared<Material>(*source);
        const Material& base = *base_[o];
        if (base.state_count() == source->state_count()) {
          for (int i = 0; i < source->state_count(); ++i) {
            ExcitedState& s = blended->states[i];
            const ExcitedState& b = base.states[i];
            s.kr = std::exp((1 - best_w) * std::log(b.kr) + best_w * std::log(s.kr));
            // A blend with an unknown ke is unknown: neither side says what it is.
            for (std::size_t k = 0; k < s.ke.size(); ++k)
              s.ke[k] = b.ke[k] && s.ke[k] ? std::optional<double>((1 - best_w) * *b.ke[k] + best_w * *s.ke[k])
                                           : std::nullopt;
            for (std::size_t k = 0; k < s.Lambda.size(); ++k)
              s.Lambda[k] = (1 - best_w) * b.Lambda[k] + best_w * s.Lambda[k];
          }
        } else if (best_w < 0.5) {
          blended = std::make_shared<Material>(base);
        }
        blended->name = object.name + " (propagated, w = " + FormatShort(best_w, 2) + ")";
        material = blended;
      }
    }
    object.phosphor = material;
    // A solved material leaves ke unknown in the bands no light reaches at its
    // constraints' points (the solve cannot tell any ke there from another),
    // and the export says so. Other points of the object, or the glow of its
    // neighbours, may still light those bands: the view alone takes unknown
    // ke as 0 for edited objects (State() says which bands), so it can be drawn.
    object.unknown_ke_as_zero = material != base_[o] || base_unknown_ke_as_zero_[o];
  }
}

nlohmann::json EditSession::State() const {
  nlohmann::json objects = nlohmann::json::array();
  for (std::size_t o = 0; o < scene_.objects.size(); ++o) {
    const render::Object& object = scene_.objects[o];
    // Bands where the material's ke is unknown (for a solved one: no light
    // reaches its constraints' points there); the view takes them as 0 only
    // when the object does (unknown_ke_assumed_zero).
    nlohmann::json unknown_ke = nlohmann::json::array();
    if (object.phosphor)
      for (int b = 0; b < scene_.bands.band_count(); ++b) {
        bool unknown = false;
        for (const ExcitedState& state : object.phosphor->states) unknown = unknown || !state.ke[b];
        if (unknown) unknown_ke.push_back(scene_.bands.BandName(b));
      }
    objects.push_back({{"name", object.name},
                       {"phosphorescent", object.phosphor != nullptr},
                       {"material", object.phosphor ? object.phosphor->name : ""},
                       {"states", base_[o] ? StatesFor(*base_[o]) : 0},
                       // The preset it wears, "" when it wears its scene's material or an edit.
                       {"preset", solved_[o] ? "" : preset_[o]},
                       {"edited", solved_[o] != nullptr},
                       {"export_name", object.phosphor ? ExportFileName(object.name) : ""},
                       {"unknown_ke", unknown_ke},
                       {"unknown_ke_assumed_zero", object.unknown_ke_as_zero}});
  }
  nlohmann::json presets = nlohmann::json::array();
  for (const auto& [name, path] : presets_) presets.push_back(name);
  nlohmann::json constraints = nlohmann::json::array();
  for (std::size_t i = 0; i < constraints_.size(); ++i) {
    const PlacedConstraint& c = constraints_[i];
    Problem probe;
    probe.bands = scene_.bands;
    probe.dt_s = dt_s_;
    probe.points.push_back({c.irradiance, scene_.objects[c.object].albedo});
    Material material = *scene_.objects[c.object].phosphor;
    AssumeUnknownKeZero(material);  // the curves show it; unknown ke means unlit there
    std::vector<double> times;
    for (double t : timeline_) times.push_back(t - scene_.start_s);
    times.push_back(c.t_s - scene_.start_s);
    const auto L = PredictRadiance(probe, material, times);
    nlohmann::json curve = nlohmann::json::array();
    for (std::size_t k = 0; k + 1 < L.size(); ++k) curve.push_back(BandsToRgb(L[k]));
    const std::vector<double> predicted = BandsToRgb(L.back());
    // Against the target the solve was given: the bands of a look taken at
    // placement (whose RGB may lie outside sRGB, shown clamped), else the RGB.
    const std::vector<double>& target = c.LookBands() ? *c.LookBands() : c.rgb;
    const std::vector<double>& got = c.LookBands() ? L.back() : predicted;
    double error = 0, norm = 0;
    for (std::size_t k = 0; k < target.size(); ++k) {
      error += std::pow(got[k] - target[k], 2);
      norm += target[k] * target[k];
    }
    const char* kind = c.kind == Constraint::Kind::kTarget    ? "target"
                       : c.kind == Constraint::Kind::kAtLeast ? "at_least"
                                                              : "at_most";
    constraints.push_back({{"object", scene_.objects[c.object].name},
                           {"t_s", c.t_s},
                           {"rgb", c.rgb},
                           {"weight", c.weight},
                           {"kind", kind},
                           {"predicted", predicted},
                           {"relative_error", std::sqrt(error / std::max(norm, 1e-300))},
                           {"curve", curve}});
  }
  nlohmann::json solutions = nlohmann::json::array();
  for (const auto& [object, solution] : solutions_)
    solutions.push_back({{"object", scene_.objects[object].name},
                         {"cost", solution.cost},
                         {"feedback", solution.feedback},
                         {"seconds", solution.seconds},
                         {"material", MaterialToJson(solution.material)}});
  return {{"scene", scene_.name},
          {"width", scene_.camera.width},
          {"height", scene_.camera.height},
          {"exposure", scene_.camera.exposure},
          {"start_s", scene_.start_s},
          {"end_s", scene_.end_s},
          {"dt_s", dt_s_},
          {"timeline", timeline_},
          {"objects", objects},
          {"presets", presets},
          {"states", states_ ? nlohmann::json(*states_) : nlohmann::json(nullptr)},
          {"falloff", falloff_},
          {"constraints", constraints},
          {"solutions", solutions},
          {"solve_ms", last_solve_seconds_ * 1e3}};
}

std::vector<unsigned char> EditSession::FramePng(double t_s, double exposure) const {
  if (!(t_s >= scene_.start_s && t_s <= scene_.end_s + 1e-9))
    ThrowUserError("", "t", FormatDouble(t_s) + " s is outside the scene's time range");
  // A solver starts at the scene's start, and AdvanceTo(start) moves nothing,
  // geometry included; but the renderer reads the lights' levels at the
  // geometry's time, which the previous frame left where it was. So t = 0
  // after a frame past lamp-off was lit as at that frame (black): the
  // geometry goes back to the start first.
  geometry_->SetTime(scene_.start_s);
  render::CoupledSolver solver(scene_, *geometry_);
  solver.AdvanceTo(t_s);
  const render::Image bands =
      render::RenderBands(*geometry_, &solver, render::DefaultFrameOptions(scene_, render::Transport::kDirect));
  const render::Image display = render::ToneMap(render::BandsToLinearSrgb(bands, scene_.bands), exposure);
  std::vector<unsigned char> pixels(display.pixels.size());
  for (std::size_t i = 0; i < pixels.size(); ++i)
    pixels[i] = static_cast<unsigned char>(std::lround(std::clamp(display.pixels[i], 0.0f, 1.0f) * 255));
  std::vector<unsigned char> png;
  stbi_write_png_to_func(
      [](void* context, void* data, int size) {
        auto* out = static_cast<std::vector<unsigned char>*>(context);
        out->insert(out->end(), static_cast<unsigned char*>(data), static_cast<unsigned char*>(data) + size);
      },
      &png, display.width, display.height, 3, pixels.data(), display.width * 3);
  return png;
}

nlohmann::json EditSession::MaterialJson(const std::string& object) const {
  const int o = ObjectIndex(object);
  if (!scene_.objects[o].phosphor) ThrowUserError("", "object", "'" + object + "' is not phosphorescent");
  return MaterialToJson(*scene_.objects[o].phosphor);
}

std::string EditSession::ExportFileName(const std::string& object) const {
  const int o = ObjectIndex(object);
  std::string name;
  for (unsigned char ch : scene_.objects[o].name) {
    if (std::isalnum(ch))
      name += static_cast<char>(std::tolower(ch));
    else if (!name.empty() && name.back() != '-')
      name += '-';
  }
  while (!name.empty() && name.back() == '-') name.pop_back();
  return (name.empty() ? std::string("material") : name.substr(0, kMaxNameBytes - 5)) + ".json";
}

std::filesystem::path EditSession::ExportMaterial(const std::string& object, const std::string& relative_path) const {
  const std::vector<std::string> names = NamesUnderRoot(relative_path, root_);
  if (!names.back().ends_with(".json")) ThrowUserError("", "path", "a material file ends in .json");
  const int o = ObjectIndex(object);
  if (!scene_.objects[o].phosphor) ThrowUserError("", "object", "'" + object + "' is not phosphorescent");
  const Material& material = *scene_.objects[o].phosphor;
  ValidateMaterial(material, relative_path);
  return WriteUnderRoot(root_, names, MaterialToJson(material).dump(2) + "\n");
}

}  // namespace phos::editor
