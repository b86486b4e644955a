#pragma once
// The texel counts of the atlas (texel_count.cpp), shared by the count that
// refuses a scene at load and the atlas that makes the texels (geometry.cpp).

#include "phos/render/scene.h"

namespace phos::render {

// Texels along each edge of a triangle of the auto atlas: its longest edge
// over the texel size, so texels are never longer than asked (1 to 4096).
int AutoSubdivisions(float longest_m, double texel_size_m);
// Texels per UV unit of a UV atlas: the object's uv_resolution, or texels of
// about texel_size_m, from the ratio of world area to UV area (1 to 8192).
int UvResolution(const Object& object, double world_area, double texel_size_m);
// Whether the object's texels live on its UV map (asked for, or by default
// when the map is one-to-one).
bool UsesUvMap(const Object& object);

}  // namespace phos::render
