// The renderer on the Cornell fixture (fixtures/scenes/cornell-phosphor.json)
// at 512 x 512: the coupled step for its phosphorescent texels, the
// direct-light frame and the path-traced frame timed separately, with
// throughput in rays per second next to the machine's Embree ceiling measured
// in the same run (primary rays that only intersect, and incoherent rays
// between random points of the box: the two ends of what a renderer casts).
//
// Two ratios are measured by alternating the two sides inside one benchmark,
// so the machine's noise hits both alike (docs/render.md's "only what the
// scene requires", Sec. 8.5's 454 vs 448 ms):
//   BM_PhosphorescenceOverhead: a frame (coupled step + direct render) with
//     phosphorescence over one without; counter `ratio`.
//   BM_FrameAfterLightsOut: a frame an hour after lights-out over one a second
//     after; counter `ratio` (the goal: within 20% of 1).
//   BM_TexturedDirectFrame/0: a 640 x 480 direct frame of the textured-plane
//     fixture (fixtures/scenes/textured-plane.json, its albedo a glTF
//     baseColorTexture through OpenImageIO's TextureSystem) over the same
//     scene untextured (the texture's factor as a constant albedo); counter
//     `ratio` (the goal: at most 1.5). /1: the same for the glTF sign
//     (fixtures/scenes/glow-sign.json at 640 x 480: textured sign, an area
//     light and a point light), a scene whose untextured pixel costs more.
//   BM_PathAgainstBareEmbree: a path-traced frame over bare rtcIntersect1 /
//     rtcOccluded1 calls on the very rays that frame cast (recorded, then
//     replayed in the same order); counter `ratio` (the goal: at most 1.5).
//   BM_PathAgainstBareEmbreeBySize/s: the same after dark, with a plain
//     white icosphere of 20 x 4^s triangles floating in the box: how the
//     ratio moves as Embree's traversal costs more per ray and the shading
//     per vertex stays the same (the fixture itself has 30 triangles).
//   BM_PathAgainstBareEmbreeGlowingBySize/s: the same with the sphere painted
//     with the back wall's phosphor, so its glow is looked up and sampled.
//   BM_GlowChoiceByBlocks/s: that scene's glowing sphere's triangles chosen by
//     blocks (FrameOptions::emitter_blocks_above_triangles) against one by one, at
//     1 spp over 8 seeds each: counters `variance_ratio` (the pixels' variance
//     by blocks over one by one), `mean_ratio` (their images' means: 1 but
//     for noise), `time_ratio` and `efficiency_ratio` (1 / (variance x time),
//     by blocks over one by one).
//
// Run: build/bin/bench_render (make bench saves the output in docs/bench/).

#include <benchmark/benchmark.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <random>

#include <embree3/rtcore.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "phos/render/dss.h"
#include "phos/render/geometry.h"
#include <tbb/global_control.h>
#include "phos/render/renderer.h"
#include "phos/render/scene.h"
#include "phos/render/solver.h"

