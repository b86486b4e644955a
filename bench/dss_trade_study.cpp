// phos-dss-study: the speed/accuracy trade of deep screen space (issue 6):
// ambient occlusion, the glow's bounce, media (the march; the glow media
// scatter through the interval map), directional occlusion of a sky and
// subsurface scattering. For ambient occlusion on each fixture view,
// ray-traced occlusion with many rays is the truth; against it, in one run
// on this machine:
//   - deep screen space over its levels (l_max + 1), epsilon and surfel size s;
//   - plain Monte Carlo with Embree at 1 to 64 rays per pixel (the same
//     budget, and more);
//   - plain screen space: one depth layer (the G-buffer's pixels as surfels).
// Every run's time includes its G-buffer. Error: RMSE and mean SSIM
// (Gaussian windows, sigma 1.5, as Wang et al. 2004) over the pixels that see
// geometry. Then the default search, as XeGTAO chose its presets: at each
// time budget, the DSS settings with the lowest mean RMSE over the views,
// beside the best Monte Carlo within the same budget. The other effects
// each have their own truth, said where they are measured: the path tracer
// at 1024 spp (the glow's bounce), a sixteenth-voxel march and 512 Monte
// Carlo rays per interval point (media), 1024 sky rays (the sky), the exact
// gather of finer surfels (translucency).
//
//   phos-dss-study --out docs    (docs/dss-trade.csv, dss-trade.svg,
//                                 dss-budget.csv, dss-budget.svg, dss-trade.md)

#include <CLI/CLI.hpp>

#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "phos/render/dss.h"
#include "phos/render/renderer.h"
#include "phos/render/solver.h"
#include "phos/render/scene.h"
#include "phos/render/subsurface.h"
#include "phos/render/transport_quality.h"
#include "phos/render/volume.h"
#include "phos/util/atomic_file.h"
#include "phos/util/format.h"
#include "phos/util/json.h"
#include "phos/util/math.h"
#include "phos/util/progress.h"
#include "phos/util/random.h"
#include "phos/util/svg_plot.h"

namespace phos::render {
namespace {

namespace fs = std::filesystem;

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

struct Error {
  double rmse = 0, ssim = 0;
};

Error Compare(const std::vector<float>& image, const std::vector<float>& truth, const GBuffer& g) {
  double sq = 0;
  int n = 0;
  for (std::size_t p = 0; p < truth.size(); ++p)
    if (g.object[p] >= 0) sq += std::pow(image[p] - truth[p], 2), ++n;
  Error e;
  e.rmse = std::sqrt(sq / std::max(n, 1));
  // SSIM on [0, 1] images (C1 = (0.01)^2, C2 = (0.03)^2), Gaussian windows.
  cv::Mat x(g.height, g.width, CV_64F), y(g.height, g.width, CV_64F);
  for (int r = 0; r < g.height; ++r)
    for (int c = 0; c < g.width; ++c) {
      x.at<double>(r, c) = image[static_cast<std::size_t>(r) * g.width + c];
      y.at<double>(r, c) = truth[static_cast<std::size_t>(r) * g.width + c];
    }
  auto blur = [](const cv::Mat& m) {
    cv::Mat out;
    cv::GaussianBlur(m, out, cv::Size(11, 11), 1.5);
    return out;
  };
  const cv::Mat mx = blur(x), my = blur(y);
  const cv::Mat sxx = blur(x.mul(x)) - mx.mul(mx), syy = blur(y.mul(y)) - my.mul(my), sxy = blur(x.mul(y)) - mx.mul(my);
  const double C1 = 1e-4, C2 = 9e-4;
  double sum = 0;
  int count = 0;
  for (int r = 0; r < g.height; ++r)
    for (int c = 0; c < g.width; ++c) {
      if (g.object[static_cast<std::size_t>(r) * g.width + c] < 0) continue;
      const double a = mx.at<double>(r, c), b = my.at<double>(r, c);
      sum += (2 * a * b + C1) * (2 * sxy.at<double>(r, c) + C2) /
             ((a * a + b * b + C1) * (sxx.at<double>(r, c) + syy.at<double>(r, c) + C2));
      ++count;
    }
  e.ssim = sum / std::max(count, 1);
  return e;
}

// Band radiance summed per pixel.
std::vector<float> BandSum(const Image& image) {
  std::vector<float> v(static_cast<std::size_t>(image.width) * image.height, 0.0f);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x)
      for (int b = 0; b < image.channels; ++b) v[static_cast<std::size_t>(y) * image.width + x] += image.at(x, y)[b];
  return v;
}

// Every pixel counts (media are seen where no surface is).
GBuffer AllPixels(int width, int height) {
  GBuffer g;
  g.width = width;
  g.height = height;
  g.object.assign(static_cast<std::size_t>(width) * height, 0);
  return g;
}

// What the media scatter of the glowing surfaces, summed over the bands, per
// pixel: sum_k dT albedo Phi(s_k) / (4 pi) over the interval map's points,
// Phi from deep screen space (directions = 0) or from `directions` uniform
// rays on the sphere per point (Monte Carlo with Embree: Phi = 4 pi mean Lp).
std::vector<float> MediumGlow(const Scene& scene, const SceneGeometry& geometry, const CoupledSolver& solver,
                              const IntervalMap& map, const CameraRays& camera, int directions, unsigned seed) {
  const int nb = scene.bands.band_count();
  const std::size_t n = map.delta_T.size();
  std::vector<float> out(n, 0.0f);
  auto Lp_at = [&](const Hit& hit, std::vector<float>& L) {
    std::fill(L.begin(), L.end(), 0.0f);
    if (!hit || !hit.front) return;
    const int slot = solver.atlas().SlotOf(hit.object);
    if (slot < 0) return;
    const std::size_t texel = solver.atlas().TexelOf(slot, hit.triangle, hit.b1, hit.b2);
    if (texel == TexelAtlas::kNoTexel) return;
    for (int b : solver.emission_bands(slot)) L[b] = solver.atlas().Coverage(slot, texel) * solver.Lp(slot, b, texel);
  };
  if (directions == 0) {
    const std::vector<Surfel> all = Surfelize(geometry, camera.origin(), static_cast<float>(scene.camera.fov_deg), {});
    std::vector<Surfel> senders;
    std::vector<float> B, L(nb);
    for (const Surfel& s : all) {
      Lp_at(FrontHit(s), L);
      if (*std::max_element(L.begin(), L.end()) <= 0) continue;
      senders.push_back(s);
      for (float l : L) B.push_back(kPiF * l);
    }
    DssOptions options;
    options.channels = nb;
    for (const GBuffer& layer : map.layer) {
      const DssResult r = SplatDeepScreenSpace(layer, camera, senders, B, options);
      for (std::size_t p = 0; p < n; ++p) {
        if (layer.object[p] < 0) continue;
        for (int b = 0; b < nb; ++b)
          out[p] += map.delta_T[p] * static_cast<float>(scene.volumes[layer.object[p]].albedo[b]) *
                    r.irradiance[p * nb + b] / (4 * kPiF);
      }
    }
    return out;
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<float> L(nb);
    std::mt19937 random(static_cast<unsigned>(seed * 7919 + range.begin()));
    std::uniform_real_distribution<float> u(0, 1);
    for (std::size_t p = range.begin(); p != range.end(); ++p)
      for (const GBuffer& layer : map.layer) {
        if (layer.object[p] < 0) continue;
        double sum = 0;
        for (int k = 0; k < directions; ++k) {
          const float z = 1 - 2 * u(random), phi = 2 * kPiF * u(random), r = std::sqrt(std::max(0.0f, 1 - z * z));
          const Vec3f d(r * std::cos(phi), r * std::sin(phi), z);
          Lp_at(geometry.Intersect(layer.position[p], d), L);
          for (int b = 0; b < nb; ++b) sum += scene.volumes[layer.object[p]].albedo[b] * L[b];
        }
        // albedo Phi / (4 pi) = albedo mean(Lp) over the sphere.
        out[p] += map.delta_T[p] * static_cast<float>(sum / directions);
      }
  });
  return out;
}

