// Light transport against closed forms and against each other:
//  - a closed box with uniform glow and albedo rho: every pixel sees
//    Lp / (1 - rho) under the path tracer (the enclosure's radiosity) and Lp
//    under direct transport, on the paper's 8 bands and on other grids;
//  - an open plane under a point light: direct transport gives rho E / pi
//    exactly, and the path tracer (nothing to bounce off) must agree;
//  - image regression of the Cornell fixture against stored references with
//    statistical tolerances, writing difference images on failure
//    (PHOS_UPDATE_REFERENCES=1 rewrites the references).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "phos/render/geometry.h"
#include "phos/render/renderer.h"
#include "phos/render/solver.h"
#include "render/scene_util.h"
#include "test_util.h"

namespace phos::render {
namespace {

using phos::testing::EmptyScene;
using phos::testing::Fixture;
using phos::testing::MakeObject;
using phos::testing::PointLight;
using phos::testing::UniformPhosphor;

struct Mean {
  double mean = 0, standard_error = 0;
};
Mean ChannelMean(const Image& image, int channel) {
  double sum = 0, sum2 = 0;
  const std::size_t n = std::size_t(image.width) * image.height;
  for (std::size_t p = 0; p < n; ++p) {
    const double v = image.pixels[p * image.channels + channel];
    sum += v;
    sum2 += v * v;
  }
  const double mean = sum / n;
  return {mean, std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n)};
}

// Inside a closed enclosure of albedo rho whose walls all glow with Lp, the
// radiosity everywhere is Lp / (1 - rho): the phosphors of these tests emit
// Lp1 in bands 2 and 4, twice that in band 3, and nothing in band 0.
void ExpectEnclosureRadiosity(const Image& image, double Lp1, double albedo) {
  for (int band : {2, 3, 4}) {
    const Mean m = ChannelMean(image, band);
    const double expected = (band == 3 ? 2 : 1) * Lp1 / (1 - albedo);
    EXPECT_NEAR(m.mean, expected, 5 * m.standard_error + 1e-3 * expected) << "band " << band;
    EXPECT_LT(m.standard_error, 0.01 * expected);
  }
  EXPECT_EQ(ChannelMean(image, 0).mean, 0.0);
}

// The closed box on a grid of `band_count` equal bands over 400-700 nm, the
// phosphor emitting in bands 2 to 4 (twice in band 3). The path tracer's
// lanes have a size fixed at compile time on the paper's 8 bands and one
// set at run time on any other grid: both must give the enclosure's radiosity.
void ExpectClosedGlowingBoxIsLpOverOneMinusAlbedo(int band_count,
                                                   std::size_t emitter_blocks_above_triangles = FrameOptions{}.emitter_blocks_above_triangles) {
  const double albedo = 0.5, kr = 0.2, r0 = 0.5;
  Scene scene = EmptyScene(24, 24);
  scene.bands = SpectralGrid::Uniform(400.0, 700.0, band_count);
  std::vector<double> Lambda(band_count, 0.0);
  Lambda[2] = Lambda[4] = 1;
  Lambda[3] = 2;
  auto phosphor = UniformPhosphor(kr, std::vector<double>(band_count, 0.1), Lambda);
  phosphor->bands = scene.bands;
  scene.objects.push_back(MakeObject("box", MakeBox(Vec3(1, 1, 1), /*inward=*/true), albedo, phosphor));
  scene.objects[0].albedo.assign(band_count, albedo);  // MakeObject's is on the paper's 8 bands
  scene.objects[0].initial = {InitialState::Kind::kUniform, r0};
  scene.texel_size_m = 0.1;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  const double Lp3 = 2 * kr * r0;  // Eq. 8.2

  FrameOptions direct;
  const Image d = RenderBands(geometry, &solver, direct);
  ASSERT_EQ(d.channels, band_count);
  for (std::size_t p = 0; p < d.pixels.size() / band_count; ++p) {
    ASSERT_FLOAT_EQ(d.pixels[p * band_count + 3], static_cast<float>(Lp3));
    ASSERT_EQ(d.pixels[p * band_count + 0], 0.0f);
  }

  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 64;
  path.max_depth = 200;  // rho^200: no truncation bias; Russian roulette ends paths
  path.emitter_blocks_above_triangles = emitter_blocks_above_triangles;
  const Image image = RenderBands(geometry, &solver, path);
  ExpectEnclosureRadiosity(image, kr * r0, albedo);
  EXPECT_EQ(ChannelMean(image, band_count - 1).mean, 0.0);
}

TEST(Transport, ClosedGlowingBoxIsLpOverOneMinusAlbedo) { ExpectClosedGlowingBoxIsLpOverOneMinusAlbedo(8); }

// The box's 12 triangles chosen by blocks (one block of 256 columns, 12 of
// them weighing: the rest padding, never chosen).
TEST(Transport, ClosedGlowingBoxIsLpOverOneMinusAlbedoWithItsTrianglesChosenByBlocks) {
  ExpectClosedGlowingBoxIsLpOverOneMinusAlbedo(8, 0);
}

TEST(Transport, ClosedGlowingBoxIsLpOverOneMinusAlbedoOnAnyBandGrid) {
  for (int band_count : {6, 13}) {
    SCOPED_TRACE(std::to_string(band_count) + " bands");
    ExpectClosedGlowingBoxIsLpOverOneMinusAlbedo(band_count);
  }
}

// The same enclosure as a glowing icosphere of 20 x 4^6 = 81,920 triangles,
// seen from inside: the path tracer's emitter table (72 bytes a triangle,
// 5.9 MB) outgrows a core's cache and 2 MiB, so it is built in parallel on
// huge-page storage and its alias columns are fetched ahead by peeking at
// each lane's stream (transport_path.cpp). None of that may change the
// answer, Lp / (1 - rho).
TEST(Transport, ClosedGlowingLargeMeshIsLpOverOneMinusAlbedo) {
  const double albedo = 0.5, kr = 0.2, r0 = 0.5;
  Scene scene = EmptyScene(24, 24);
  scene.camera.keys = {{0, Vec3(0, 0, 0.3), Vec3(0, 0, -1)}};
  scene.objects.push_back(MakeObject("sphere", MakeSphere(1.0, 6, /*inward=*/true), albedo,
                                     UniformPhosphor(kr, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0})));
  ASSERT_EQ(scene.objects[0].mesh->triangles.size(), 81920u);
  scene.objects[0].initial = {InitialState::Kind::kUniform, r0};
  scene.texel_size_m = 0.1;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 64;
  path.max_depth = 200;
  const Image image = RenderBands(geometry, &solver, path);
  ExpectEnclosureRadiosity(image, kr * r0, albedo);
}

