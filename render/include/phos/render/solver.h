#pragma once
// The coupled solver (Sec. 8.5): the rate-equation state of every
// phosphorescent texel, advanced through the scene's time while lights switch
// and objects move.
//
// Model only what the scene requires (docs/render.md, "The coupled solver"):
//  - only phosphorescent objects have texels and states;
//  - a material's batch coefficients keep only the bands the scene's lights
//    reach (excitation) and the bands it emits (Lambda > 0);
//  - the geometric part of each light's irradiance at each texel (cosine,
//    distance, shadow ray) is cached and recomputed only when that light or
//    the geometry moved; a light switching or dimming only rescales it;
//  - a sky (Environment) charges them too, by shadow rays computed once per
//    geometry;
//  - while every light is off the state jumps in closed form (DecayBatch), at
//    no cost in the length of the interval: a frame an hour after lights-out
//    costs what the first did.

#include <cstddef>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "phos/model/batch.h"
#include "phos/render/geometry.h"
#include "phos/render/scene.h"

namespace phos::render {

struct SolverStats {
  std::size_t texels = 0;
  std::size_t steps = 0;               // lit steps (AdvanceBatch)
  std::size_t dark_jumps = 0;          // closed-form dark steps (DecayBatch)
  std::size_t irradiance_updates = 0;  // per-light geometry recomputations (each: one shadow ray per texel)
  std::size_t shadow_rays = 0;
  std::size_t glow_patches = 0;  // phosphor_irradiance: source/receiver patches
};

class VolumeMedia;

// The coupled solver's state at one frame: all that a frame needs from it
// (the states r and the emission Lp of every phosphorescent texel and voxel),
// so that frames from `frame` on render without the solver's past. Written by
// `phos render --solve-only` at the start of each frame range and read by the
// range's task. The floats are kept bit for bit, so a range rendered from a
// checkpoint equals the same frames of one sequential run.
//
// File (docs/formats.md, "Solver state"): one line of JSON, the header below
// (ToJson), then the arrays as little-endian float32, back to back, in the
// header's order and sizes.
struct SolverCheckpoint {
  static constexpr const char* kFormat = "phos.solver-state/1";
  double time_s = 0;
  int frame = 0;      // index of the frame at time_s in the run's frame list
  std::string scene;  // the scene's name, to refuse a state of another scene
  // Per texel group (object) in atlas order: r (nc * n), then Lp (n_em * n);
  // then per phosphorescent volume the same two.
  std::vector<std::vector<float>> arrays;

  nlohmann::json HeaderJson() const;  // everything but the arrays' values
};
// Atomic (util/atomic_file.h): a killed solver pass leaves no half a state.
void WriteSolverCheckpoint(const std::filesystem::path& path, const SolverCheckpoint& checkpoint);
// UserError naming the file when it is not a whole checkpoint.
SolverCheckpoint ReadSolverCheckpoint(const std::filesystem::path& path);

class CoupledSolver {
 public:
  // Places the geometry at scene.start_s and sets the initial states.
  CoupledSolver(const Scene& scene, SceneGeometry& geometry);
  ~CoupledSolver();

  // Advances every state from time_s() to t_s (>= time_s()), splitting steps at
  // light switches and, while something moves, at the scene's max_step_s.
  void AdvanceTo(double t_s);
  double time_s() const { return time_s_; }

  const TexelAtlas& atlas() const { return atlas_; }
  int band_count() const { return band_count_; }
  // Emitted radiance Lp (Eq. 8.2) of texel j of object slot s in scene band b;
  // 0 for bands the material does not emit.
  float Lp(int slot, int band, std::size_t texel) const {
    const Group& g = groups_[slot];
    const int e = g.emission_index[band];
    return e < 0 ? 0.0f : g.Lp[static_cast<std::size_t>(e) * g.states.n + texel];
  }
  // The Lp of every texel of slot s in scene band b, consecutive (band-major
  // storage); null for a band the material does not emit.
  const float* LpOfBand(int slot, int band) const {
    const Group& g = groups_[slot];
    const int e = g.emission_index[band];
    return e < 0 ? nullptr : g.Lp.data() + static_cast<std::size_t>(e) * g.states.n;
  }
  // State i of texel j of object slot s.
  float State(int slot, int i, std::size_t texel) const { return groups_[slot].states.state(i)[texel]; }
  const std::vector<int>& excitation_bands(int slot) const { return groups_[slot].excitation_bands; }
  const std::vector<int>& emission_bands(int slot) const { return groups_[slot].emission_bands; }
  const SolverStats& stats() const { return stats_; }
  // The scene's media (volume.h), with the phosphorescent voxels' states;
  // null without volumes. Non-const: it caches the voxels' light per frame.
  VolumeMedia* media() const { return media_.get(); }

  // The state now, for a checkpoint (frame: the caller's frame index).
  SolverCheckpoint Checkpoint(int frame) const;
  // Takes the state of a checkpoint of this scene (time and arrays); a
  // checkpoint that does not fit the scene's texels is a UserError naming `source`.
  void Restore(const SolverCheckpoint& checkpoint, const std::string& source);