namespace phos::render {
namespace {

constexpr int kSize = 512;
constexpr double kLightsOff = 30;  // the fixture's LED goes off at 30 s

struct Cornell {
  Scene scene;
  std::unique_ptr<SceneGeometry> geometry;
  std::unique_ptr<CoupledSolver> solver;
  // sphere_subdivisions >= 0: a plain white icosphere (20 x 4^s triangles,
  // radius 8 cm) floats in the box above the short block; glowing_sphere:
  // painted with the back wall's phosphor instead (a texel per triangle at
  // least, so its atlas grows with it).
  explicit Cornell(double texel_size_m = 0.0, int sphere_subdivisions = -1, bool glowing_sphere = false) {
    scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/cornell-phosphor.json");
    scene.camera.width = scene.camera.height = kSize;
    if (texel_size_m > 0) scene.texel_size_m = texel_size_m;
    if (sphere_subdivisions >= 0) {
      Mesh sphere = MakeSphere(0.08, sphere_subdivisions, /*inward=*/false);
      for (Eigen::Vector3f& p : sphere.positions) p += Eigen::Vector3f(0.42f, 0.42f, 0.12f);
      Object ball;
      if (glowing_sphere) ball = scene.objects[2];  // the back wall: green phosphor, albedo 0.7
      ball.name = "ball";
      ball.mesh = std::make_shared<Mesh>(std::move(sphere));
      if (!glowing_sphere) ball.albedo.assign(scene.bands.band_count(), 0.8);
      scene.objects.push_back(std::move(ball));
    }
    geometry = std::make_unique<SceneGeometry>(scene);
    solver = std::make_unique<CoupledSolver>(scene, *geometry);
  }
};

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

// The coupled step alone, lit (cached irradiance, AdvanceBatch) and dark (DecayBatch).
// Arg: texel size in mm (10: the fixture's 37k texels; 1: 3.7 M texels, the paper's scale).
void BM_CoupledStepLit(benchmark::State& state) {
  Cornell c(state.range(0) * 1e-3);
  double t = 0;
  c.solver->AdvanceTo(t += 1e-3);  // irradiance computed once here
  for (auto _ : state) {
    c.solver->AdvanceTo(t += 1e-3);  // stays inside the lit interval
    benchmark::ClobberMemory();
  }
  state.counters["texels"] = static_cast<double>(c.solver->stats().texels);
  state.counters["texel_steps/s"] =
      benchmark::Counter(static_cast<double>(c.solver->stats().texels), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_CoupledStepLit)->Arg(10)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_CoupledStepDark(benchmark::State& state) {
  Cornell c(state.range(0) * 1e-3);
  double t = kLightsOff;
  c.solver->AdvanceTo(t);
  for (auto _ : state) {
    c.solver->AdvanceTo(t += 1.0 / 30);
    benchmark::ClobberMemory();
  }
  state.counters["texels"] = static_cast<double>(c.solver->stats().texels);
  state.counters["texel_steps/s"] =
      benchmark::Counter(static_cast<double>(c.solver->stats().texels), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_CoupledStepDark)->Arg(10)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void RenderBenchmark(benchmark::State& state, Transport transport, double t_s) {
  Cornell c;
  c.solver->AdvanceTo(t_s);
  FrameOptions options = DefaultFrameOptions(c.scene, transport);
  options.spp = 1;
  std::uint64_t rays = 0;
  for (auto _ : state) {
    FrameStats stats;
    Image image = RenderBands(*c.geometry, c.solver.get(), options, &stats);
    benchmark::DoNotOptimize(image.pixels.data());
    rays += stats.rays;
  }
  state.counters["Mrays/s"] = benchmark::Counter(static_cast<double>(rays) * 1e-6, benchmark::Counter::kIsRate);
}

void BM_DirectFrameLit(benchmark::State& state) { RenderBenchmark(state, Transport::kDirect, 20); }
BENCHMARK(BM_DirectFrameLit)->Unit(benchmark::kMillisecond)->UseRealTime();
void BM_DirectFrameDark(benchmark::State& state) { RenderBenchmark(state, Transport::kDirect, 40); }
BENCHMARK(BM_DirectFrameDark)->Unit(benchmark::kMillisecond)->UseRealTime();
// One path per pixel: multiply by spp for a frame.
void BM_PathFrameLit1spp(benchmark::State& state) { RenderBenchmark(state, Transport::kPath, 20); }
BENCHMARK(BM_PathFrameLit1spp)->Unit(benchmark::kMillisecond)->UseRealTime();
void BM_PathFrameDark1spp(benchmark::State& state) { RenderBenchmark(state, Transport::kPath, 40); }
BENCHMARK(BM_PathFrameDark1spp)->Unit(benchmark::kMillisecond)->UseRealTime();

// Embree's ceiling on this machine and scene: rays that only find their hit.
void BM_EmbreeCeilingPrimary(benchmark::State& state) {
  Cornell c;
  const CameraRays camera(c.scene, 0);
  std::uint64_t rays = 0;
  for (auto _ : state) {
    std::atomic<int> hits{0};
    tbb::parallel_for(0, kSize, [&](int y) {
      int h = 0;
      for (int x = 0; x < kSize; ++x) {
        h += static_cast<bool>(c.geometry->Intersect(camera.origin(), camera.Direction(x + 0.5f, y + 0.5f)));
      }
      hits += h;
    });
    benchmark::DoNotOptimize(hits.load());
    rays += std::uint64_t(kSize) * kSize;
  }
  state.counters["Mrays/s"] = benchmark::Counter(static_cast<double>(rays) * 1e-6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_EmbreeCeilingPrimary)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_EmbreeCeilingIncoherent(benchmark::State& state) {
  Cornell c;
  constexpr int kRays = kSize * kSize;
  std::vector<Vec3f> origins(kRays), directions(kRays);
  std::mt19937 random(1);
  std::uniform_real_distribution<float> u(0.01f, 0.54f);
  for (int i = 0; i < kRays; ++i) {
    origins[i] = Vec3f(u(random), u(random), u(random));
    directions[i] = (Vec3f(u(random), u(random), u(random)) - Vec3f::Constant(0.275f)).normalized();
  }
  std::uint64_t rays = 0;
  for (auto _ : state) {
    std::atomic<int> hits{0};
    tbb::parallel_for(tbb::blocked_range<int>(0, kRays, 4096), [&](const tbb::blocked_range<int>& r) {
      int h = 0;
      for (int i = r.begin(); i < r.end(); ++i)
        h += static_cast<bool>(c.geometry->Intersect(origins[i], directions[i]));
      hits += h;
    });
    benchmark::DoNotOptimize(hits.load());
    rays += kRays;
  }
  state.counters["Mrays/s"] = benchmark::Counter(static_cast<double>(rays) * 1e-6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_EmbreeCeilingIncoherent)->Unit(benchmark::kMillisecond)->UseRealTime();

// Every ray a frame casts, per thread in the order cast.
class ThreadRayLog : public RayRecorder {
 public:
  void Record(const CastRay& ray) override { rays_.local().push_back(ray); }
  std::vector<CastRay> Flatten() const {
    std::vector<CastRay> all;
    for (const auto& rays : rays_) all.insert(all.end(), rays.begin(), rays.end());
    return all;
  }

 private:
  tbb::enumerable_thread_specific<std::vector<CastRay>> rays_;
};

// Embree alone on recorded rays: the renderer's calls without anything
// around them (no hit record, no shading), in blocks of consecutive rays.
int ReplayBare(RTCScene scene, const std::vector<CastRay>& rays) {
  std::atomic<int> hits{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      RTCIntersectContext context;
                      rtcInitIntersectContext(&context);
                      int h = 0;
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        const CastRay& c = rays[i];
                        RTCRayHit ray{};
                        ray.ray.org_x = c.origin.x();
                        ray.ray.org_y = c.origin.y();
                        ray.ray.org_z = c.origin.z();
                        ray.ray.dir_x = c.direction.x();
                        ray.ray.dir_y = c.direction.y();
                        ray.ray.dir_z = c.direction.z();
                        ray.ray.tfar = c.t_far;
                        ray.ray.mask = 0xFFFFFFFFu;
                        if (c.occlusion) {
                          rtcOccluded1(scene, &context, &ray.ray);
                          h += ray.ray.tfar < 0;
                        } else {
                          ray.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                          rtcIntersect1(scene, &context, &ray);
                          h += ray.hit.geomID != RTC_INVALID_GEOMETRY_ID;
                        }
                      }
                      hits += h;
                    });
  return hits.load();
}

// The same rays through SceneGeometry's Intersect and Occluded (the hit
// record: position, normal, side).
int ReplayWrapped(const SceneGeometry& geometry, const std::vector<CastRay>& rays) {
  std::atomic<int> hits{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      int h = 0;
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        const CastRay& c = rays[i];
                        h += c.occlusion ? geometry.Occluded(c.origin, c.direction, c.t_far)
                                         : static_cast<bool>(geometry.Intersect(c.origin, c.direction, c.t_far));
                      }
                      hits += h;
                    });
  return hits.load();
}

// The path tracer (1 spp, lit at 20 s or dark at 40 s) against bare Embree on
// the same rays: what shading, sampling and bookkeeping add to tracing.
// Alternated; best of each side.
void PathAgainstBareEmbree(benchmark::State& state, Cornell& c, double t_s, int spp = 1) {
  c.solver->AdvanceTo(t_s);
  FrameOptions options = DefaultFrameOptions(c.scene, Transport::kPath);
  options.spp = spp;
  ThreadRayLog log;
  c.geometry->SetRayRecorder(&log);
  FrameStats recorded;
  RenderBands(*c.geometry, c.solver.get(), options, &recorded);
  c.geometry->SetRayRecorder(nullptr);
  const std::vector<CastRay> rays = log.Flatten();
  std::size_t shadow = 0;
  for (const CastRay& r : rays) shadow += r.occlusion;
  double best_path = 1e9, best_bare = 1e9, best_wrapped = 1e9, best_path_setup = 0;
  for (auto _ : state) {
    double start = Now();
    FrameStats frame;
    Image image = RenderBands(*c.geometry, c.solver.get(), options, &frame);
    if (const double elapsed = Now() - start; elapsed < best_path) {
      best_path = elapsed;
      best_path_setup = frame.setup_s;
    }
    start = Now();
    benchmark::DoNotOptimize(ReplayBare(c.geometry->embree_scene(), rays));
    best_bare = std::min(best_bare, Now() - start);
    start = Now();
    benchmark::DoNotOptimize(ReplayWrapped(*c.geometry, rays));
    best_wrapped = std::min(best_wrapped, Now() - start);
    benchmark::DoNotOptimize(image.pixels.data());
  }
  state.counters["wrapped_ratio"] = best_wrapped / best_bare;
  state.counters["rays"] = static_cast<double>(rays.size());
  state.counters["shadow_share"] = static_cast<double>(shadow) / static_cast<double>(rays.size());
  state.counters["path_Mrays/s"] = static_cast<double>(rays.size()) * 1e-6 / best_path;
  state.counters["bare_Mrays/s"] = static_cast<double>(rays.size()) * 1e-6 / best_bare;
  state.counters["ratio"] = best_path / best_bare;
  // The best frame's set-up (the glow copy and the emitter table, FrameStats)
  // as a share of it, and the ratio of the rest: what the paths cost per ray
  // once the frame is set up.
  state.counters["setup_share"] = best_path_setup / best_path;
  state.counters["traced_ratio"] = (best_path - best_path_setup) / best_bare;
}
void BM_PathAgainstBareEmbree(benchmark::State& state) {
  Cornell c;
  PathAgainstBareEmbree(state, c, static_cast<double>(state.range(0)));
}
BENCHMARK(BM_PathAgainstBareEmbree)->Arg(20)->Arg(40)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
void PathAgainstBareEmbreeBySize(benchmark::State& state, bool glowing_sphere, int spp = 1) {
  Cornell c(0.0, static_cast<int>(state.range(0)), glowing_sphere);
  std::size_t triangles = 0;
  for (const Object& object : c.scene.objects) triangles += object.mesh->triangles.size();
  PathAgainstBareEmbree(state, c, 40, spp);
  state.counters["triangles"] = static_cast<double>(triangles);
  state.counters["texels"] = static_cast<double>(c.solver->stats().texels);
}
void BM_PathAgainstBareEmbreeBySize(benchmark::State& state) { PathAgainstBareEmbreeBySize(state, false); }
BENCHMARK(BM_PathAgainstBareEmbreeBySize)
    ->Arg(0)
    ->Arg(2)
    ->Arg(4)
    ->Arg(6)
    ->Arg(8)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(2.0);
void BM_PathAgainstBareEmbreeGlowingBySize(benchmark::State& state) { PathAgainstBareEmbreeBySize(state, true); }
BENCHMARK(BM_PathAgainstBareEmbreeGlowingBySize)
    ->Arg(4)
    ->Arg(6)
    ->Arg(8)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(2.0);
// The same at 4 spp. A frame's set-up (the emitter table and the glow's
// copy, built once per frame because the glow changes) grows with the
// glowing triangles, not with the samples: at 1 spp it weighs as much as
// the frame's paths allow, at the fixture's own 64 spp a 64th of that. 4 spp
// (5.8 M rays at 1.3 M triangles) shows the paths' own rate at a ray log
// that still fits in memory.
void BM_PathAgainstBareEmbreeGlowingBySize4spp(benchmark::State& state) { PathAgainstBareEmbreeBySize(state, true, 4); }
BENCHMARK(BM_PathAgainstBareEmbreeGlowingBySize4spp)
    ->Arg(6)
    ->Arg(8)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(2.0);

// The noise and the time of choosing the glowing triangles by blocks, against
// one by one, on the glowing sphere after dark (its glow uneven: the LED lit
// it from one side). Each way renders 8 frames at 1 spp with seeds 1 to 8,
// alternated; a pixel's variance is estimated over its 8 values in each
// band. Counters also: `mean_difference_se`, the images' means' difference
// in standard errors, and each way's first frame (first_frame_ms_*).
void BM_GlowChoiceByBlocks(benchmark::State& state) {
  Cornell c(0.0, static_cast<int>(state.range(0)), /*glowing_sphere=*/true);
  c.solver->AdvanceTo(40);
  constexpr int kSeeds = 8;
  struct Way {
    std::size_t above;
    double variance = 0, mean = 0, seconds = 0;
  };
  // By blocks: the sphere alone (the walls, two triangles each, stay chosen one by one).
  const std::size_t sphere_triangles = c.scene.objects.back().mesh->triangles.size();
  Way ways[2] = {{sphere_triangles - 1}, {~std::size_t{0}}};  // by blocks, one by one
  FrameOptions options[2];
  std::vector<double> sum[2], sum2[2];
  for (int w = 0; w < 2; ++w) {
    options[w] = DefaultFrameOptions(c.scene, Transport::kPath);
    options[w].spp = 1;
    options[w].emitter_blocks_above_triangles = ways[w].above;
  }
  for (auto _ : state) {
    // A frame each way first, not counted: the blocks' tables are built
    // once for the geometry, at the first frame by blocks (first_frame_ms).
    for (int w = 0; w < 2; ++w) {
      const double start = Now();
      RenderBands(*c.geometry, c.solver.get(), options[w]);
      state.counters[w == 0 ? "first_frame_ms_blocks" : "first_frame_ms_one_by_one"] = (Now() - start) * 1e3;
    }
    for (int seed = 1; seed <= kSeeds; ++seed)
      for (int w = 0; w < 2; ++w) {  // alternated, so that the machine's noise hits both alike
        options[w].seed = static_cast<unsigned>(seed);
        const double start = Now();
        const Image image = RenderBands(*c.geometry, c.solver.get(), options[w]);
        ways[w].seconds += Now() - start;
        sum[w].resize(image.pixels.size(), 0.0);
        sum2[w].resize(image.pixels.size(), 0.0);
        for (std::size_t i = 0; i < image.pixels.size(); ++i) {
          sum[w][i] += image.pixels[i];
          sum2[w][i] += static_cast<double>(image.pixels[i]) * image.pixels[i];
        }
      }
    for (int w = 0; w < 2; ++w)
      for (std::size_t i = 0; i < sum[w].size(); ++i) {
        const double mean = sum[w][i] / kSeeds;
        ways[w].mean += mean;
        ways[w].variance += (sum2[w][i] - kSeeds * mean * mean) / (kSeeds - 1);
      }
  }
  state.counters["variance_ratio"] = ways[0].variance / ways[1].variance;
  state.counters["mean_ratio"] = ways[0].mean / ways[1].mean;
  // The means' difference in standard errors (pixels independent): within a
  // few for two unbiased estimates.
  state.counters["mean_difference_se"] =
      (ways[0].mean - ways[1].mean) / std::sqrt((ways[0].variance + ways[1].variance) / kSeeds);
  state.counters["time_ratio"] = ways[0].seconds / ways[1].seconds;
  state.counters["efficiency_ratio"] = (ways[1].variance * ways[1].seconds) / (ways[0].variance * ways[0].seconds);
}
BENCHMARK(BM_GlowChoiceByBlocks)->Arg(6)->Arg(8)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

// A frame of an animation at 30 fps while the LED is on: the coupled step for
// 1/30 s and the direct render, against the render alone of the same scene
// without phosphorescence (no solver). Alternated; best of each side.
void BM_PhosphorescenceOverhead(benchmark::State& state) {
  Cornell with;
  Cornell without;
  FrameOptions options = DefaultFrameOptions(with.scene, Transport::kDirect);
  double t = 1, best_with = 1e9, best_without = 1e9;
  with.solver->AdvanceTo(t);
  without.geometry->SetTime(t);
  for (auto _ : state) {
    double start = Now();
    with.solver->AdvanceTo(t += 1.0 / 30);
    Image a = RenderBands(*with.geometry, with.solver.get(), options);
    best_with = std::min(best_with, Now() - start);
    start = Now();
    Image b = RenderBands(*without.geometry, nullptr, options);
    best_without = std::min(best_without, Now() - start);
    benchmark::DoNotOptimize(a.pixels.data());
    benchmark::DoNotOptimize(b.pixels.data());
    if (t > kLightsOff - 1) t = 1;  // stay lit (the solver only moves forward: restart it)
    if (t == 1) {
      with.solver = std::make_unique<CoupledSolver>(with.scene, *with.geometry);
      with.solver->AdvanceTo(t);
    }
  }
  state.counters["with_ms"] = best_with * 1e3;
  state.counters["without_ms"] = best_without * 1e3;
  state.counters["ratio"] = best_with / best_without;
}
BENCHMARK(BM_PhosphorescenceOverhead)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(3.0);

// The textured-plane fixture at its own 640 x 480, textured and untextured
// (the same scene with the texture dropped: its factor, 1, as the albedo).
// Alternated; best of each side.
void BM_TexturedDirectFrame(benchmark::State& state) {
  Scene textured = LoadScene(state.range(0) == 0 ? PHOS_FIXTURES_DIR "/scenes/textured-plane.json"
                                                 : PHOS_FIXTURES_DIR "/scenes/glow-sign.json");
  textured.camera.width = 640;
  textured.camera.height = 480;
  Scene untextured = textured;
  for (Object& object : untextured.objects) {
    object.albedo_texture.reset();
    object.gloss_texture.reset();
  }
  const SceneGeometry textured_geometry(textured), untextured_geometry(untextured);
  const FrameOptions options = DefaultFrameOptions(textured, Transport::kDirect);
  RenderBands(textured_geometry, nullptr, options);  // the texture's first read and its mip levels: once per run
  double best_textured = 1e9, best_untextured = 1e9;
  for (auto _ : state) {
    double start = Now();
    Image a = RenderBands(textured_geometry, nullptr, options);
    best_textured = std::min(best_textured, Now() - start);
    start = Now();
    Image b = RenderBands(untextured_geometry, nullptr, options);
    best_untextured = std::min(best_untextured, Now() - start);
    benchmark::DoNotOptimize(a.pixels.data());
    benchmark::DoNotOptimize(b.pixels.data());
  }
  state.counters["textured_ms"] = best_textured * 1e3;
  state.counters["untextured_ms"] = best_untextured * 1e3;
  state.counters["ratio"] = best_textured / best_untextured;
}
BENCHMARK(BM_TexturedDirectFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(3.0);

// A frame (coupled step + direct render) 1 s and 3600 s after lights-out, each
// from a freshly charged state: both are one closed-form jump. Alternated.
void BM_FrameAfterLightsOut(benchmark::State& state) {
  Cornell c(state.range(0) * 1e-3);
  FrameOptions options = DefaultFrameOptions(c.scene, Transport::kDirect);
  double best_second = 1e9, best_hour = 1e9;
  for (auto _ : state) {
    for (double after : {1.0, 3600.0}) {
      c.solver = std::make_unique<CoupledSolver>(c.scene, *c.geometry);
      c.solver->AdvanceTo(kLightsOff);
      const double start = Now();
      c.solver->AdvanceTo(kLightsOff + after);
      Image image = RenderBands(*c.geometry, c.solver.get(), options);
      benchmark::DoNotOptimize(image.pixels.data());
      double& best = after == 1.0 ? best_second : best_hour;
      best = std::min(best, Now() - start);
    }
  }
  state.counters["texels"] = static_cast<double>(c.solver->stats().texels);
  state.counters["1s_ms"] = best_second * 1e3;
  state.counters["3600s_ms"] = best_hour * 1e3;
  state.counters["ratio"] = best_hour / best_second;
}
BENCHMARK(BM_FrameAfterLightsOut)->Arg(10)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

// Deep screen space, ambient occlusion of the Cornell box at 256 x 256:
// surfelize + G-buffer + hierarchical splat, against the exact gather it
// approximates (every surfel for every pixel). Arg: threads (the splat is a
// tile-owned gather: does it scale?).
void BM_DeepScreenSpaceAo(benchmark::State& state) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(state.range(0)));
  Scene scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/cornell-phosphor.json");
  scene.camera.width = scene.camera.height = 256;
  SceneGeometry geometry(scene);
  const CameraRays camera(scene, 0);
  std::size_t surfels = 0;
  std::uint64_t splats = 0;
  for (auto _ : state) {
    const auto cloud = Surfelize(geometry, camera.origin(), static_cast<float>(scene.camera.fov_deg), SurfelOptions{});
    const GBuffer g = RenderGBuffer(geometry, scene, 0);
    const DssResult r = SplatDeepScreenSpace(g, camera, cloud, {}, DssOptions{});
    surfels = cloud.size();
    splats = r.splats;
    benchmark::ClobberMemory();
  }
  state.counters["surfels"] = static_cast<double>(surfels);
  state.counters["splats"] = static_cast<double>(splats);
}
BENCHMARK(BM_DeepScreenSpaceAo)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ExactGatherAo(benchmark::State& state) {
  Scene scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/cornell-phosphor.json");
  scene.camera.width = scene.camera.height = 256;
  SceneGeometry geometry(scene);
  const CameraRays camera(scene, 0);
  const auto cloud = Surfelize(geometry, camera.origin(), static_cast<float>(scene.camera.fov_deg), SurfelOptions{});
  const GBuffer g = RenderGBuffer(geometry, scene, 0);
  const DssResult dss = SplatDeepScreenSpace(g, camera, cloud, {}, DssOptions{});
  for (auto _ : state) {
    const DssResult r = GatherAllSurfels(g, cloud, {}, 0);
    benchmark::ClobberMemory();
    state.counters["splats"] = static_cast<double>(r.splats);
    // How far deep screen space (defaults) lands from this exact gather.
    double error = 0;
    int n = 0;
    for (std::size_t p = 0; p < r.occlusion.size(); ++p)
      if (g.object[p] >= 0) error += std::fabs(r.occlusion[p] - dss.occlusion[p]), ++n;
    state.counters["dss_mean_abs_error"] = error / std::max(n, 1);
  }
}
BENCHMARK(BM_ExactGatherAo)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

// The bounced z-buffer on the same view as BM_DeepScreenSpaceAo (its cost
// against blending's, same surfels and levels).
void BM_BouncedZBufferAo(benchmark::State& state) {
  Scene scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/cornell-phosphor.json");
  scene.camera.width = scene.camera.height = 256;
  SceneGeometry geometry(scene);
  const CameraRays camera(scene, 0);
  for (auto _ : state) {
    const auto cloud = Surfelize(geometry, camera.origin(), static_cast<float>(scene.camera.fov_deg), SurfelOptions{});
    const GBuffer g = RenderGBuffer(geometry, scene, 0);
    const DssResult r = SplatBouncedZBuffer(g, camera, cloud, {}, DssOptions{});
    benchmark::ClobberMemory();
    state.counters["splats"] = static_cast<double>(r.splats);
  }
}
BENCHMARK(BM_BouncedZBufferAo)->Unit(benchmark::kMillisecond)->UseRealTime();

// Media: a frame of the dust-sheets fixture (Fig. 8.17) at 256 x 192 while a
// sheet sweeps the cloud (t = 1.5 s): the direct transport's ray march
// (single scattering of both sheets, the voxels' glow) and the solver's
// step to the next frame (0.5 s in 10 ms steps, 22 584 phosphor voxels).
void BM_DustSheetsFrame(benchmark::State& state) {
  const Scene scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/dust-sheets.json");
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(1.5);
  const FrameOptions options = DefaultFrameOptions(scene, Transport::kDirect);
  for (auto _ : state) {
    const Image image = RenderBands(geometry, &solver, options);
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_DustSheetsFrame)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_DustSheetsSolverHalfSecond(benchmark::State& state) {
  const Scene scene = LoadScene(PHOS_FIXTURES_DIR "/scenes/dust-sheets.json");
  SceneGeometry geometry(scene);
  double t = 0;
  auto solver = std::make_unique<CoupledSolver>(scene, geometry);
  for (auto _ : state) {
    if (t + 0.5 > 3.0) {  // stay inside the sweep
      state.PauseTiming();
      solver = std::make_unique<CoupledSolver>(scene, geometry);
      t = 0;
      state.ResumeTiming();
    }
    t += 0.5;
    solver->AdvanceTo(t);
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_DustSheetsSolverHalfSecond)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace phos::render

BENCHMARK_MAIN();