// A sphere's inside is the one enclosure with a closed form for any glow:
// each surface element sees each other in proportion to its area (form
// factor dA / A), so the radiosity is B(x) = Le(x) + rho mean_A(Le) /
// (1 - rho). Here only the half x > 0 glows, in proportion to x (the glow
// set texel by texel through a solver state), so the emitter table's
// triangles differ in power, within its blocks and across them, and the
// dark half's pixels must show rho mean_A(Le) / (1 - rho). Next-event
// estimation that chose triangles by another distribution than the pdf it
// divides by would miss that; a uniform glow (the test above) cannot tell.
// At 81,920 triangles (s = 6) the path tracer chooses triangles one by one
// from an alias table of one block; at 327,680 (s = 7), more than
// FrameOptions::emitter_blocks_above_triangles, by blocks of 256 triangles
// (a block by its power, then a triangle of it by its area), whose glow
// here differs within a block and from block to block. Each size is also
// rendered the other way: all are unbiased.
void ExpectSphereGlowingUnevenlyShowsTheMeanGlowOnItsDarkHalf(int subdivisions,
                                                              std::size_t emitter_blocks_above_triangles,
                                                              bool split = false) {
  const double albedo = 0.5, kr = 0.2, r0 = 0.5;
  Scene scene = EmptyScene(24, 24);
  scene.camera.keys = {{0, Vec3(0, 0, 0.3), Vec3(0, 0, -1)}};
  const Mesh whole = MakeSphere(1.0, subdivisions, /*inward=*/true);
  auto phosphor = UniformPhosphor(kr, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0});
  if (!split) {
    scene.objects.push_back(MakeObject("sphere", whole, albedo, phosphor));
  } else {  // the same sphere as two objects: its cap x > 0.6, and the rest
    Mesh cap = whole, rest = whole;
    cap.triangles.clear();
    rest.triangles.clear();
    for (const Eigen::Vector3i& t : whole.triangles)
      (whole.positions[t[0]].x() + whole.positions[t[1]].x() + whole.positions[t[2]].x() > 1.8f ? cap : rest)
          .triangles.push_back(t);
    EXPECT_LT(cap.triangles.size(), 30000u);  // one by one in the test below
    EXPECT_GT(rest.triangles.size(), 30000u);  // by blocks
    scene.objects.push_back(MakeObject("cap", cap, albedo, phosphor));
    scene.objects.push_back(MakeObject("rest", rest, albedo, phosphor));
  }
  for (Object& object : scene.objects) object.initial = {InitialState::Kind::kUniform, r0};
  scene.texel_size_m = 0.1;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  SolverCheckpoint state = solver.Checkpoint(0);
  double glow_area = 0, area = 0;  // the integral of the glow's scale over the sphere, and its area
  for (std::size_t slot = 0; slot < solver.atlas().objects().size(); ++slot) {
    const TexelAtlas::ObjectTexels& texels = solver.atlas().objects()[slot];
    const int object = texels.object;
    ASSERT_FALSE(texels.uv());
    std::vector<float>& Lp = state.arrays[2 * slot + 1];  // [emission band][texel]
    ASSERT_EQ(Lp.size() % texels.count, 0u);
    const std::size_t emission_bands = Lp.size() / texels.count;
    for (int t = 0; t < geometry.triangle_count(object); ++t) {
      const float x =
          (geometry.Vertex(object, t, 0) + geometry.Vertex(object, t, 1) + geometry.Vertex(object, t, 2)).x() / 3;
      const float scale = std::max(0.0f, x);
      glow_area += scale * geometry.Area(object, t);
      area += geometry.Area(object, t);
      const std::size_t texel_count = std::size_t{texels.m[t]} * texels.m[t];
      for (std::size_t e = 0; e < emission_bands; ++e)
        for (std::size_t k = texels.first[t]; k < texels.first[t] + texel_count; ++k) Lp[e * texels.count + k] *= scale;
    }
  }
  EXPECT_NEAR(glow_area / area, 0.25, 0.01);  // the mean of max(0, x) over a unit sphere
  solver.Restore(state, "test");
  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 64;
  path.max_depth = 200;
  path.emitter_blocks_above_triangles = emitter_blocks_above_triangles;
  const Image image = RenderBands(geometry, &solver, path);
  // The camera looks down -z from x = 0: its columns left of centre see x < 0.
  for (int band : {2, 3, 4}) {
    double sum = 0, sum2 = 0;
    int n = 0;
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < 10; ++x, ++n) {
        const double v = image.at(x, y)[band];
        sum += v;
        sum2 += v * v;
      }
    const double mean = sum / n, standard_error = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n);
    const double expected = albedo / (1 - albedo) * (band == 3 ? 2 : 1) * kr * r0 * glow_area / area;
    EXPECT_NEAR(mean, expected, 5 * standard_error + 2e-3 * expected) << "band " << band;
    EXPECT_LT(standard_error, 0.02 * expected) << "band " << band;
  }
}
TEST(Transport, SphereGlowingUnevenlyShowsTheMeanGlowOnItsDarkHalf) {
  const std::size_t by_default = FrameOptions{}.emitter_blocks_above_triangles;
  for (int subdivisions : {6, 7}) {
    const std::size_t triangles = std::size_t{20} << (2 * subdivisions);
    for (std::size_t above : {by_default, triangles > by_default ? SIZE_MAX : std::size_t{0}}) {
      SCOPED_TRACE(std::to_string(triangles) + " triangles, " + (triangles > above ? "by blocks" : "one by one"));
      ExpectSphereGlowingUnevenlyShowsTheMeanGlowOnItsDarkHalf(subdivisions, above);
    }
  }
}

