#pragma once
// Albedo that varies across a surface (Sec. 8.5: "parameters per material
// or, if spatial variation is desired, in textures"): an object's base colour
// texture (Object::albedo_texture), looked up through OpenImageIO's
// TextureSystem (mip-mapped, filtered over the hit's UV footprint), decoded
// from sRGB and upsampled to the scene's bands (spectral_upsampling.h).
//
// Only textured objects come here: the renderer keeps an untextured
// object's constant albedo and never asks.

#include <memory>
#include <vector>

#include "phos/render/geometry.h"
#include "phos/render/spectral_upsampling.h"

#include <OpenImageIO/oiioversion.h>

OIIO_NAMESPACE_BEGIN
class TextureSystem;
OIIO_NAMESPACE_END

namespace phos::render {

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
  // Albedo per band at a hit on a textured object, written to bands[0, band
  // count). dp_dx, dp_dy: where the rays through the next pixel right and
  // down meet the hit's plane, less the hit (world metres; pbrt's ray
  // differentials): the texture is filtered over their UV footprint. Zero:
  // a point lookup at the finest level.
  void Albedo(const SceneGeometry& geometry, const Hit& hit, const Vec3f& dp_dx, const Vec3f& dp_dy,
              float* bands) const;

 private:
  const Scene& scene_;
  RgbToBands to_bands_;
  OIIO::TextureSystem* system_ = nullptr;
  std::vector<void*> handles_;      // per object: its texture's handle, null when untextured
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
