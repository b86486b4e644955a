#pragma once
// One editing session of the material editor page (Sec. 8.6, Fig. 8.20): a
// scene, the constraints an artist placed by clicking on its image, and the
// materials solved for them. Every edit re-solves at once. The HTTP server
// (server.h) is a thin layer over this class, which the tests drive directly.
//
// A constraint is a surface point (picked through a pixel), a time, a target
// colour (linear sRGB, as the page shows it) and a weight. The irradiance at
// each point over the scene's timeline comes from the renderer's lights and
// shadow rays, computed once when the point is placed. Targets become band
// radiance through the renderer's own colour conversion: the non-negative
// mix of at most three bands with exactly the asked colour and the least
// energy (see RgbToBands).
//
// Edit propagation (after Pellacini and Lawrence 2007): the solved material
// is carried to other phosphorescent objects in proportion to their
// similarity in albedo, position and orientation,
//   w = exp(-(|d_albedo|^2 + (d_position / scene diagonal)^2 + (1 - n . n') / 2) / falloff^2)
// (n: an object's area-weighted mean normal; 0: no propagation), blending kr
// in log space and ke and Lambda linearly. Materials are per object in the
// renderer, so edits propagate object by object.

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/editor/solve.h"
#include "phos/model/material.h"
#include "phos/render/geometry.h"
#include "phos/render/scene.h"

namespace phos::editor {

class EditSession {
 public:
  // root: the only folder exports may write into. presets: phos.material/1 files.
  EditSession(const std::filesystem::path& scene, const std::filesystem::path& presets_dir,
              const std::filesystem::path& root);

  // Everything the page shows: scene, timeline, objects, presets,
  // constraints, their curves (predicted RGB over the timeline) and targets,
  // the solution's cost, feedback and solve time.
  nlohmann::json State() const;
  // The view at t (direct transport, current materials), as PNG bytes.
  std::vector<unsigned char> FramePng(double t_s, double exposure) const;

  // Edits; each re-solves. Bad requests are UserErrors and change nothing.
  void AddConstraint(int x, int y, double t_s);  // the pixel must show a phosphorescent surface
  void UpdateConstraint(std::size_t index, const nlohmann::json& fields);  // rgb, t_s, weight, kind
  void RemoveConstraint(std::size_t index);
  void SetPreset(const std::string& object, const std::string& preset);
  // The states an edit solves for: 1 to 3, or nullopt for each object's own count.
  void SetStates(std::optional<int> states);
  void SetPropagation(double falloff);
  // The material of an object; and the same written under root (a relative
  // path inside it, no "..", no control characters, at most 1024 bytes). The
  // export never follows a symbolic link: every folder of the path is opened
  // under root with O_NOFOLLOW, and the file is written to a temporary beside
  // it (".NAME.tmp", created with O_EXCL | O_NOFOLLOW; another name if
  // something is there) and renamed over it.
  nlohmann::json MaterialJson(const std::string& object) const;
  std::filesystem::path ExportMaterial(const std::string& object, const std::string& relative_path) const;
  // What an export of the object is called: its name in lower case, other
  // characters as '-' ("back wall" -> "back-wall.json").
  std::string ExportFileName(const std::string& object) const;

  const render::Scene& scene() const { return scene_; }
  double last_solve_seconds() const { return last_solve_seconds_; }

 private:
  struct PlacedConstraint {
    int object = -1;
    Eigen::Vector3f position;
    std::vector<std::vector<double>> irradiance;  // per timeline frame, per band
    double t_s = 0;
    std::vector<double> rgb;  // target, linear sRGB
    // The point's look at placement, per band and as its rgb: while rgb is
    // that colour the target is those bands (exact: RGB to bands is not the
    // inverse of bands to RGB), else RgbToBands(rgb).
    std::vector<double> look_bands, look_rgb;
    const std::vector<double>* LookBands() const {
      return rgb == look_rgb && !look_bands.empty() ? &look_bands : nullptr;
    }
    double weight = 1;
    Constraint::Kind kind = Constraint::Kind::kTarget;
  };
  int ObjectIndex(const std::string& name) const;
  // The states an edit of an object wearing `wears` solves for.
  int StatesFor(const Material& wears) const;
  std::vector<double> RgbToBands(const std::vector<double>& rgb) const;
  std::vector<double> BandsToRgb(const std::vector<double>& bands) const;
  void Resolve();
  void ApplyMaterials();

  render::Scene scene_;
  std::unique_ptr<render::SceneGeometry> geometry_;
  std::filesystem::path root_;
  std::map<std::string, std::filesystem::path> presets_;
  std::vector<double> timeline_;  // frame start times
  double dt_s_ = 0.1;
  // The number of states the solve gives an edited object: set on the page,
  // or (nullopt) the object's own material's, so an edit starts from what it wears.
  std::optional<int> states_;
  double falloff_ = 0;
  std::vector<PlacedConstraint> constraints_;
  std::vector<std::shared_ptr<const Material>> base_;    // per object: before edits (scene or preset)
  std::vector<bool> base_unknown_ke_as_zero_;            // per object: the scene file's "unknown_ke" policy
  std::vector<std::shared_ptr<const Material>> solved_;  // per object: solved, or null
  std::vector<std::string> preset_;                      // per object: the preset set on it, or ""
  std::map<int, Solution> solutions_;                    // per edited object
  std::vector<double> xyz_to_rgb_weights_;               // 3 x nb: band radiance -> linear sRGB
  std::vector<int> wide_band_;                           // per band: 0 blue, 1 green, 2 red
  double last_solve_seconds_ = 0;
};

}  // namespace phos::editor