// The mean difference and the RMSE of `image` against `truth` over the
// pixels that see geometry: the bias and the whole error.
struct Bias {
  double bias = 0, rmse = 0;
};
Bias Signed(const std::vector<float>& image, const std::vector<float>& truth, const GBuffer& g) {
  double sum = 0, sq = 0;
  int n = 0;
  for (std::size_t p = 0; p < truth.size(); ++p)
    if (g.object[p] >= 0) sum += image[p] - truth[p], sq += std::pow(image[p] - truth[p], 2), ++n;
  return {sum / std::max(n, 1), std::sqrt(sq / std::max(n, 1))};
}

// What blending sums, traced: per pixel, cosine-distributed rays (as
// RayTracedOcclusion) followed through every surface they cross, unbounded.
// min(1, mean crossings) is the sum of form factors over both sides of every
// surface (blending before the fix); min(1, mean crossings onto a front) the
// sum over the sides facing the receiver (after). Either differs from the
// reference, the fraction of rays that hit anything, only where a ray
// crosses a second surface after the first: visibility.
struct Crossings {
  std::vector<float> both_sides, front;
};
Crossings TraceCrossings(const SceneGeometry& geometry, const GBuffer& g, int rays, unsigned seed) {
  const std::size_t n = g.object.size();
  Crossings c{std::vector<float>(n, 0.0f), std::vector<float>(n, 0.0f)};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t p = range.begin(); p != range.end(); ++p) {
      if (g.object[p] < 0) continue;
      const Vec3f nrm = g.normal[p], t = nrm.unitOrthogonal(), b = nrm.cross(t);
      int all = 0, front = 0;
      for (int k = 0; k < rays; ++k) {
        const float u1 = Hash01(seed, p, 2 * static_cast<std::uint64_t>(k)),
                    u2 = Hash01(seed, p, 2 * static_cast<std::uint64_t>(k) + 1);
        const float r = std::sqrt(u1), phi = 2 * kPiF * u2;
        const Vec3f d = r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0f, 1 - u1)) * nrm;
        Vec3f origin = g.position[p] + geometry.ray_epsilon() * nrm;
        for (int crossing = 0; crossing < 64; ++crossing) {
          const Hit hit = geometry.Intersect(origin, d);
          if (!hit) break;
          ++all;
          front += hit.front;
          origin = hit.position + 2 * geometry.ray_epsilon() * d;
        }
      }
      c.both_sides[p] = std::min(1.0f, static_cast<float>(all) / static_cast<float>(rays));
      c.front[p] = std::min(1.0f, static_cast<float>(front) / static_cast<float>(rays));
    }
  });
  return c;
}

// One view's ambient occlusion error, taken apart (bias and RMSE of each
// against the ray-traced reference).
struct Decomposition {
  std::string view;
  Bias noise, both_sides, front, exact, dss, hierarchy, definition, cells;
};

struct Run {
  std::string view, method, parameters;
  double seconds;
  Error error;
  int levels = 0;
  float epsilon = 0, s = 0;
};

// The glow's-bounce runs as the renderer's table of expected quality per
// transport (transport_quality.h): direct, dss with its defaults (no bounced
// z-buffer: what --budget-s picks), and the path tracer per spp.
void WriteQualityTable(const fs::path& path, const std::vector<Run>& glow, int size, int reference_spp) {
  TransportQuality q;
  q.source =
      "build/bin/phos-dss-study --out docs --quality-table render/data/transport-quality.json (make study); "
      "docs/dss-trade.md, 'The glow's bounce'";
  q.scene = "fixtures/scenes/cornell-phosphor.json";
  q.view = "t = 40 s (10 s after the LED went off), " + std::to_string(size) + " x " + std::to_string(size) +
           " px, the bands summed, relative to the brightest pixel";
  q.reference = "mean SSIM against the path tracer at " + std::to_string(reference_spp) + " samples per pixel";
  for (const Run& r : glow) {
    if (r.method == "direct (no bounce)") q.direct_ssim = r.error.ssim;
    if (r.method == "deep screen space (direct + one bounce)") q.dss_ssim = r.error.ssim;
    if (r.method == "path tracer") q.path_ssim.emplace_back(std::stoi(r.parameters.substr(4)), r.error.ssim);
  }
  WriteFileAtomically(path, q.ToJson().dump(2) + "\n");
}

void Append(std::vector<Run>& to, const std::vector<Run>& runs) { to.insert(to.end(), runs.begin(), runs.end()); }

// A fixture scene, keeping the view's aspect ratio, `size` pixels high.
Scene LoadView(const std::string& name, int size) {
  Scene scene = LoadScene(fs::path(PHOS_FIXTURES_DIR) / "scenes" / (name + ".json"));
  scene.camera.width =
      static_cast<int>(std::lround(size * static_cast<double>(scene.camera.width) / scene.camera.height));
  scene.camera.height = size;
  return scene;
}

// The Cornell box, `size` pixels square.
Scene LoadCornell(int size) {
  Scene scene = LoadScene(fs::path(PHOS_FIXTURES_DIR) / "scenes" / "cornell-phosphor.json");
  scene.camera.width = scene.camera.height = size;
  return scene;
}

// Divides every value by `peak`: errors relative to the brightest pixel.
std::vector<float> Relative(std::vector<float> v, float peak) {
  for (float& x : v) x /= peak;
  return v;
}

