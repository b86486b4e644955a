#pragma once
// Frames: light transport from the lights and the glowing texels to the
// camera, per band of the scene's grid, then colour, EXR and PNG.
//
// Transports (docs/render.md, "Transports"):
//  - direct: primary rays; reflected light from the lights (shadow rays) plus
//    the phosphors' own emission Lp (Eq. 8.2). No interreflection: the glow
//    lights nothing else. Fast; the interactive and animation path.
//  - path: a spectral path tracer, the reference. All bands travel together
//    (diffuse materials scatter no light between bands); next-event
//    estimation for the lights and for the glowing triangles, combined with
//    BSDF sampling by multiple importance sampling (power heuristic), so the
//    glow of one surface lights the others (Fig. 8.15).
//  - dss: direct, plus one bounce of diffuse light through deep screen space
//    (dss.h): every surfel sends what it reflects of the lights and what it
//    glows (B = albedo E + pi Lp), so a glowing wall lights a box in the dark
//    without a single path; with media, the surfels also light the media
//    through the transmittance interval map (volume.h). Its speed and its
//    error against the path tracer are in docs/render.md.
//
// Media (volume.h) are ray marched on camera rays in every transport
// (single scattering of the lights, the phosphorescent voxels' glow) and
// shadow the lights; light scattered more than once inside them, and the
// path tracer's bounce rays through them, are not modelled.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "phos/render/geometry.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"
#include "phos/util/large_table.h"

namespace phos {
class ProgressBar;
}

