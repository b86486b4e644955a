#include "shading.h"

namespace phos::render {

Shading::Shading(const SceneGeometry& geometry, const CoupledSolver* solver, const VolumeMedia* media,
                 const FrameOptions& options)
    : geometry_(geometry),
      scene_(geometry.scene()),
      solver_(solver),
      media_(media),
      options_(options),
      nb_(scene_.bands.band_count()) {
  const double t = geometry.time_s();
  if (scene_.environment) {
    sky_level_ = static_cast<float>(scene_.environment->schedule.LevelAt(t));
    sky_L_ = Bands(nb_);
    for (int b = 0; b < nb_; ++b) sky_L_[b] = static_cast<float>(sky_level_ * scene_.environment->L_per_band[b]);
  }
  textures_ = geometry.surface_textures();
  for (const Object& object : scene_.objects) {
    Bands a(nb_);
    for (int b = 0; b < nb_; ++b) a[b] = static_cast<float>(object.albedo[b]);
    albedo_.push_back(a);
  }
  for (const Light& light : scene_.lights) {
    const double level = light.schedule.LevelAt(t);
    if (level <= 0) continue;
    LitLight lit;
    lit.pose = PoseAt(light, t);
    lit.E = Bands(nb_);
    for (int b = 0; b < nb_; ++b) lit.E[b] = static_cast<float>(level * light.E_per_band[b]);
    lights_.push_back(lit);
    if (lit.pose.bodiless()) area_lights_.push_back(lit);
    if (light.kind == Light::Kind::kMesh) {
      if (emitter_of_object_.empty()) emitter_of_object_.assign(scene_.objects.size(), -1);
      emitter_of_object_[light.emitter_object] = static_cast<int>(lights_.size() - 1);
    }
  }
}

}  // namespace phos::render