// `truth` relative to its own brightest pixel; *peak is that pixel's value.
std::vector<float> RelativeToPeak(std::vector<float> truth, float* peak) {
  *peak = *std::max_element(truth.begin(), truth.end());
  return Relative(std::move(truth), *peak);
}

// One fixture view of the ambient occlusion study and its ray-traced truth.
struct OcclusionView {
  const std::string& name;
  const Scene& scene;
  const SceneGeometry& geometry;
  const CameraRays& camera;
  const GBuffer& truth_g;
  const std::vector<float>& truth;
};

// Where the error comes from: the reference's own noise (a second
// reference, another seed), what blending sums traced by rays (both
// sides, front sides), the exact gather of the default surfels, and
// the hierarchy against that gather.
Decomposition DecomposeOcclusionError(const OcclusionView& v, int reference_rays) {
  const float fov = static_cast<float>(v.scene.camera.fov_deg);
  const GBuffer& g = v.truth_g;
  const Crossings crossings = TraceCrossings(v.geometry, g, reference_rays / 2, 5);
  const std::vector<Surfel> surfels = Surfelize(v.geometry, v.camera.origin(), fov, {});
  const DssResult exact = GatherAllSurfels(g, surfels, {}, 0);
  const DssResult dss = SplatDeepScreenSpace(g, v.camera, surfels, {}, {});
  DssOptions with_cells;
  with_cells.occlusion_cells = 4;
  const DssResult cells = SplatDeepScreenSpace(g, v.camera, surfels, {}, with_cells);
  return {v.name,
          Signed(RayTracedOcclusion(v.geometry, g, reference_rays, 98), v.truth, g),
          Signed(crossings.both_sides, v.truth, g),
          Signed(crossings.front, v.truth, g),
          Signed(exact.occlusion, v.truth, g),
          Signed(dss.occlusion, v.truth, g),
          Signed(dss.occlusion, exact.occlusion, g),
          Signed(exact.occlusion, crossings.front, g),
          Signed(cells.occlusion, v.truth, g)};
}

// Plain Monte Carlo with Embree, 1 to 256 rays per pixel.
std::vector<Run> MonteCarloOcclusionRuns(const OcclusionView& v) {
  std::vector<Run> runs;
  for (int rays : {1, 2, 4, 8, 16, 32, 64, 128, 256}) {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer g = RenderGBuffer(v.geometry, v.scene, 0);
    const std::vector<float> ao = RayTracedOcclusion(v.geometry, g, rays, 7);
    const double seconds = Seconds(t0);
    runs.push_back({v.name, "monte carlo", "rays=" + std::to_string(rays), seconds, Compare(ao, v.truth, g), 0, 0, 0});
  }
  return runs;
}

// Plain screen space: the G-buffer's pixels as the only layer of surfels.
std::vector<Run> ScreenSpaceOcclusionRuns(const OcclusionView& v) {
  std::vector<Run> runs;
  for (int levels : {1, 2, 3, 4, 5}) {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer g = RenderGBuffer(v.geometry, v.scene, 0);
    const std::vector<Surfel> layer = SurfelsFromGBuffer(g, v.camera);
    DssOptions options;
    options.levels = levels;
    const DssResult r = SplatDeepScreenSpace(g, v.camera, layer, {}, options);
    const double seconds = Seconds(t0);
    runs.push_back({v.name, "screen space (one layer)", "levels=" + std::to_string(levels), seconds,
                    Compare(r.occlusion, v.truth, g), levels, options.epsilon, 0});
  }
  return runs;
}

// Deep screen space over s, levels and epsilon, then the bounced z-buffer.
std::vector<Run> DeepScreenSpaceOcclusionRuns(const OcclusionView& v) {
  const float fov = static_cast<float>(v.scene.camera.fov_deg);
  std::vector<Run> runs;
  // Blending over s, levels and epsilon; and with direction cells
  // (DssOptions::occlusion_cells, issue 17) over s, levels and the grid.
  for (float s : {0.01f, 0.02f, 0.04f})
    for (int levels : {2, 3, 4, 5})
      for (const auto& [epsilon, cells] :
           std::vector<std::pair<float, int>>{{1e-6f, 0}, {1e-7f, 0}, {1e-8f, 0}, {1e-6f, 4}, {1e-6f, 6}}) {
        const auto t0 = std::chrono::steady_clock::now();
        const GBuffer g = RenderGBuffer(v.geometry, v.scene, 0);
        SurfelOptions surfel_options;
        surfel_options.s = s;
        const std::vector<Surfel> surfels = Surfelize(v.geometry, v.camera.origin(), fov, surfel_options);
        DssOptions options;
        options.levels = levels;
        options.epsilon = epsilon;
        options.occlusion_cells = cells;
        const DssResult r = SplatDeepScreenSpace(g, v.camera, surfels, {}, options);
        const double seconds = Seconds(t0);
        runs.push_back({v.name, "deep screen space",
                        "s=" + FormatShort(s) + " levels=" + std::to_string(levels) +
                            " epsilon=" + FormatShort(epsilon) + (cells ? " cells=" + std::to_string(cells) : ""),
                        seconds, Compare(r.occlusion, v.truth, g), levels, epsilon, s});
      }
  for (float s : {0.04f, 0.02f}) {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer g = RenderGBuffer(v.geometry, v.scene, 0);
    SurfelOptions surfel_options;
    surfel_options.s = s;
    const std::vector<Surfel> surfels = Surfelize(v.geometry, v.camera.origin(), fov, surfel_options);
    const DssResult r = SplatBouncedZBuffer(g, v.camera, surfels, {}, {});
    const double seconds = Seconds(t0);
    runs.push_back({v.name, "bounced z-buffer", "s=" + FormatShort(s) + " levels=3", seconds,
                    Compare(r.occlusion, v.truth, g), 3, 1e-6f, s});
  }
  return runs;
}

struct OcclusionStudy {
  std::vector<Run> runs;
  std::vector<Decomposition> decompositions;
};

// Ambient occlusion on each fixture view against its ray-traced truth.
OcclusionStudy StudyOcclusion(const std::vector<std::string>& views, int size, int reference_rays) {
  OcclusionStudy study;
  ProgressBar progress("dss study", views.size());
  for (const std::string& name : views) {
    const Scene scene = LoadView(name, size);
    SceneGeometry geometry(scene);
    const CameraRays camera(scene, 0);
    const GBuffer truth_g = RenderGBuffer(geometry, scene, 0);
    const std::vector<float> truth = RayTracedOcclusion(geometry, truth_g, reference_rays, 99);
    const OcclusionView view{name, scene, geometry, camera, truth_g, truth};
    study.decompositions.push_back(DecomposeOcclusionError(view, reference_rays));
    Append(study.runs, MonteCarloOcclusionRuns(view));
    Append(study.runs, ScreenSpaceOcclusionRuns(view));
    Append(study.runs, DeepScreenSpaceOcclusionRuns(view));
    progress.Advance();
  }
  progress.Finish();
  return study;
}

