#pragma once
// The light transports of a frame (renderer.h): direct, path and dss, each
// in its own unit behind FrameTransport, and all of them shading through one
// Shading (shading.h), so that a material, a texture or a light is written
// once for every transport. RenderBands (renderer.cpp) runs a transport's
// rows in parallel, then its Finish. Internal to phos_render.

#include <cstdint>
#include <memory>

#include "phos/render/geometry.h"
#include "phos/render/renderer.h"
#include "phos/util/random.h"
#include "shading.h"

namespace phos::render {

class FrameTransport {
 public:
  virtual ~FrameTransport() = default;
  // Renders row y of the frame into `image` and counts its rays in `rays`.
  // Called once per row, from any thread, the rows in any order.
  virtual void RenderRow(int y, Image& image, std::uint64_t& rays) = 0;
  // After every row: what needs the whole frame (dss's bounce through deep
  // screen space). Returns the rays it cast.
  virtual std::uint64_t Finish(Image& /*image*/) { return 0; }
};

// The transport of options().transport, shading with `shading` through
// `camera`; both outlive it.
std::unique_ptr<FrameTransport> MakeDirectTransport(const Shading& shading, const CameraRays& camera);
std::unique_ptr<FrameTransport> MakePathTransport(const Shading& shading, const CameraRays& camera);
std::unique_ptr<FrameTransport> MakeDssTransport(const Shading& shading, const CameraRays& camera);

// Each pixel draws from a stream of its own (seed, frame, pixel), so a frame
// is the same on any number of threads and in any range of frames.
inline SplitMix64 PixelStream(const FrameOptions& options, int width, int x, int y) {
  return SplitMix64((std::uint64_t(options.seed) << 40) ^ options.frame * 0x9E3779B97F4A7C15ull ^
                    (std::uint64_t(y) * std::uint64_t(width) + x) * 0x2545F4914F6CDD1Dull);
}

// The rays through the image points one pixel right of and below the one
// `through` passes (CameraRays::Through), for filtering textures; none when
// nothing is textured (no cost there). Unnormalized: a ray's footprint on
// the hit's plane does not depend on its direction's length.
inline RayDifferential CameraDifferential(const Shading& shading, const CameraRays& camera, const Vec3f& through) {
  RayDifferential d;
  if (shading.textured()) {
    d.dx = through + camera.pixel_right();
    d.dy = through + camera.pixel_down();
  }
  return d;
}

}  // namespace phos::render
