#pragma once
// Participating media on grids (scene.h's Volume), ray marched, with direct
// single scattering of the scene's lights and, for phosphorescent media, a
// rate-equation state per voxel that charges and glows (Figs. 8.17, 8.18:
// a dust cloud swept by laser sheets, a glowing liquid).
//
// Model only what the scene requires: a voxel carries a state only where its
// density is above zero; the light reaching each voxel is computed only next
// to such voxels, once per light pose and geometry (a light switching or
// dimming only rescales it; a sheet sweeping through a cloud only moves its
// slab mask, since the transmittance along its direction does not change).
//
// Radiative transfer along a camera ray (single scattering, no multiple
// scattering inside the medium):
//
//   L = T(s_end) L_surface + sum over steps T(s_k) (1 - e^{-sigma ds}) J(s_k),
//   J = albedo sum_lights E_l unit_l p_HG(cos) / (4 pi normalized) + Lp,
//
// with sigma = density sigma_t_per_m held constant over a step, so a step of
// any optical depth is exact for a constant source: a huge sigma gives the
// source at the entry point (an opaque cloud), sigma = 0 gives nothing.

#include <cstdint>
#include <memory>
#include <vector>

#include "phos/model/batch.h"
#include "phos/render/dss.h"
#include "phos/render/geometry.h"
#include "phos/render/scene.h"
#include "phos/util/math.h"

namespace phos::render {

// Henyey-Greenstein phase function (per steradian), cos_theta between the
// light's travel direction and the scattered direction; g > 0 scatters forward.
inline float HenyeyGreenstein(float cos_theta, float g) {
  const float d = 1 + g * g - 2 * g * cos_theta;
  return (1 - g * g) / (4 * kPiF * d * std::sqrt(d));
}

// A volume's grid: voxel addressing and trilinear sampling between voxel
// centres (clamped at the faces, so a uniform box is uniform to its faces;
// zero outside the bounds).
class VolumeGrid {
 public:
  explicit VolumeGrid(const Volume& volume);
  const Volume& volume() const { return *volume_; }
  // Trilinear value of a per-voxel field at p; 0 outside the bounds.
  float Sample(const float* field, const Vec3f& p) const;
  float Density(const Vec3f& p) const { return Sample(volume_->density.data(), p); }
  // The ray's parameter interval inside the bounds, clipped to [0, t_max].
  bool Clip(const Vec3f& origin, const Vec3f& direction, float t_max, float* t0, float* t1) const;
  Vec3f VoxelCentre(std::size_t index) const;
  float min_voxel_m() const { return min_voxel_; }
  const Vec3f& voxel_m() const { return voxel_; }

 private:
  const Volume* volume_;
  Vec3f min_, max_, inv_voxel_, voxel_;
  float min_voxel_;
};

struct MarchOptions {
  // step = step_scale * the smallest voxel edge. The study (docs/dss-trade.md,
  // Media) found a whole voxel within 3e-4 of a sixteenth (RMSE relative to
  // the brightest pixel) on both media fixtures, at half the time of 0.5:
  // the lights are cached per voxel, so a finer step only resamples them.
  float step_scale = 1.0f;
};

struct VolumeStats {
  std::size_t voxels = 0;           // all voxels
  std::size_t phosphor_voxels = 0;  // voxels with a state (density > 0)
  std::size_t lit_voxels = 0;       // voxels whose light is computed (next to density > 0)
  std::size_t light_updates = 0;    // per-light recomputations of the voxels' light
  std::size_t steps = 0, dark_jumps = 0;
};

// The scene's media: lighting caches and phosphor states. The coupled solver
// owns one when the scene has volumes; a frame without a solver makes its own.
class VolumeMedia {
 public:
  VolumeMedia(const Scene& scene, const SceneGeometry& geometry, MarchOptions options = {});
  ~VolumeMedia();
  bool empty() const { return grids_.empty(); }
  // The march's step (studies trade it against error); the voxels' light is
  // recomputed with it at the next PrepareLighting.
  void set_march_options(const MarchOptions& options);
  const std::vector<VolumeGrid>& grids() const { return grids_; }

  // Brings the voxels' light up to date for the lights' poses at t_s (call
  // before marching; not thread-safe, the marches afterwards are).
  void PrepareLighting(double t_s);

  // Transmittance through every medium from a to b (shadow rays).
  float Transmittance(const Vec3f& a, const Vec3f& b) const;
  float TransmittanceToInfinity(const Vec3f& a, const Vec3f& direction) const;