// The same sphere as two objects, its cap (x > 0.6: a fifth of it, the
// brightest) and the rest, the rest's triangles chosen by blocks and the
// cap's one by one, in one table over the blocks and the cap's triangles.
TEST(Transport, SphereGlowingUnevenlyInTwoPartsChosenTwoWaysShowsTheMeanGlow) {
  ExpectSphereGlowingUnevenlyShowsTheMeanGlowOnItsDarkHalf(6, 30000, /*split=*/true);
}

TEST(Transport, OpenPlaneDirectIsAlbedoTimesIrradianceOverPiAndPathAgrees) {
  const double albedo = 0.6, intensity = 0.8, height = 1.0;
  Scene scene = EmptyScene(32, 32);
  scene.camera.keys = {{0, Vec3(0, 2, 0.001), Vec3(0, 0, 0)}};
  scene.camera.fov_deg = 20;
  scene.objects.push_back(MakeObject("plane", MakeQuad(4, 4), albedo));
  scene.lights.push_back(PointLight(Vec3(0, height, 0), std::vector<double>(8, intensity)));
  SceneGeometry geometry(scene);
  FrameOptions direct;
  const Image d = RenderBands(geometry, nullptr, direct);
  // Analytic value at every pixel: find where its (centre) ray meets y = 0.
  const double tan_half = std::tan(10.0 * M_PI / 180);
  for (int y = 0; y < 32; y += 3) {
    for (int x = 0; x < 32; x += 3) {
      const Eigen::Vector3d forward = (Vec3(0, 0, 0) - Vec3(0, 2, 0.001)).normalized();
      const Eigen::Vector3d right = forward.cross(Vec3(0, 1, 0)).normalized(), up = right.cross(forward);
      const double sx = (2 * (x + 0.5) / 32 - 1) * tan_half, sy = (1 - 2 * (y + 0.5) / 32) * tan_half;
      const Eigen::Vector3d dir = (forward + sx * right + sy * up).normalized();
      const Eigen::Vector3d p = Vec3(0, 2, 0.001) + dir * (-2.0 / dir.y());
      const Eigen::Vector3d to_light = Vec3(0, height, 0) - p;
      const double E = intensity * (height / to_light.norm()) / to_light.squaredNorm();
      EXPECT_NEAR(d.at(x, y)[5], albedo * E / M_PI, 2e-5 * albedo * E / M_PI) << x << "," << y;
    }
  }
  FrameOptions path;
  path.transport = Transport::kPath;
  path.spp = 4;
  const Image pt = RenderBands(geometry, nullptr, path);
  const Mean m_direct = ChannelMean(d, 5), m_path = ChannelMean(pt, 5);
  EXPECT_NEAR(m_path.mean, m_direct.mean, 0.01 * m_direct.mean);  // only pixel jitter differs
}