// The glow's bounce (what phos uses deep screen space for): the Cornell
// box 10 s after its LED went off, in the bands, against the path tracer
// with many samples; direct transport (no bounce), dss over its levels,
// and the path tracer at fewer samples.
std::vector<Run> GlowBounceRuns(int size, int reference_spp) {
  const Scene scene = LoadCornell(size);
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(40);
  geometry.SetTime(40);
  auto render = [&](Transport transport, int spp, int visibility, double* seconds) {
    FrameOptions options = DefaultFrameOptions(scene, transport);
    options.spp = spp;
    options.seed = 5;
    options.indirect_visibility = visibility != 0;
    const auto t0 = std::chrono::steady_clock::now();
    Image image = RenderBands(geometry, &solver, options);
    *seconds = Seconds(t0);
    return image;
  };
  double seconds = 0;
  const Image truth = render(Transport::kPath, reference_spp, 0, &seconds);
  const GBuffer g = RenderGBuffer(geometry, scene, 40);
  float peak = 0;
  const std::vector<float> truth_sum = RelativeToPeak(BandSum(truth), &peak);
  std::vector<Run> glow;
  auto add = [&](const std::string& method, const std::string& parameters, const Image& image, double t) {
    glow.push_back({"cornell-phosphor t=40 s (glow only)", method, parameters, t,
                    Compare(Relative(BandSum(image), peak), truth_sum, g), 0, 0, 0});
  };
  // (Each frame is rendered before its time is read: argument order is unspecified.)
  const Image direct = render(Transport::kDirect, 1, 0, &seconds);
  add("direct (no bounce)", "-", direct, seconds);
  const Image dss = render(Transport::kDss, 1, 0, &seconds);
  add("deep screen space (direct + one bounce)", "defaults", dss, seconds);
  const Image dss_z = render(Transport::kDss, 1, 1, &seconds);
  add("deep screen space + bounced z-buffer", "defaults", dss_z, seconds);
  for (int spp : {1, 4, 16, 64}) {
    const Image path = render(Transport::kPath, spp, 0, &seconds);
    add("path tracer", "spp=" + std::to_string(spp), path, seconds);
  }
  return glow;
}

// A Markdown table's rows of runs: method, parameters, seconds, RMSE and
// SSIM, after the view when `with_view`.
std::string RunRows(const std::vector<Run>& runs, bool with_view) {
  std::string md;
  for (const Run& r : runs) {
    md.append("| ");
    if (with_view) md.append(r.view).append(" | ");
    md.append(r.method)
        .append(" | ")
        .append(r.parameters)
        .append(" | ")
        .append(FormatShort(r.seconds))
        .append(" | ")
        .append(FormatShort(r.error.rmse))
        .append(" | ")
        .append(FormatShort(r.error.ssim))
        .append(" |\n");
  }
  return md;
}

// Media (1): the lights' single scattering and the voxels' glow, ray
// marched: the march's step against a fine reference (a sixteenth of a
// voxel, the same one sample per pixel), on the two media fixtures.
std::vector<Run> MarchRuns(int size) {
  std::vector<Run> runs;
  for (const auto& [name, t] :
       std::vector<std::pair<std::string, double>>{{"dust-sheets", 1.5}, {"glowing-liquid", 10.0}}) {
    const Scene scene = LoadView(name, size);
    SceneGeometry geometry(scene);
    CoupledSolver solver(scene, geometry);
    solver.AdvanceTo(t);
    geometry.SetTime(t);
    auto render = [&](float step_scale, int spp, double* seconds) {
      MarchOptions march;
      march.step_scale = step_scale;
      solver.media()->set_march_options(march);
      FrameOptions options = DefaultFrameOptions(scene, Transport::kDirect);
      options.direct_spp = spp;
      const auto t0 = std::chrono::steady_clock::now();
      Image image = RenderBands(geometry, &solver, options);
      *seconds = Seconds(t0);
      return image;
    };
    double seconds = 0;
    float peak = 0;
    const std::vector<float> truth = RelativeToPeak(BandSum(render(1.0f / 16, 1, &seconds)), &peak);
    const GBuffer all = AllPixels(scene.camera.width, scene.camera.height);
    for (float step : {4.0f, 2.0f, 1.0f, 0.5f, 0.25f}) {
      const std::vector<float> v = Relative(BandSum(render(step, 1, &seconds)), peak);
      runs.push_back({name + " t=" + FormatShort(t) + " s (media)", "ray march", "step=" + FormatShort(step) + " voxel",
                      seconds, Compare(v, truth, all), 0, 0, 0});
    }
  }
  return runs;
}

// The thin fog of the media study: sigma_t 1.5/m, albedo 0.9, filling the Cornell box.
Volume CornellFog(int band_count) {
  Volume fog;
  fog.name = "fog";
  fog.min_m = Vec3(0.001, 0.001, 0.001);
  fog.max_m = Vec3(0.555, 0.548, 0.559);
  fog.nx = fog.ny = fog.nz = 16;
  fog.density.assign(16 * 16 * 16, 1.0f);
  fog.sigma_t_per_m = 1.5;
  fog.albedo.assign(band_count, 0.9);
  return fog;
}

// Media (2): surface-to-volume light. The Cornell box of Fig. 8.15 filled
// with a thin fog (sigma_t 1.5/m, albedo 0.9) 10 s after lights-out: the
// glowing walls light the fog. The truth: 16 points per pixel on the
// transmittance interval map, 512 Monte Carlo rays per point; against it
// the interval map with fewer points and deep screen space, and Monte
// Carlo with fewer rays.
std::vector<Run> FogGlowRuns(int size) {
  Scene scene = LoadCornell(size);
  scene.volumes.push_back(CornellFog(scene.bands.band_count()));
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(40);
  geometry.SetTime(40);
  const CameraRays camera(scene, 40);
  const GBuffer g = RenderGBuffer(geometry, scene, 40);
  solver.media()->PrepareLighting(40);
  float peak = 0;
  const std::vector<float> truth = RelativeToPeak(
      MediumGlow(scene, geometry, solver, BuildIntervalMap(*solver.media(), g, camera, 16), camera, 512, 3), &peak);
  const GBuffer all = AllPixels(size, size);
  std::vector<Run> runs;
  auto run = [&](const std::string& method, int layers, int directions) {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer gb = RenderGBuffer(geometry, scene, 40);
    std::vector<float> v = MediumGlow(scene, geometry, solver, BuildIntervalMap(*solver.media(), gb, camera, layers),
                                      camera, directions, 11);
    const double seconds = Seconds(t0);
    v = Relative(std::move(v), peak);
    runs.push_back({"cornell fog t=40 s (glow in the medium)", method,
                    "layers=" + std::to_string(layers) + (directions ? " rays=" + std::to_string(directions) : ""),
                    seconds, Compare(v, truth, all), 0, 0, 0});
  };
  for (int layers : {1, 2, 4, 8, 16}) run("deep screen space (interval map)", layers, 0);
  for (int directions : {1, 4, 16, 64}) run("monte carlo (interval map)", 4, directions);
  run("monte carlo (interval map)", 16, 16);
  return runs;
}

