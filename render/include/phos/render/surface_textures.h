#pragma once
// Albedo and gloss that vary across a surface (Sec. 8.5: "parameters per
// material or, if spatial variation is desired, in textures"), looked up
// through OpenImageIO's TextureSystem (mip-mapped, filtered over the hit's
// UV footprint):
//  - an object's base colour texture (Object::albedo_texture), decoded from
//    sRGB and upsampled to the scene's bands (spectral_upsampling.h);
//  - its glTF metallicRoughnessTexture (Object::gloss_texture): roughness
//    from G and metallic from B, linear, times the object's Gloss factors.
//
// Only textured objects come here: the renderer keeps an untextured
// object's constant albedo and gloss and never asks.

#include <memory>
#include <vector>

#include "phos/render/geometry.h"
#include "phos/render/spectral_upsampling.h"

#include <OpenImageIO/oiioversion.h>

OIIO_NAMESPACE_BEGIN
class TextureSystem;
class ImageSpec;
OIIO_NAMESPACE_END

namespace phos::render {

// Where a hit lies in its mesh's UV map, and the UV offsets of its pixel's
// footprint: worked out once per hit for all of its textures.
struct UvFootprint {
  Eigen::Vector2f uv = Eigen::Vector2f::Zero();
  Eigen::Vector2f duv_dx = Eigen::Vector2f::Zero(), duv_dy = Eigen::Vector2f::Zero();  // zero: a point lookup
};

class SurfaceTextures {
 public:
  // Opens every textured object's file; one that is not an image OpenImageIO
  // can read is a UserError naming the scene's object, the mesh file's field
  // and the texture file.
  explicit SurfaceTextures(const Scene& scene);
  ~SurfaceTextures();
  SurfaceTextures(const SurfaceTextures&) = delete;
  SurfaceTextures& operator=(const SurfaceTextures&) = delete;

  bool textured(int object) const { return handles_[object] != nullptr; }
  bool gloss_textured(int object) const { return gloss_handles_[object] != nullptr; }
  bool any_textured(int object) const { return textured(object) || gloss_textured(object); }

  // A hit's place in its mesh's UV map and its footprint there. dp_dx,
  // dp_dy: where the rays through the next pixel right and down meet the
  // hit's plane, less the hit (world metres; pbrt's ray differentials): the
  // textures are filtered over their UV footprint. Zero: a point lookup at
  // the finest level.
  UvFootprint Footprint(const SceneGeometry& geometry, const Hit& hit, const Vec3f& dp_dx, const Vec3f& dp_dy) const;

  // Albedo per band of a textured object over a footprint, written to
  // bands[0, band count).
  void Albedo(int object, const UvFootprint& footprint, float* bands) const;

  // The gloss of an object with a gloss texture over a footprint: `factors`
  // (the object's Gloss) times the texture's B (metallic) and G (roughness).
  Gloss GlossAt(int object, const UvFootprint& footprint, const Gloss& factors) const;

 private:
  // A texture's handle (an embedded image is first written to a file of its
  // own in the user's cache: $XDG_CACHE_HOME/phos/textures, else
  // ~/.cache/phos/textures); an image OpenImageIO cannot read is a
  // UserError naming `source.texture` (the file, or the glTF's embedded
  // image) and its field.
  void* Open(const TextureSource& source, const std::string& where, OIIO::ImageSpec& spec) const;
  // `channels` channels from `first_channel` of `source`'s texture (its
  // wraps and UV transform) over a footprint.
  void Lookup(void* handle, const UvFootprint& footprint, bool v_up, const TextureSource& source, int first_channel,
              int channels, float* out) const;

  const Scene& scene_;
  RgbToBands to_bands_;
  OIIO::TextureSystem* system_ = nullptr;
  std::vector<void*> handles_;      // per object: its albedo texture's handle, null when untextured
  std::vector<void*> gloss_handles_;  // per object: its gloss texture's handle, null when none
  std::vector<char> srgb_;          // per object: its texels are sRGB-encoded
};

// A phosphor mask (Object::phosphor_mask) at the centres of a resolution x
// resolution grid over UV space, [y * resolution + x] with row y at v in
// [y, y + 1) / resolution: its first channel, as stored (not sRGB-decoded),
// by OpenImageIO's TextureSystem at the nearest texel of the finest level
// (the atlas's texels are the lookups' footprint). v_up: the mesh's v = 0
// is the image's bottom row (OBJ). A file that is not an image is a
// UserError naming `where`.
std::vector<float> SampleMaskGrid(const std::filesystem::path& file, bool v_up, int resolution,
                                  const std::string& where);

}  // namespace phos::render