// A glowing disk 1 m above a grey floor, its state set (no light), seen
// from below: its front facing down; or facing up, one- or two-sided. A
// two-sided sheet seen and sampled from its back must be the first case
// exactly (direct: the glow the camera sees) and within noise (path: the
// floor lit by next-event estimation toward its back and by paths that hit
// it); one-sided and facing away, it neither shows a glow nor lights the
// floor, so the comparison can fail.
Image GlowingDiskOverAFloor(bool faces_down, bool two_sided, Transport transport) {
  Scene scene = EmptyScene(48, 48);
  scene.camera.keys = {{0, Vec3(0, 0.4, 2.5), Vec3(0, 0.3, 0)}};
  scene.texel_size_m = 0.1;
  scene.objects.push_back(MakeObject("floor", MakeQuad(4, 4), 0.5));
  render::Mesh disk = phos::testing::DiskFacingDown(0.5f, 1.0f, 24);
  if (!faces_down)
    for (auto& triangle : disk.triangles) std::swap(triangle[1], triangle[2]);
  scene.objects.push_back(
      MakeObject("sheet", disk, 0.5, UniformPhosphor(0.2, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0})));
  scene.objects[1].initial = {InitialState::Kind::kUniform, 0.5};
  scene.objects[1].two_sided = two_sided;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  FrameOptions options;
  options.transport = transport;
  options.spp = 32;
  return RenderBands(geometry, &solver, options);
}