  // Phosphors that a light never charged (a triangle wound away from its
  // light is lit but never glows, and nothing said why). Since this
  // solver started, for each object slot: was a light (or the sky) that
  // reaches the material's excitation bands on, and did any texel of the
  // object receive its irradiance? If not, were some texels lit on their
  // back (the front is the side the counter-clockwise winding faces; only
  // the front charges, Sec. 8.3.4)?
  struct ChargeReport {
    bool light_on = false;        // a light reaching its excitation bands was on
    bool received = false;        // some texel received irradiance
    bool lit_from_behind = false;  // while none did, some sampled texel faced away from a light that reached its back
    bool NeverCharged() const { return light_on && !received; }
  };
  const ChargeReport& charge_report(int slot) const { return groups_[slot].charge; }

  // A transport's tables derived from this atlas and the geometry alone,
  // kept from frame to frame while nothing moves: the path transport's
  // glowing triangles of a large mesh (transport_path.cpp), whose writing
  // was the largest part of a 1.3M-triangle mesh's frame set-up. One slot,
  // typed by its one user; null when none is kept for the geometry's
  // version() now.
  std::shared_ptr<const void> DerivedTables() const;
  void KeepDerivedTables(std::shared_ptr<const void> tables) const;

  // The irradiance (per scene band) that the lights put on texel j of slot s now.
  std::vector<double> TexelIrradiance(int slot, std::size_t texel);
  // With phosphor_irradiance: the irradiance (per scene band) the phosphors'
  // glow puts on texel j of slot s now; zeros without it.
  std::vector<double> TexelGlowIrradiance(int slot, std::size_t texel);

 private:
  struct Group {
    int object = -1;
    std::vector<int> excitation_bands, emission_bands;
    std::vector<int> emission_index;  // per scene band: index into emission_bands or -1
    BatchCoefficients<float> coefficients;
    StateBatch<float> states;
    std::vector<float> Lp;  // [n_em * n]
    std::vector<float> E;   // [n_exc * n], scratch
    // Per light: irradiance per unit of the light's band irradiance (geometry
    // only: cos / d^2 and visibility), and where it was computed.
    std::vector<std::vector<float>> unit_E;
    std::vector<LightPose> unit_E_light_at;
    std::vector<std::uint64_t> unit_E_version;                  // the geometry's version() it was computed at
    std::vector<Eigen::Vector3f> texel_position, texel_normal;  // at texel_version
    std::uint64_t texel_version = ~std::uint64_t{0};
    std::vector<std::uint32_t> texel_patch;  // phosphor_irradiance: the glow patch of each texel
    std::vector<float> unit_sky;             // the sky's irradiance per unit of its radiance, per texel
    std::uint64_t unit_sky_version = ~std::uint64_t{0};
    ChargeReport charge;
  };
  // Updates g.charge for light l (on, reaching g's excitation bands) with its unit irradiance.
  void NoteCharge(Group& g, int l, const std::vector<float>& unit);

  // phosphor_irradiance (Sec. 8.5's optional term): every phosphorescent
  // triangle is split into at most 8 x 8 patches; irradiance from patch k
  // onto the centre of patch j per unit radiance, cos_j cos_k A_k / d^2 with
  // visibility (4 points per source patch), is computed once per geometry;
  // a step then costs a patches^2 product per glowing band, and each texel
  // takes its patch's value.
  struct GlowPatches {
    std::vector<Eigen::Vector3f> centre, normal;
    std::vector<float> area;
    // Texel cells per patch, bare ones (a mask's, a map's) included: a
    // patch's Lp is the mean over its cells of coverage x Lp.
    std::vector<float> cells;
    std::vector<std::uint8_t> two_sided;  // per patch: its object glows from and receives on both faces
    std::vector<float> transfer;      // [receiver * count + source]
    std::vector<int> emission_bands;  // bands any phosphor emits
    std::vector<float> Lp, E;         // per patch per band (scratch)
    std::size_t count = 0;
    std::uint64_t geometry_version = ~std::uint64_t{0};
  };
  void BuildGlowPatches();
  // Fills glow_.E from the current Lp; false if nothing glows.
  bool GatherGlow();

  void Step(double t0_s, double t1_s, bool moving);
  void UpdateTexelFrames(Group& group);
  const std::vector<float>& UnitIrradiance(Group& group, int light);
  // Fills group.E for the lights' levels at time t; returns false if no light reaches the group.
  bool GatherIrradiance(Group& group, double t_s);
  void InitialStates();

  const Scene& scene_;
  SceneGeometry& geometry_;
  TexelAtlas atlas_;
  std::vector<Group> groups_;
  int band_count_ = 0;
  double time_s_ = 0;
  SolverStats stats_;
  GlowPatches glow_;
  bool glow_enabled_ = false;
  std::unique_ptr<VolumeMedia> media_;
  mutable std::mutex derived_mutex_;
  mutable std::shared_ptr<const void> derived_tables_;
  mutable std::uint64_t derived_version_ = 0;
};

}  // namespace phos::render
