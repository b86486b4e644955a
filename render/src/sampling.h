#pragma once
// Directions about a surface normal, written once for every part of the
// renderer that draws them: the path tracer's diffuse bounces, the glossy
// BSDF's cosine lobe and its visible normals' frame, the sky's shadow rays
// and ray-traced occlusion. Internal to phos_render.

#include <algorithm>
#include <cmath>

#include "phos/render/geometry.h"
#include "phos/util/math.h"
#include "phos/util/random.h"

namespace phos::render {

// An orthonormal frame (t, b, n) about the unit normal n, without branches
// or a normalization (Duff et al. 2017, "Building an Orthonormal Basis,
// Revisited").
struct TangentFrame {
  Vec3f t, b, n;
  explicit TangentFrame(const Vec3f& normal) : n(normal) {
    const float sign = std::copysign(1.0f, n.z());
    const float a = -1.0f / (sign + n.z()), c = n.x() * n.y() * a;
    t = Vec3f(1.0f + sign * n.x() * n.x() * a, sign * c, -sign * n.x());
    b = Vec3f(c, sign + n.y() * n.y() * a, -n.y());
  }
  Vec3f ToWorld(float x, float y, float z) const { return x * t + y * b + z * n; }
  Vec3f ToLocal(const Vec3f& w) const { return Vec3f(w.dot(t), w.dot(b), w.dot(n)); }
};

// Malley's method: a uniform point (x, y) of the unit disk, lifted onto the
// hemisphere about the frame's n, is a cosine-weighted direction (pdf
// cos theta / pi).
inline Vec3f LiftToHemisphere(const TangentFrame& frame, float x, float y) {
  return frame.ToWorld(x, y, std::sqrt(std::max(0.0f, 1.0f - x * x - y * y)));
}

// A cosine-weighted direction from (u1, u2) in [0, 1)^2 by the polar map
// (r = sqrt(u1), phi = 2 pi u2), which keeps a stratification of the square.
inline Vec3f SampleCosineHemisphere(const TangentFrame& frame, float u1, float u2) {
  const float r = std::sqrt(u1), phi = 2 * kPiF * u2;
  return LiftToHemisphere(frame, r * std::cos(phi), r * std::sin(phi));
}

// A cosine-weighted direction from a random stream: the disk's point by
// rejection from its square (on average 1.27 tries, 2.5 random numbers),
// cheaper than the polar map's sine and cosine, which were a tenth of the
// path tracer's own time.
inline Vec3f SampleCosineHemisphere(const TangentFrame& frame, SplitMix64& random) {
  float x, y;
  do {
    x = 2 * random.UniformFloat() - 1;
    y = 2 * random.UniformFloat() - 1;
  } while (x * x + y * y >= 1.0f);
  return LiftToHemisphere(frame, x, y);
}

}  // namespace phos::render