TEST(Transport, ATwoSidedSheetGlowsAndLightsFromItsBackAsOthersFromTheirFront) {
  const Image front = GlowingDiskOverAFloor(true, false, Transport::kDirect);
  const Image back = GlowingDiskOverAFloor(false, true, Transport::kDirect);
  const Image away = GlowingDiskOverAFloor(false, false, Transport::kDirect);
  ASSERT_GT(ChannelMean(front, 3).mean, 0);
  for (std::size_t i = 0; i < front.pixels.size(); ++i) ASSERT_FLOAT_EQ(back.pixels[i], front.pixels[i]) << i;
  EXPECT_EQ(ChannelMean(away, 3).mean, 0.0);  // one-sided, seen from its back: no glow, and nothing lit

  const Image front_path = GlowingDiskOverAFloor(true, false, Transport::kPath);
  const Image back_path = GlowingDiskOverAFloor(false, true, Transport::kPath);
  const Image away_path = GlowingDiskOverAFloor(false, false, Transport::kPath);
  // The floor's share: the path image less the glow the camera sees directly.
  auto floor_light = [&](const Image& path, const Image& direct) {
    double sum = 0;
    for (std::size_t p = 0; p < path.pixels.size() / 8; ++p) sum += path.pixels[p * 8 + 3] - direct.pixels[p * 8 + 3];
    return sum / static_cast<double>(path.pixels.size() / 8);
  };
  const double lit_by_front = floor_light(front_path, front), lit_by_back = floor_light(back_path, back);
  ASSERT_GT(lit_by_front, 0);
  EXPECT_NEAR(lit_by_back, lit_by_front, 0.02 * lit_by_front);
  EXPECT_LT(floor_light(away_path, away), 0.05 * lit_by_front);  // the floor sees the dark back only
}

// Deep screen space: a two-sided sheet's back sends its glow to the floor as
// the front-facing sheet's front does (a twin surfel per surfel); a
// one-sided sheet facing away sends nothing there.
TEST(Transport, DeepScreenSpaceBouncesATwoSidedSheetsGlowFromItsBack) {
  const Image front = GlowingDiskOverAFloor(true, false, Transport::kDss);
  const Image back = GlowingDiskOverAFloor(false, true, Transport::kDss);
  const Image away = GlowingDiskOverAFloor(false, false, Transport::kDss);
  const Image front_direct = GlowingDiskOverAFloor(true, false, Transport::kDirect);
  auto bounce = [&](const Image& dss) {
    double sum = 0;
    for (std::size_t p = 0; p < dss.pixels.size() / 8; ++p) sum += dss.pixels[p * 8 + 3] - front_direct.pixels[p * 8 + 3];
    return sum;
  };
  ASSERT_GT(bounce(front), 0);
  EXPECT_NEAR(bounce(back), bounce(front), 1e-3 * bounce(front));
  EXPECT_LT(bounce(away), 0.05 * bounce(front));
}

// Glow on glow (phosphor_irradiance): a glowing disk over a phosphor floor;
// the floor turned over (its front facing down, away from the disk)
// receives nothing, unless it is two-sided: then as much as facing up.
double FloorGlowIrradiance(bool floor_faces_up, bool floor_two_sided) {
  Scene scene = EmptyScene(8, 8);
  scene.settings.phosphor_irradiance = true;
  scene.texel_size_m = 0.25;
  render::Mesh floor = MakeQuad(2, 2);
  if (!floor_faces_up)
    for (auto& triangle : floor.triangles) std::swap(triangle[1], triangle[2]);
  scene.objects.push_back(
      MakeObject("floor", floor, 0.5, UniformPhosphor(0.2, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0})));
  scene.objects[0].two_sided = floor_two_sided;
  scene.objects.push_back(MakeObject("disk", phos::testing::DiskFacingDown(0.5f, 1.0f, 24), 0.5,
                                     UniformPhosphor(0.2, std::vector<double>(8, 0.1), {0, 0, 1, 2, 1, 0, 0, 0})));
  scene.objects[1].initial = {InitialState::Kind::kUniform, 0.5};
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  double sum = 0;
  for (std::size_t k = 0; k < solver.atlas().objects()[0].count; ++k) sum += solver.TexelGlowIrradiance(0, k)[3];
  return sum;
}