  // March the ray over [0, t_max): adds the media's in-scattered and emitted
  // radiance (per band, nb values) to L and returns the transmittance to
  // t_max. `jitter` in [0, 1) offsets the step grid (a camera ray's own
  // random number: noise instead of banding).
  float March(const Vec3f& origin, const Vec3f& direction, float t_max, float jitter, float* L) const;

  // Points along the ray where the transmittance from its origin falls to
  // each of `targets` (decreasing, in (0, 1)); the march's optical depth is
  // linear inside a step, so the points are placed within it. Writes the
  // distance and the volume of each point reached (volume -1: the ray left
  // the media first) and returns the transmittance over [0, t_max).
  float FindTransmittanceDepths(const Vec3f& origin, const Vec3f& direction, float t_max, const float* targets,
                                int count, float* distance, int* volume) const;

  // The light (per unit of each light's band irradiance) reaching voxel j of
  // volume v from light l, as last prepared: transmittance, visibility, 1/d^2
  // for point lights. Particles see light from every side: no cosine.
  const std::vector<float>& unit_light(int volume, int light) const { return caches_[volume][light].unit; }

  // Phosphorescent media (the coupled solver calls these): advance every
  // voxel's state over [t0, t1] with the lights' levels constant, at the
  // poses of the midpoint.
  void Step(double t0_s, double t1_s);
  void InitialStates();
  // Emitted radiance Lp of voxel j of volume v in scene band b (0 if not emitted).
  float Lp(int volume, int band, std::size_t voxel) const;
  // State i of voxel j (by grid index) of volume v; 0 where the density is 0.
  float State(int volume, int i, std::size_t voxel) const;
  const VolumeStats& stats() const { return stats_; }
  // The phosphorescent voxels' states and Lp, two arrays per phosphorescent
  // volume (the solver's checkpoints); RestoreStates takes them back in the
  // same order and sizes, else a UserError naming `source`.
  void SaveStates(std::vector<std::vector<float>>* arrays) const;
  void RestoreStates(const std::vector<std::vector<float>>& arrays, std::size_t first, const std::string& source);

 private:
  struct LightCache {
    std::vector<float> unit;  // per voxel
    LightPose pose;
    std::uint64_t version = ~std::uint64_t{0};
    bool valid = false;
  };
  struct Phosphor;
  // The ray's intervals inside each volume, front to back (at most kMaxSegments).
  struct Segment {
    float t0, t1;
    int volume;
  };
  static constexpr int kMaxSegments = 16;
  int Segments(const Vec3f& origin, const Vec3f& direction, float t_max, Segment* segments) const;
  void UpdateLight(int volume, int light, const LightPose& pose);
  void StepVolume(int volume, double h_s);  // at the lights as last prepared
  void ScatterLp(int volume);
  float MediaOpticalDepth(const Vec3f& origin, const Vec3f& direction, float t_max) const;

  const Scene& scene_;
  const SceneGeometry& geometry_;
  MarchOptions options_;
  int nb_;
  std::vector<VolumeGrid> grids_;
  std::vector<std::vector<LightCache>> caches_;         // [volume][light]
  std::vector<std::vector<std::uint8_t>> needs_light_;  // per volume per voxel
  std::vector<LightPose> poses_;                        // lights' poses at the last PrepareLighting
  std::vector<float> levels_;                           // lights' levels at the last PrepareLighting
  std::vector<std::unique_ptr<Phosphor>> phosphors_;    // per volume, null if not phosphorescent
  VolumeStats stats_;
};

// The transmittance interval map (surface-to-volume light, the volume paper
// of the method's seeds): per pixel, `layers` points along the camera ray at
// equal steps of transmittance, T(s_k) = 1 - (k + xi) dT with
// dT = (1 - T_end) / layers and xi a per-pixel jitter. Since the in-scattered
// radiance is  int T sigma_s J ds = int albedo J (-dT),  each point stands
// for the same share dT of the ray's scattering: where the medium is dense
// the points crowd, where it is empty there are none. Surfels are then
// splatted onto the points as onto any receivers (dss.h; a point in a medium
// has no normal: its receivers' normal is zero) and
//
//   L_pixel += sum_k dT albedo(s_k) Phi(s_k) / (4 pi),  Phi = sum B F_iso,
//
// with an isotropic phase function (Phi: the radiance arriving from every
// direction, integrated over the sphere).
struct IntervalMap {
  int layers = 0;
  std::vector<GBuffer> layer;  // receivers: object = volume index, -1 where the pixel has no point
  std::vector<float> delta_T;  // per pixel
  std::vector<float> T_end;    // per pixel: transmittance to the surface the pixel sees (or through)
};
IntervalMap BuildIntervalMap(const VolumeMedia& media, const GBuffer& gbuffer, const CameraRays& camera, int layers);

}  // namespace phos::render