namespace phos::render {

enum class Transport { kDirect, kPath, kDss };
Transport ParseTransport(const std::string& name);  // UserError on an unknown name
const char* TransportName(Transport transport);

// Pixels with `channels` floats each, row-major from the top-left.
// A large table (large_table.h): a frame's image is the same size as the
// last one's, so its storage is the last one's, kept, not pages faulted in
// and zeroed afresh.
struct Image {
  int width = 0, height = 0, channels = 0;
  LargeTable<float> pixels;
  Image() = default;
  Image(int w, int h, int c) : width(w), height(h), channels(c), pixels(std::size_t(w) * h * c, 0.0f) {}
  // Every pixel left unset, for a writer that sets each (RenderBands' rows,
  // in parallel): at 1920 x 1080 and 8 bands, zeroing on one thread first
  // was 31 ms of a 193 ms direct frame (phos render --json, setup_seconds).
  static Image ForOverwrite(int w, int h, int c) {
    Image image;
    image.width = w;
    image.height = h;
    image.channels = c;
    image.pixels.resize(std::size_t(w) * h * c);  // default-initialised: not zeroed
    return image;
  }
  float* at(int x, int y) { return pixels.data() + (std::size_t(y) * width + x) * channels; }
  const float* at(int x, int y) const { return pixels.data() + (std::size_t(y) * width + x) * channels; }
};

struct FrameOptions {
  Transport transport = Transport::kDirect;
  int spp = 16;        // path: samples per pixel
  int direct_spp = 1;  // direct: jittered samples per pixel
  int max_depth = 8;   // path: bounces
  unsigned seed = 1;
  // The frame's index in its run: the path tracer's and the jitter's random
  // numbers are seeded by pixel, frame and sample (never by thread), so a
  // range of frames rendered on its own equals the same frames of one run.
  std::uint64_t frame = 0;
  int interval_layers = 4;           // dss with media: points per pixel of the transmittance interval map
  int sky_rays = 16;                 // direct (and what dss surfels receive): shadow rays per point for the sky
  bool indirect_visibility = false;  // dss: the bounced z-buffer (no leaking, no over-occlusion) instead of blending
  // path: an object with more phosphorescent triangles than this has them
  // chosen by blocks (transport_path.cpp, EmitterBlocks), not one by one.
  // 2^17: where a table choosing them one by one would have two levels
  // anyway (alias_table.h), so blocks add no step to a pick. Tests set 0
  // to render a small scene both ways.
  std::size_t emitter_blocks_above_triangles = std::size_t{1} << 17;
  // Advanced by one for every row of pixels finished (a path-traced frame
  // can take minutes: the bar moves inside it). Null: no progress.
  ProgressBar* progress_rows = nullptr;
};
FrameOptions DefaultFrameOptions(const Scene& scene, Transport transport);

// Choosing a transport for the user's budget. The candidates are direct,
// dss and the path tracer at 4 to 1024 spp; each carries the perceptual
// quality (mean SSIM against the path tracer at 1024 spp) that the trade
// study measured for the glow's light in the Cornell box after lights-out:
// MeasuredTransportQuality() (transport_quality.h), the study's output
// render/data/transport-quality.json built in. Costs are measured on this
// scene now: one frame each of direct, dss and the path tracer at 1 spp
// (path time scales with spp).
struct TransportCandidate {
  FrameOptions options;
  double expected_ssim = 0;
  double estimated_s = 0;
  std::string label;  // "direct", "dss", "path 64 spp"
};
struct TransportChoice {
  TransportCandidate chosen;
  std::vector<TransportCandidate> candidates;
  bool fits = true;  // false: nothing met the budget or the quality; the nearest was chosen
};
std::vector<TransportCandidate> MeasureTransportCandidates(const SceneGeometry& geometry, const CoupledSolver* solver,
                                                           const FrameOptions& base);
// Best expected quality within budget_s seconds per frame (budget_s > 0), or
// the cheapest candidate of at least min_ssim (min_ssim > 0).
TransportChoice ChooseTransport(std::vector<TransportCandidate> candidates, double budget_s, double min_ssim);

struct FrameStats {
  std::uint64_t rays = 0;  // every ray cast (primary, shadow, bounce)
  // Wall time before the first row: the frame's shading and its transport's
  // set-up (the path tracer's glow copy and emitter table), which grows
  // with the scene, not with the samples.
  double setup_s = 0;
};

// Radiance per band at every pixel at the geometry's and solver's current
// time (the caller advances the solver first). solver may be null: no phosphorescence.
Image RenderBands(const SceneGeometry& geometry, const CoupledSolver* solver, const FrameOptions& options,
                  FrameStats* stats = nullptr);

// Band radiance to linear sRGB (D65): band averages of the CIE 1931 colour
// matching functions (the analytic fit of Wyman, Sloan and Shirley 2013),
// normalized so that radiance 1 in every band has luminance Y = 1.
Image BandsToLinearSrgb(const Image& bands, const SpectralGrid& grid);
// Weights [3 x n]: row 0 X, 1 Y, 2 Z per band.
std::vector<double> BandToXyzWeights(const SpectralGrid& grid);

// Linear EXR (32-bit float: glows are dim, half floats would lose them) with R, G, B and one channel per band ("band<b>"),
// the band edges in the header attribute "phos:bands_nm". Atomic write.
// `compression`: one of OpenEXR's as OpenImageIO names them; "zip" (the
// default) and "none", "rle", "zips", "piz" keep every float; "pxr24"
// (floats to 24 bits) and "dwaa", "dwab" (lossy, for viewing) do not
// (docs/render.md, "EXR compression", measures the trade).
// A physical scene's (units kPhysical: band radiances in W/(sr m²)) holds one
// more channel, "Y", after the bands: the photopic luminance in cd/m²,
// sum_b w_b L_b with w_b = PhotopicBandEfficacy (phos/model/photometry.h),
// and the header attribute "phos:units" = "physical".
void WriteExr(const std::filesystem::path& path, const Image& rgb, const Image& bands, const SpectralGrid& grid,
              const std::string& compression = "zip", Units units = Units::kRelative);
// For viewing: rgb * exposure through Reinhard's global operator (L / (1 + L)
// on luminance), then the sRGB transfer: display values in [0, 1].
Image ToneMap(const Image& rgb, double exposure);
// 8-bit PNG of ToneMap(rgb, exposure). Atomic write.
void WritePng(const std::filesystem::path& path, const Image& rgb, double exposure);
// Display images (ToneMap's output, all the same size) side by side, `columns`
// per row, each under its label (DejaVu Sans when installed). Atomic write.
void WriteContactSheet(const std::filesystem::path& path, const std::vector<Image>& frames,
                       const std::vector<std::string>& labels, int columns);
// What puts light into band b of the scene, for a message: the lights ever
// on with their value there (a point or spot light's intensity, a
// directional or sheet light's irradiance, an area light's radiance), the
// sky, and with phosphor_irradiance the phosphors' own glow; "" if nothing
// does. The refusal of an unknown ke names them, not a unit probe.
std::string ChargingSources(const Scene& scene, int band);
// An unknown ke (not measured) of `material` in one of `excitation_bands` is
// a UserError naming `where`, the state, the band and ChargingSources there,
// ending with kUnknownKeRemedy; the solver and the media check each
// phosphor so before compiling it.
void RequireKnownKe(const Scene& scene, const Material& material, const std::vector<int>& excitation_bands,
                    const std::string& where);
// Reads any image OpenImageIO reads, as float (tests, regression references).
Image ReadImage(const std::filesystem::path& path);
// The channels of an image named `names`, in that order. OpenEXR stores
// channels sorted by name, and OpenImageIO gives R, G, B first and the rest
// in that order: a physical frame's "Y" comes back before "band0". A
// channel the file lacks is a UserError naming the file.
Image ReadImageChannels(const std::filesystem::path& path, const std::vector<std::string>& names);

}  // namespace phos::render