TEST(Transport, GlowOnGlowChargesATwoSidedSheetFromItsBack) {
  const double up = FloorGlowIrradiance(true, false);
  ASSERT_GT(up, 0);
  EXPECT_EQ(FloorGlowIrradiance(false, false), 0.0);
  EXPECT_NEAR(FloorGlowIrradiance(false, true), up, 1e-4 * up);
}

// Compares with a stored reference in blocks; writes the difference on failure.
void ExpectMatchesReference(const Image& image, const std::string& name, double block_tolerance) {
  const std::filesystem::path reference_path = Fixture("render/" + name + ".exr");
  if (std::getenv("PHOS_UPDATE_REFERENCES")) {
    std::filesystem::create_directories(reference_path.parent_path());
    WriteExr(reference_path, BandsToLinearSrgb(image, SpectralGrid::Paper()), image, SpectralGrid::Paper());
    GTEST_SKIP() << "wrote " << reference_path;
  }
  const Image stored = ReadImage(reference_path);
  ASSERT_EQ(stored.width, image.width);
  ASSERT_EQ(stored.channels, 3 + image.channels);
  // Luminance-like sum over bands, compared per 8x8 block against the reference's noise-free scale.
  const int block = 8;
  double worst = 0, total_ref = 0, total = 0;
  Image difference(image.width, image.height, 1);
  for (int by = 0; by < image.height; by += block) {
    for (int bx = 0; bx < image.width; bx += block) {
      double sum = 0, sum_ref = 0;
      for (int y = by; y < by + block; ++y)
        for (int x = bx; x < bx + block; ++x)
          for (int b = 0; b < image.channels; ++b) {
            sum += image.at(x, y)[b];
            sum_ref += stored.at(x, y)[3 + b];
            difference.at(x, y)[0] += image.at(x, y)[b] - stored.at(x, y)[3 + b];
          }
      total += sum;
      total_ref += sum_ref;
      worst = std::max(worst, std::abs(sum - sum_ref));
    }
  }
  const double mean_block = total_ref / ((image.width / block) * (image.height / block));
  const bool ok =
      worst <= block_tolerance * mean_block && std::abs(total - total_ref) <= 0.25 * block_tolerance * total_ref;
  if (!ok) {
    const std::filesystem::path out = std::filesystem::current_path() / ("render-regression-" + name + "-diff.exr");
    Image rgb(difference.width, difference.height, 3);
    for (std::size_t p = 0; p < difference.pixels.size(); ++p)
      for (int c = 0; c < 3; ++c) rgb.pixels[3 * p + c] = difference.pixels[p];
    WriteExr(out, rgb, difference, SpectralGrid::Uniform(400, 700, 1));
    ADD_FAILURE() << name << ": worst 8x8 block differs by " << worst / mean_block << " of a mean block (tolerance "
                  << block_tolerance << "), totals " << total << " vs " << total_ref << "; difference image: " << out;
  }
}

Image RenderCornell(Transport transport, double t_s, unsigned seed,
                    std::size_t emitter_blocks_above_triangles = FrameOptions{}.emitter_blocks_above_triangles) {
  Scene scene = LoadScene(Fixture("scenes/cornell-phosphor.json"));
  scene.camera.width = scene.camera.height = 64;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(t_s);
  FrameOptions options = DefaultFrameOptions(scene, transport);
  options.spp = 64;
  options.seed = seed;
  options.emitter_blocks_above_triangles = emitter_blocks_above_triangles;
  return RenderBands(geometry, &solver, options);
}

TEST(Regression, CornellDirectWhileLitAndAfterLightsOut) {
  // Direct transport is deterministic up to float rounding across thread orders.
  ExpectMatchesReference(RenderCornell(Transport::kDirect, 20, 1), "cornell-direct-t20", 1e-3);
  ExpectMatchesReference(RenderCornell(Transport::kDirect, 40, 1), "cornell-direct-t40", 1e-3);
}