// Directional occlusion of the sky: dusk-sign.json at 30 s (the sky at
// full level, no lamps), the sky's irradiance per pixel per unit of its
// radiance, against 1024 stratified sky rays (ray-traced truth).
std::vector<Run> SkyRuns(int size) {
  const Scene scene = LoadView("dusk-sign", size);
  SceneGeometry geometry(scene);
  geometry.SetTime(30);
  const CameraRays camera(scene, 30);
  const Environment& env = *scene.environment;
  const GBuffer truth_g = RenderGBuffer(geometry, scene, 30);
  const std::size_t n = truth_g.object.size();
  auto sky_rays = [&](const GBuffer& g, int rays) {
    std::vector<float> E(n, 0.0f);
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t p) {
      if (g.object[p] >= 0) E[p] = UnitSkyIrradiance(geometry, env, g.position[p], g.normal[p], rays, p * 7 + rays);
    });
    return E;
  };
  float peak = 0;
  const std::vector<float> truth = RelativeToPeak(sky_rays(truth_g, 1024), &peak);
  auto from_dss = [&](const GBuffer& g, const DssResult& r) {
    std::vector<float> E(n, 0.0f);
    for (std::size_t p = 0; p < n; ++p)
      if (g.object[p] >= 0)
        E[p] = SkyIrradianceFromOcclusion(r.occlusion[p], r.occlusion_y[p], g.normal[p].y(),
                                          static_cast<float>(env.gradient));
    return E;
  };
  const std::string view = "dusk-sign t=30 s (sky irradiance)";
  std::vector<Run> runs;
  for (int rays : {1, 4, 16, 64}) {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer g = RenderGBuffer(geometry, scene, 30);
    std::vector<float> E = sky_rays(g, rays);
    const double seconds = Seconds(t0);
    E = Relative(std::move(E), peak);
    runs.push_back(
        {view, "monte carlo (sky rays)", "rays=" + std::to_string(rays), seconds, Compare(E, truth, truth_g), 0, 0, 0});
  }
  for (const auto& [method, s_value, levels] :
       std::vector<std::tuple<std::string, float, int>>{{"deep screen space", 0.04f, 2},
                                                        {"deep screen space", 0.04f, 3},
                                                        {"deep screen space", 0.04f, 5},
                                                        {"deep screen space", 0.02f, 3},
                                                        {"bounced z-buffer", 0.04f, 3}}) {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer g = RenderGBuffer(geometry, scene, 30);
    SurfelOptions surfel_options;
    surfel_options.s = s_value;
    const std::vector<Surfel> surfels =
        Surfelize(geometry, camera.origin(), static_cast<float>(scene.camera.fov_deg), surfel_options);
    DssOptions options;
    options.levels = levels;
    const DssResult r = method == "bounced z-buffer" ? SplatBouncedZBuffer(g, camera, surfels, {}, options)
                                                     : SplatDeepScreenSpace(g, camera, surfels, {}, options);
    std::vector<float> E = from_dss(g, r);
    const double seconds = Seconds(t0);
    E = Relative(std::move(E), peak);
    runs.push_back({view, method, "s=" + FormatShort(s_value) + " levels=" + std::to_string(levels), seconds,
                    Compare(E, truth, truth_g), levels, 1e-6f, s_value});
  }
  return runs;
}

// Subsurface scattering: the wax of translucent-shadow.json at 2 s (lamp
// on), the radiant exitance of its pixels in the 550-587.5 nm band,
// against the exact gather of surfels twice as fine as the default (no
// path tracer in phos follows light beneath a surface); beside it the
// local answer without subsurface transport (R_d E, the direct
// transport's), whose error is the bleeding it misses.
std::vector<Run> WaxRuns(int size) {
  const Scene scene = LoadView("translucent-shadow", size);
  SceneGeometry geometry(scene);
  geometry.SetTime(2);
  const CameraRays camera(scene, 2);
  const int band = 4, wax = 1;
  const Subsurface& sss = *scene.objects[wax].subsurface;
  std::vector<Dipole> dipoles(scene.objects.size(),
                              Dipole::From(sss.sigma_a_per_m[band], sss.sigma_s_prime_per_m[band], sss.eta));
  const Light& lamp = scene.lights[0];
  const LightPose pose = PoseAt(lamp, 2);
  auto irradiance = [&](const Vec3f& p, const Vec3f& normal) {
    return static_cast<float>(lamp.E_per_band[band]) * UnitIrradiance(geometry, pose, p, normal);
  };
  GBuffer mask = RenderGBuffer(geometry, scene, 2);
  for (int& o : mask.object) o = o == wax ? 0 : -1;
  auto exitance = [&](float s_value, bool exact, double* seconds) {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer g = RenderGBuffer(geometry, scene, 2);
    SurfelOptions surfel_options;
    surfel_options.s = s_value;
    std::vector<Surfel> entering;
    std::vector<float> E_in;
    for (const Surfel& s :
         Surfelize(geometry, camera.origin(), static_cast<float>(scene.camera.fov_deg), surfel_options)) {
      if (s.object != wax) continue;
      const float E = irradiance(s.position, s.normal);
      if (E <= 0) continue;
      entering.push_back(s);
      E_in.push_back(E);
    }
    const std::vector<float> near = SubsurfaceNearField(g, s_value, static_cast<float>(scene.camera.fov_deg));
    DssOptions options;
    options.channels = 1;
    options.dipoles = &dipoles;
    options.near_m = &near;
    const DssResult r = exact ? GatherAllSurfels(g, entering, E_in, 1, &dipoles, &near)
                              : SplatDeepScreenSpace(g, camera, entering, E_in, options);
    std::vector<float> M(g.object.size(), 0.0f);
    for (std::size_t p = 0; p < M.size(); ++p)
      if (g.object[p] == wax)
        M[p] = dipoles[wax].Exitance(irradiance(g.position[p], g.normal[p]), near[p], r.irradiance[p]);
    *seconds = Seconds(t0);
    return M;
  };
  double seconds = 0;
  float peak = 0;
  const std::vector<float> truth = RelativeToPeak(exitance(0.02f, true, &seconds), &peak);
  const std::string view = "translucent-shadow t=2 s (wax exitance in the 550 nm band)";
  std::vector<Run> runs;
  auto add = [&](const std::string& method, const std::string& parameters, std::vector<float> M, double t) {
    runs.push_back({view, method, parameters, t, Compare(Relative(std::move(M), peak), truth, mask), 0, 0, 0});
  };
  {
    const auto t0 = std::chrono::steady_clock::now();
    const GBuffer g = RenderGBuffer(geometry, scene, 2);
    std::vector<float> M(g.object.size(), 0.0f);
    const float Rd = static_cast<float>(dipoles[wax].TotalReflectance());
    for (std::size_t p = 0; p < M.size(); ++p)
      if (g.object[p] == wax) M[p] = Rd * irradiance(g.position[p], g.normal[p]);
    add("no subsurface transport (R_d E)", "-", M, Seconds(t0));
  }
  for (float s_value : {0.08f, 0.04f, 0.02f}) {
    std::vector<float> M = exitance(s_value, false, &seconds);
    add("deep screen space (dipole)", "s=" + FormatShort(s_value), M, seconds);
  }
  std::vector<float> M = exitance(0.04f, true, &seconds);
  add("exact gather (dipole)", "s=0.04", M, seconds);
  return runs;
}