TEST(Regression, CornellPathTracedAfterLightsOutWithinNoise) {
  // A different seed from the reference's: only the noise differs. 64 spp over
  // an 8x8 block is 4096 paths per block; blocks stay within 15%.
  ExpectMatchesReference(RenderCornell(Transport::kPath, 40, std::getenv("PHOS_UPDATE_REFERENCES") ? 1 : 2),
                         "cornell-path-t40", 0.15);
}

// The same with the walls' glowing triangles chosen by blocks (each wall a
// block of its own, its two triangles' glow uneven): only the noise may differ.
TEST(Regression, CornellPathTracedAfterLightsOutWithTheGlowChosenByBlocksWithinNoise) {
  ExpectMatchesReference(RenderCornell(Transport::kPath, 40, 2, 0), "cornell-path-t40", 0.15);
}

// A frame's image is not zeroed first (Image::ForOverwrite): every
// transport must set every pixel. Rendered into the storage of a bright
// frame just freed (a block of 2 MiB, 256 x 256 x 8 bands, kept for the
// next of its size, large_table.h), a frame with the lights off and no
// phosphorescence must be exactly black: a pixel a transport skipped would
// show the bright frame.
// The box after dark with a glowing sphere of 1280 triangles in it (painted
// with the back wall's phosphor, lit by the LED from one side), its
// triangles chosen by blocks and the walls' one by one, in one table: the
// frame must be the one all chosen one by one gives, but for noise (8 x 8
// blocks of 64 spp within 15% of a mean block, as the reference's, and the
// totals within 5 standard errors).
TEST(Transport, AGlowingMeshByBlocksAmongWallsOneByOneGivesTheSameFrame) {
  Scene scene = LoadScene(Fixture("scenes/cornell-phosphor.json"));
  scene.camera.width = scene.camera.height = 64;
  Mesh sphere = MakeSphere(0.1, 3, /*inward=*/false);  // large, so that its glow weighs in the frame
  for (Eigen::Vector3f& p : sphere.positions) p += Eigen::Vector3f(0.4f, 0.3f, 0.12f);  // beside the LED
  Object ball = scene.objects[2];  // the back wall: green phosphor
  ball.name = "ball";
  ball.mesh = std::make_shared<Mesh>(std::move(sphere));
  scene.objects.push_back(std::move(ball));
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(40);
  Image frames[2];
  for (int way = 0; way < 2; ++way) {
    FrameOptions options = DefaultFrameOptions(scene, Transport::kPath);
    options.spp = 64;
    options.seed = 3 + way;
    options.emitter_blocks_above_triangles = way == 0 ? 1000 : SIZE_MAX;  // the sphere by blocks; none
    frames[way] = RenderBands(geometry, &solver, options);
  }
  const int block = 8, nb = frames[0].channels;
  double total[2] = {0, 0}, worst = 0, variance = 0;
  for (int by = 0; by < 64; by += block)
    for (int bx = 0; bx < 64; bx += block) {
      double sum[2] = {0, 0};
      for (int y = by; y < by + block; ++y)
        for (int x = bx; x < bx + block; ++x)
          for (int way = 0; way < 2; ++way)
            for (int b = 0; b < nb; ++b) sum[way] += frames[way].at(x, y)[b];
      worst = std::max(worst, std::abs(sum[0] - sum[1]));
      for (int way = 0; way < 2; ++way) total[way] += sum[way];
      variance += (sum[0] - sum[1]) * (sum[0] - sum[1]) / 2;  // each block's sum's variance, estimated by the pair
    }
  const double mean_block = total[1] / 64;
  EXPECT_GT(mean_block, 0);
  EXPECT_LE(worst, 0.15 * mean_block);
  EXPECT_LE(std::abs(total[0] - total[1]), 5 * std::sqrt(2 * variance));
}