std::string RunsCsv(const std::vector<Run>& runs) {
  std::string csv = "view,method,parameters,seconds,rmse,ssim\n";
  for (const Run& r : runs)
    csv.append(r.view)
        .append(",")
        .append(r.method)
        .append(",")
        .append(r.parameters)
        .append(",")
        .append(FormatDouble(r.seconds))
        .append(",")
        .append(FormatDouble(r.error.rmse))
        .append(",")
        .append(FormatDouble(r.error.ssim))
        .append("\n");
  return csv;
}

// Per method and parameters, the means over the ambient occlusion views
// (the glow runs have their own table): seconds, RMSE and SSIM.
struct OcclusionMeans {
  std::map<std::string, std::map<std::string, std::pair<double, double>>> time_rmse;  // (s, rmse)
  std::map<std::string, std::map<std::string, double>> ssim;
};

OcclusionMeans MeanOverViews(const std::vector<Run>& runs, const std::vector<std::string>& views) {
  OcclusionMeans mean;
  for (const Run& r : runs) {
    if (std::find(views.begin(), views.end(), r.view) == views.end()) continue;
    auto& m = mean.time_rmse[r.method][r.parameters];
    m.first += r.seconds / views.size();
    m.second += r.error.rmse / views.size();
    mean.ssim[r.method][r.parameters] += r.error.ssim / views.size();
  }
  return mean;
}

PlotOptions OcclusionPlotOptions(int size) {
  PlotOptions plot;
  plot.title = "Ambient occlusion: RMSE against ray-traced truth vs time (mean of the fixture views)";
  plot.x_label = "seconds per frame (G-buffer included), " + std::to_string(size) + " px high";
  plot.y_label = "RMSE of occlusion";
  plot.log_x = plot.log_y = true;
  return plot;
}

// Error against time, per method, both views (RMSE; time and error means over the views).
std::string OcclusionTradeSvg(const OcclusionMeans& mean, int size) {
  std::vector<PlotSeries> series;
  int color = 0;
  for (const auto& [method, by_parameters] : mean.time_rmse) {
    PlotSeries s(method);
    s.markers = true;
    s.line = method != "deep screen space";
    s.color = PaletteColor(color++);
    std::vector<std::pair<double, double>> points;
    for (const auto& [parameters, v] : by_parameters) points.push_back(v);
    std::sort(points.begin(), points.end());
    for (const auto& [t, e] : points) s.x.push_back(t), s.y.push_back(e);
    series.push_back(s);
  }
  return PlotSvg(series, OcclusionPlotOptions(size));
}

// The default search: at each budget, the lowest mean RMSE per method; the
// budget table's rows, dss-budget.csv and both methods' curves.
struct BudgetSearch {
  std::string table, csv = "budget_s,method,parameters,seconds,rmse,ssim\n";
  PlotSeries dss_curve{"deep screen space, best within budget"}, mc_curve{"monte carlo, best within budget"};
};

// The parameters of `method` with the lowest mean RMSE within `budget`
// seconds; empty when none fits.
std::string BestWithin(const OcclusionMeans& mean, const std::string& method, double budget) {
  std::string chosen;
  double error = 1e300;
  const auto by_parameters = mean.time_rmse.find(method);
  if (by_parameters == mean.time_rmse.end()) return chosen;
  for (const auto& [parameters, v] : by_parameters->second)
    if (v.first <= budget && v.second < error) error = v.second, chosen = parameters;
  return chosen;
}

// One method's best within a budget: its cells of the table (the last one
// ending in `end`), its line of the CSV and a point of its curve.
void AddBest(const OcclusionMeans& mean, const std::string& method, double budget, const std::string& end,
             BudgetSearch& search, PlotSeries& curve) {
  const std::string chosen = BestWithin(mean, method, budget);
  if (chosen.empty()) {
    search.table.append("- | - | - | -").append(end);
    return;
  }
  const auto v = mean.time_rmse.at(method).at(chosen);
  const double ssim = mean.ssim.at(method).at(chosen);
  search.table.append(chosen)
      .append(" | ")
      .append(FormatShort(v.first))
      .append(" | ")
      .append(FormatShort(v.second))
      .append(" | ")
      .append(FormatShort(ssim))
      .append(end);
  search.csv.append(FormatDouble(budget))
      .append(",")
      .append(method)
      .append(",")
      .append(chosen)
      .append(",")
      .append(FormatDouble(v.first))
      .append(",")
      .append(FormatDouble(v.second))
      .append(",")
      .append(FormatDouble(ssim))
      .append("\n");
  curve.x.push_back(budget);
  curve.y.push_back(v.second);
}

BudgetSearch SearchBudgets(const OcclusionMeans& mean) {
  BudgetSearch search;
  search.dss_curve.markers = search.mc_curve.markers = true;
  for (double budget : {0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 4.0}) {
    search.table.append("| ").append(FormatShort(budget)).append(" | ");
    AddBest(mean, "deep screen space", budget, " | ", search, search.dss_curve);
    AddBest(mean, "monte carlo", budget, " |\n", search, search.mc_curve);
  }
  return search;
}