TEST(Transport, EveryTransportSetsEveryPixelOfItsFrame) {
  Scene scene = LoadScene(Fixture("scenes/cornell-phosphor.json"));
  scene.camera.width = scene.camera.height = 256;
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  for (Transport transport : {Transport::kDirect, Transport::kPath, Transport::kDss}) {
    FrameOptions options = DefaultFrameOptions(scene, transport);
    options.spp = 1;
    geometry.SetTime(20);  // the LED on
    const float* storage = nullptr;
    {
      const Image lit = RenderBands(geometry, nullptr, options);
      double sum = 0;
      for (float v : lit.pixels) sum += v;
      ASSERT_GT(sum, 0.0);
      storage = lit.pixels.data();
    }
    geometry.SetTime(40);  // the LED off since 30 s, and no glow: black
    const Image dark = RenderBands(geometry, nullptr, options);
    EXPECT_EQ(dark.pixels.data(), storage) << "not the lit frame's storage: this test would prove nothing";
    std::size_t set = 0;
    for (float v : dark.pixels) set += v == 0.0f;
    EXPECT_EQ(set, dark.pixels.size()) << static_cast<int>(transport);
  }
}

// Deep screen space adds the one bounce direct transport lacks: after
// lights-out the glowing walls light the white blocks. Against the stored
// path-traced reference (the truth up to its noise), the dss frame must be
// far closer than the direct one.
TEST(Transport, DeepScreenSpaceBringsTheGlowsBounceCloseToThePathTracer) {
  const Image reference = ReadImage(Fixture("render/cornell-path-t40.exr"));
  const Image direct = RenderCornell(Transport::kDirect, 40, 1);
  const Image dss = RenderCornell(Transport::kDss, 40, 1);
  auto rms = [&](const Image& image) {
    double e = 0;
    std::size_t n = 0;
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < image.width; ++x)
        for (int b = 0; b < image.channels; ++b, ++n) e += std::pow(image.at(x, y)[b] - reference.at(x, y)[3 + b], 2);
    return std::sqrt(e / n);
  };
  ASSERT_EQ(reference.channels, 3 + dss.channels);  // R, G, B, then the bands
  EXPECT_LT(rms(dss), 0.5 * rms(direct)) << "dss " << rms(dss) << ", direct " << rms(direct);
  // And it only adds light: never less than direct.
  for (std::size_t i = 0; i < dss.pixels.size(); ++i) EXPECT_GE(dss.pixels[i], direct.pixels[i] - 1e-7f);
}

TEST(Transport, ChoosingForABudgetOrAQuality) {
  // Synthetic costs: the choice depends only on them and the expected qualities.
  std::vector<TransportCandidate> c(4);
  c[0].label = "direct", c[0].estimated_s = 0.01, c[0].expected_ssim = 0.44;
  c[1].label = "dss", c[1].estimated_s = 0.05, c[1].expected_ssim = 0.90;
  c[2].label = "path 16 spp", c[2].estimated_s = 0.2, c[2].expected_ssim = 0.80;
  c[3].label = "path 64 spp", c[3].estimated_s = 0.8, c[3].expected_ssim = 0.93;
  EXPECT_EQ(ChooseTransport(c, 0.001, 0).chosen.label, "direct");
  EXPECT_FALSE(ChooseTransport(c, 0.001, 0).fits);
  EXPECT_EQ(ChooseTransport(c, 0.03, 0).chosen.label, "direct");
  EXPECT_EQ(ChooseTransport(c, 0.5, 0).chosen.label, "dss");  // path 16 fits too but looks worse
  EXPECT_EQ(ChooseTransport(c, 1.0, 0).chosen.label, "path 64 spp");
  EXPECT_EQ(ChooseTransport(c, 0, 0.85).chosen.label, "dss");  // the cheapest of >= 0.85
  EXPECT_EQ(ChooseTransport(c, 0, 0.92).chosen.label, "path 64 spp");
  const TransportChoice unreachable = ChooseTransport(c, 0, 0.99);
  EXPECT_FALSE(unreachable.fits);
  EXPECT_EQ(unreachable.chosen.label, "path 64 spp");  // the best there is
  // If dss became slower than the path tracer at 64 spp, a quality of 0.85 takes the path tracer.
  c[1].estimated_s = 2.0;
  EXPECT_EQ(ChooseTransport(c, 0, 0.85).chosen.label, "path 64 spp");
}

}  // namespace
}  // namespace phos::render