// Issue 17: the floor of ambient occlusion, taken apart.
std::string ErrorSourcesMd(const std::vector<Decomposition>& decompositions, int size, int reference_rays) {
  auto cell = [](const Bias& b) { return FormatShort(b.bias) + " / " + FormatShort(b.rmse); };
  std::string md =
      "\n## Where the error of ambient occlusion comes from\n\n"
      "Blending had an RMSE floor of 0.187 on both views (0.1874 Cornell, 0.1866 still life, at the "
      "defaults) that no setting of s, levels or epsilon moved: a bias, DSS above the reference by "
      "+0.153 and +0.141 on average. The reference (`RayTracedOcclusion`) and DSS share their definition "
      "(cosine-weighted, no distance bound; epsilon cuts contributions below 1e-6), so the difference was "
      "in what is counted. A ray traced through every surface it crosses tells it: the sum of form factors "
      "over all surfels is the mean number of surfaces a cosine-distributed ray crosses, where the "
      "reference counts whether it hits one. Two causes:\n\n"
      "1. **Both sides of closed surfaces were counted** (fixed). A ray crosses a closed surface once "
      "from each side: into a block and out of its far side. Blending summed the surfels of both sides "
      "(`|cos_q|`), so every closed occluder counted twice: the blocks, balls, box and pedestal. "
      "Occlusion now sums "
      "the surfels facing the receiver and those seen from behind apart and keeps the larger sum: for "
      "closed surfaces the front (back-facing surfels are their far sides, never more than the front), "
      "for an open sheet seen from behind its back (`ResolveOcclusion` in render/src/dss.cpp; "
      "`dss_test`'s closed slab over a floor point occludes F = 0.2394, the closed form, where both sides "
      "gave 2F = 0.479).\n"
      "2. **Visibility** (inherent to a plain sum). What remains is the rest of surfels behind surfels: a "
      "ray that enters a block and then meets the wall behind it counts twice. A sum cannot know which "
      "surfel is nearer. It is largest where occluders stand in front of other surfaces: the Cornell floor "
      "and walls around the blocks. **Direction cells** (`DssOptions::occlusion_cells`, new) remove most "
      "of it without a z-buffer: each receiver's cosine-weighted hemisphere, projected onto the unit disk "
      "(a surfel covers pi F of it), is cut into an N x N grid, the sums are kept per cell (still sums: "
      "they go through the interleaved levels and the blur unchanged) and each cell counts at most its "
      "share of the disk, so a covered direction counts once however many surfaces lie along it. What they "
      "miss: a cell that two surfaces both cover in part counts whole (too much), and finer cells lose "
      "occlusion (too little: the bias turns negative from N = 6 on the Cornell box), so N = 4 to 6 is "
      "best (`dss_test`: a wall behind a wall, 0.50 against Lambert's 0.486 where the sum gives twice "
      "that).\n\n"
      "Bias (mean of DSS minus the reference) / RMSE, per view, at " +
      std::to_string(size) + " px; the traced sums with " + std::to_string(reference_rays / 2) +
      " rays per pixel, the reference's own noise against a second reference with another seed:\n\n"
      "| view | reference noise | both sides, traced (before) | front sides, traced (after) | exact gather, "
      "defaults | DSS, defaults | DSS against the exact gather | exact gather against the traced front sum "
      "| DSS, defaults and 4 x 4 direction cells |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const Decomposition& d : decompositions)
    md += "| " + d.view + " | " + cell(d.noise) + " | " + cell(d.both_sides) + " | " + cell(d.front) + " | " +
          cell(d.exact) + " | " + cell(d.dss) + " | " + cell(d.hierarchy) + " | " + cell(d.definition) + " | " +
          cell(d.cells) + " |\n";
  md +=
      "\nThe exact gather follows the traced front-side sum (column 'exact gather against the traced "
      "front sum': the surfels' discretization and the traced sum's noise), so what is left of DSS's error is "
      "visibility (the bias), plus the "
      "hierarchy's own error against the exact gather (unbiased) and the reference's noise. No setting of "
      "the surfels or the hierarchy removes the bias, which is why the error of the plain sum is flat in "
      "s, levels and epsilon; direction cells take most of it away (last column).\n";
  return md;
}

// The goal of issue 17: DSS on the Pareto front of error against time.
// Per view, the DSS runs that no Monte Carlo run dominates (as fast or
// faster and as accurate or more).
std::string ParetoMd(const std::vector<Run>& runs, const std::vector<std::string>& views) {
  std::string md =
      "\n**On the Pareto front?** Per view, the DSS runs of this study that no Monte Carlo run dominates "
      "(none at most as slow and at most as wrong, RMSE), among those no slower than the slowest Monte "
      "Carlo run (beyond it nothing is measured to compare). Times wander by 10-30% between runs, so a "
      "run within that of a Monte Carlo run is a tie:\n\n";
  for (const std::string& view : views) {
    std::string front;
    double slowest = 0;
    for (const Run& m : runs)
      if (m.view == view && m.method == "monte carlo") slowest = std::max(slowest, m.seconds);
    for (const Run& d : runs) {
      if (d.view != view || d.method != "deep screen space" || d.seconds > slowest) continue;
      bool dominated = false;
      for (const Run& m : runs)
        if (m.view == view && m.method == "monte carlo" && m.seconds <= d.seconds && m.error.rmse <= d.error.rmse)
          dominated = true;
      if (!dominated)
        front += "\n  - " + d.parameters + ": " + FormatShort(d.error.rmse) + " in " + FormatShort(d.seconds) + " s";
    }
    md += "- " + view + ":" + (front.empty() ? std::string(" none") : front) + "\n";
  }
  return md;
}

// One effect's plot: RMSE against seconds per method.
std::string EffectPlotSvg(const std::vector<Run>& runs, const std::string& view, int size) {
  std::map<std::string, std::vector<std::pair<double, double>>> by_method;
  for (const Run& r : runs)
    if (r.view == view) by_method[r.method].push_back({r.seconds, r.error.rmse});
  std::vector<PlotSeries> effect_series;
  int c = 0;
  for (auto& [method, points] : by_method) {
    std::sort(points.begin(), points.end());
    PlotSeries series(method);
    series.markers = true;
    series.color = PaletteColor(c++);
    for (const auto& [t, e] : points) series.x.push_back(t), series.y.push_back(e);
    effect_series.push_back(series);
  }
  PlotOptions effect_plot;
  effect_plot.title = view + ": RMSE vs time";
  effect_plot.x_label = "seconds per frame, " + std::to_string(size) + " px high";
  effect_plot.y_label = "RMSE (relative to the brightest pixel)";
  effect_plot.log_x = effect_plot.log_y = true;
  return PlotSvg(effect_series, effect_plot);
}

// The other effects: one plot each, RMSE against seconds per method
// (docs/dss-trade-<effect>.svg); returns the page's line linking them.
std::string WriteEffectPlots(const std::vector<Run>& runs, int size, const fs::path& out) {
  const std::vector<std::pair<std::string, std::string>> effect_plots = {
      {"cornell-phosphor t=40 s (glow only)", "glow-bounce"},
      {"cornell fog t=40 s (glow in the medium)", "fog"},
      {"dusk-sign t=30 s (sky irradiance)", "sky"},
      {"translucent-shadow t=2 s (wax exitance in the 550 nm band)", "wax"},
      {"glowing-liquid t=10 s (media)", "march"}};
  std::string plots_md = "\nPlots of RMSE against time per effect: ";
  for (const auto& [view, file] : effect_plots) {
    const std::string name = "dss-trade-" + file + ".svg";
    WriteFileAtomically(out / name, EffectPlotSvg(runs, view, size));
    plots_md.append("[").append(file).append("](").append(name).append(") ");
  }
  return plots_md + "\n";
}

// The page's tables of the glow's bounce, media, and the sky and the wax.
std::string GlowMd(const std::vector<Run>& glow, int size, int reference_spp) {
  return "\n## The glow's bounce (what phos uses it for)\n\nThe Cornell box 10 s after its LED went off, " +
         std::to_string(size) +
         " px, summed over the bands and relative to the brightest pixel, against the path tracer at " +
         std::to_string(reference_spp) +
         " samples per pixel.\n\n| method | parameters | seconds | RMSE | SSIM |\n|---|---|---|---|---|\n" +
         RunRows(glow, false);
}

std::string MediaMd(const std::vector<Run>& media_runs, int size) {
  return "\n## Media\n\nRay-marched single scattering and glow against a march of a sixteenth of a voxel "
         "(the same one sample per pixel); the glow that the media scatter of glowing surfaces against 16 "
         "interval-map points per pixel with 512 Monte Carlo rays each. " +
         std::to_string(size) +
         " px high, band sums relative to the brightest pixel, every pixel counted.\n\n"
         "| view | method | parameters | seconds | RMSE | SSIM |\n|---|---|---|---|---|---|\n" +
         RunRows(media_runs, true);
}

std::string EffectsMd(const std::vector<Run>& effect_runs, int size) {
  return "\n## Directional occlusion and subsurface scattering\n\nThe sky's irradiance on dusk-sign "
         "against 1024 sky rays per pixel; the wax's exitance against the exact gather of surfels at s = 0.02 "
         "(band sums relative to the brightest pixel; " +
         std::to_string(size) +
         " px high).\n\n"
         "| view | method | parameters | seconds | RMSE | SSIM |\n|---|---|---|---|---|---|\n" +
         RunRows(effect_runs, true);
}

// The head of dss-trade.md: ambient occlusion's budget table.
std::string BudgetMd(const BudgetSearch& search, int size, int reference_rays) {
  return "<!-- written by: build/bin/phos-dss-study --out docs -->\n# Deep screen space: error against time\n\n"
         "Ambient occlusion at " +
         std::to_string(size) + " px high on the fixture views " +
         "(cornell-phosphor, still-life), against ray-traced occlusion with " + std::to_string(reference_rays) +
         " cosine-distributed rays per pixel. Times include the G-buffer; errors are means over the views. "
         "All runs: [dss-trade.csv](dss-trade.csv), plot [dss-trade.svg](dss-trade.svg).\n\n"
         "| budget (s) | DSS: best settings | DSS s | DSS RMSE | DSS SSIM | Monte Carlo: best | MC s | MC RMSE | MC "
         "SSIM |\n"
         "|---|---|---|---|---|---|---|---|---|\n" +
         search.table;
}

}  // namespace
}  // namespace phos::render

int main(int argc, char** argv) {
  using namespace phos;
  using namespace phos::render;
  CLI::App app{
      "Deep screen space against ray-traced and path-traced truth, Monte Carlo and screen space: error against "
      "time\n(occlusion, the glow's bounce, media, the sky, translucency)."};
  std::string out = "docs";
  int size = 128, reference_rays = 2048;
  app.add_option("--out", out, "folder for the CSVs, plots and dss-trade.md (default docs)");
  app.add_option("--size", size, "image size in pixels, square (default 128)");
  app.add_option("--reference-rays", reference_rays, "rays per pixel of the ray-traced truth (default 2048)");
  std::string quality_table;
  app.add_option("--quality-table", quality_table,
                 "also write the glow's-bounce SSIMs as the renderer's expected quality of each transport\n"
                 "(phos.transport-quality/1; make study writes render/data/transport-quality.json, which the\n"
                 "build compiles into --budget-s and --quality) (default: not written)");
  CLI11_PARSE(app, argc, argv);
  try {
    const std::vector<std::string> views = {"cornell-phosphor", "still-life"};
    const int reference_spp = 4 * reference_rays / 8;
    OcclusionStudy occlusion = StudyOcclusion(views, size, reference_rays);
    std::vector<Run>& runs = occlusion.runs;
    const std::vector<Run> glow = GlowBounceRuns(size, reference_spp);
    if (!quality_table.empty()) WriteQualityTable(quality_table, glow, size, reference_spp);
    Append(runs, glow);
    std::vector<Run> media_runs = MarchRuns(size);
    Append(media_runs, FogGlowRuns(size));
    Append(runs, media_runs);
    std::vector<Run> effect_runs = SkyRuns(size);
    Append(effect_runs, WaxRuns(size));
    Append(runs, effect_runs);

    fs::create_directories(out);
    WriteFileAtomically(fs::path(out) / "dss-trade.csv", RunsCsv(runs));
    const OcclusionMeans mean = MeanOverViews(runs, views);
    WriteFileAtomically(fs::path(out) / "dss-trade.svg", OcclusionTradeSvg(mean, size));
    const BudgetSearch search = SearchBudgets(mean);
    WriteFileAtomically(fs::path(out) / "dss-budget.csv", search.csv);
    PlotOptions plot = OcclusionPlotOptions(size);
    plot.title = "The default search: lowest RMSE within a time budget";
    plot.x_label = "time budget (s)";
    WriteFileAtomically(fs::path(out) / "dss-budget.svg", PlotSvg({search.dss_curve, search.mc_curve}, plot));

    const std::string md =
        BudgetMd(search, size, reference_rays) + ErrorSourcesMd(occlusion.decompositions, size, reference_rays) +
        ParetoMd(runs, views) +
        "\nMeasured by `build/bin/phos-dss-study --out docs` (`make study`); the analytic checks of both "
        "causes are `dss_test`'s `AClosedSlabOverheadOccludesOnceAndAnOpenSheetFromBehindToo` and "
        "`DirectionCellsCountAWallBehindAWallOnce`.\n" +
        GlowMd(glow, size, reference_spp) + MediaMd(media_runs, size) + EffectsMd(effect_runs, size) +
        WriteEffectPlots(runs, size, out);
    WriteFileAtomically(fs::path(out) / "dss-trade.md", md);
    std::printf("%s", md.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "phos-dss-study: %s\n", e.what());
    return 2;
  }
  return 0;
}
