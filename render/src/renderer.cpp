#include "phos/render/renderer.h"

#include <algorithm>
#include <bit>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "phos/model/photometry.h"
#include "phos/model/schedule.h"
#include "phos/render/transport_quality.h"
#include "phos/render/volume.h"
#include "phos/util/atomic_file.h"
#include "phos/util/colour.h"
#include "phos/util/error.h"
#include "phos/util/image_file.h"
#include "phos/util/format.h"
#include "phos/util/math.h"
#include "phos/util/progress.h"
#include "shading.h"
#include "transport.h"

namespace phos::render {

Transport ParseTransport(const std::string& name) {
  if (name == "direct") return Transport::kDirect;
  if (name == "path") return Transport::kPath;
  if (name == "dss") return Transport::kDss;
  ThrowUserError("--transport", "", "unknown transport '" + name + "' (direct, path, dss)");
}

const char* TransportName(Transport transport) {
  return transport == Transport::kPath ? "path" : transport == Transport::kDss ? "dss" : "direct";
}

FrameOptions DefaultFrameOptions(const Scene& scene, Transport transport) {
  FrameOptions options;
  options.transport = transport;
  options.spp = scene.settings.spp;
  options.direct_spp = scene.settings.direct_spp;
  options.max_depth = scene.settings.max_depth;
  options.seed = scene.settings.seed;
  return options;
}

Image RenderBands(const SceneGeometry& geometry, const CoupledSolver* solver, const FrameOptions& options,
                  FrameStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  const Scene& scene = geometry.scene();
  const int nb = scene.bands.band_count();
  if (nb > kMaxBands) ThrowUserError(scene.source, "bands_nm", "more than " + std::to_string(kMaxBands) + " bands");
  const int width = scene.camera.width, height = scene.camera.height;
  Image image = Image::ForOverwrite(width, height, nb);  // every row sets each of its pixels
  // The media: the solver's (with the phosphorescent voxels' states), or this frame's own.
  std::unique_ptr<VolumeMedia> own_media;
  VolumeMedia* media = solver ? solver->media() : nullptr;
  if (!media && !scene.volumes.empty()) {
    own_media = std::make_unique<VolumeMedia>(scene, geometry);
    media = own_media.get();
  }
  if (media) media->PrepareLighting(geometry.time_s());
  const Shading shading(geometry, solver, media, options);
  const CameraRays camera(scene, geometry.time_s());
  const std::unique_ptr<FrameTransport> transport =
      options.transport == Transport::kPath  ? MakePathTransport(shading, camera)
      : options.transport == Transport::kDss ? MakeDssTransport(shading, camera)
                                             : MakeDirectTransport(shading, camera);
  if (stats) stats->setup_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::atomic<std::uint64_t> total_rays{0};
  tbb::parallel_for(0, height, [&](int y) {
    std::uint64_t rays = 0;
    transport->RenderRow(y, image, rays);
    total_rays += rays;
    if (options.progress_rows) options.progress_rows->Advance();
  });
  total_rays += transport->Finish(image);
  if (stats) stats->rays = total_rays.load();
  return image;
}

std::vector<TransportCandidate> MeasureTransportCandidates(const SceneGeometry& geometry, const CoupledSolver* solver,
                                                           const FrameOptions& base) {
  auto time_of = [&](const FrameOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    RenderBands(geometry, solver, options);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  const TransportQuality& quality = MeasuredTransportQuality();
  std::vector<TransportCandidate> candidates;
  FrameOptions direct = base;
  direct.transport = Transport::kDirect;
  direct.direct_spp = 1;
  candidates.push_back({direct, quality.direct_ssim, time_of(direct), "direct"});
  FrameOptions dss = direct;
  dss.transport = Transport::kDss;
  candidates.push_back({dss, quality.dss_ssim, time_of(dss), "dss"});
  FrameOptions path = base;
  path.transport = Transport::kPath;
  path.spp = 1;
  const double path_1spp_s = time_of(path);
  for (int spp : {4, 16, 64, 256, 1024}) {
    path.spp = spp;
    candidates.push_back({path, quality.PathSsim(spp), path_1spp_s * spp, "path " + std::to_string(spp) + " spp"});
  }
  return candidates;
}

TransportChoice ChooseTransport(std::vector<TransportCandidate> candidates, double budget_s, double min_ssim) {
  PHOS_CHECK(!candidates.empty());
  TransportChoice choice;
  choice.candidates = candidates;
  const TransportCandidate* best = nullptr;
  if (budget_s > 0) {
    for (const TransportCandidate& c : candidates)
      if (c.estimated_s <= budget_s && (!best || c.expected_ssim > best->expected_ssim)) best = &c;
    if (!best) {  // nothing fits: the fastest
      choice.fits = false;
      for (const TransportCandidate& c : candidates)
        if (!best || c.estimated_s < best->estimated_s) best = &c;
    }
  } else {
    for (const TransportCandidate& c : candidates)
      if (c.expected_ssim >= min_ssim && (!best || c.estimated_s < best->estimated_s)) best = &c;
    if (!best) {  // nothing is that good: the best there is
      choice.fits = false;
      for (const TransportCandidate& c : candidates)
        if (!best || c.expected_ssim > best->expected_ssim) best = &c;
    }
  }
  choice.chosen = *best;
  return choice;
}

std::vector<double> BandToXyzWeights(const SpectralGrid& grid) {
  const int nb = grid.band_count();
  std::vector<double> w(3 * static_cast<std::size_t>(nb), 0.0);
  double y_total = 0;
  for (int b = 0; b < nb; ++b) {
    // Band averages of the matching functions (radiance is uniform inside a band).
    const Tristimulus mean = Cie1931CmfBandMean(grid.lower_nm(b), grid.upper_nm(b));
    for (int c = 0; c < 3; ++c) w[c * nb + b] = mean[c];
    y_total += w[nb + b];
  }
  for (double& v : w) v /= y_total;
  return w;
}

namespace {

// pixel(p) for every pixel p in [0, count), in parallel by blocks of
// pixels: the per-pixel passes over a whole frame (its colour, its tone
// map, its EXR's channels), each a sizeable share of a large frame's time
// on one thread.
template <typename PerPixel>
void ForEachPixel(std::size_t count, const PerPixel& pixel) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 16384), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t p = r.begin(); p < r.end(); ++p) pixel(p);
  });
}

}  // namespace

Image BandsToLinearSrgb(const Image& bands, const SpectralGrid& grid) {
  const int nb = grid.band_count();
  PHOS_CHECK(bands.channels == nb);
  const std::vector<double> w = BandToXyzWeights(grid);
  // In parallel: on one thread it cost a 1920 x 1080 frame two thirds of
  // its direct render (perf, phos render --width 1920).
  Image rgb = Image::ForOverwrite(bands.width, bands.height, 3);  // each pixel set below
  ForEachPixel(std::size_t(bands.width) * bands.height, [&](std::size_t p) {
    Tristimulus xyz = {0, 0, 0};
    for (int c = 0; c < 3; ++c)
      for (int b = 0; b < nb; ++b) xyz[c] += w[c * nb + b] * bands.pixels[p * nb + b];
    const Tristimulus linear = XyzToLinearSrgb(xyz);
    for (int c = 0; c < 3; ++c) rgb.pixels[3 * p + c] = static_cast<float>(linear[c]);
  });
  return rgb;
}

void WriteExr(const std::filesystem::path& path, const Image& rgb, const Image& bands, const SpectralGrid& grid,
              const std::string& compression, Units units) {
  const int nb = bands.channels;
  const bool physical = units == Units::kPhysical;
  const int channels = 3 + nb + (physical ? 1 : 0);
  const std::vector<double> efficacy = physical ? PhotopicBandEfficacy(grid) : std::vector<double>();
  OIIO::ImageSpec spec(rgb.width, rgb.height, channels, OIIO::TypeDesc::FLOAT);
  spec.channelnames = {"R", "G", "B"};
  for (int b = 0; b < nb; ++b) spec.channelnames.push_back("band" + std::to_string(b));
  if (physical) {
    spec.channelnames.push_back("Y");
    spec.attribute("phos:units", "physical");
  }
  spec.attribute("compression", compression);
  std::string edges;
  for (double e : grid.edges_nm) {
    if (!edges.empty()) edges += ',';
    edges += FormatDouble(e);
  }
  spec.attribute("phos:bands_nm", edges);
  // Interleaved in parallel into a table not zeroed first (each value is written).
  LargeTable<float> data;
  data.resize(std::size_t(rgb.width) * rgb.height * channels);
  ForEachPixel(std::size_t(rgb.width) * rgb.height, [&](std::size_t p) {
    std::copy_n(&rgb.pixels[3 * p], 3, &data[p * channels]);
    std::copy_n(&bands.pixels[p * nb], nb, &data[p * channels + 3]);
    if (!physical) return;
    double luminance_cd_m2 = 0;  // Y = sum_b w_b L_b (photometry.h)
    for (int b = 0; b < nb; ++b) luminance_cd_m2 += efficacy[b] * bands.pixels[p * nb + b];
    data[p * channels + 3 + nb] = static_cast<float>(luminance_cd_m2);
  });
  WriteImageAtomically(path, spec, OIIO::TypeDesc::FLOAT, data.data());
}

Image ToneMap(const Image& rgb, double exposure) {
  PHOS_CHECK(rgb.channels == 3);
  Image display = Image::ForOverwrite(rgb.width, rgb.height, 3);  // each pixel set below
  ForEachPixel(rgb.pixels.size() / 3, [&](std::size_t p) {
    // Reinhard's global operator on luminance (Reinhard et al. 2002): a glow
    // a hundred times dimmer than the lit scene stays visible, and lit
    // highlights roll off instead of clipping. Hue is kept.
    const float* c = &rgb.pixels[3 * p];
    const double Y = std::max(0.0, exposure * LinearSrgbLuminance(c[0], c[1], c[2]));
    const double scale = exposure / (1 + Y);
    for (int k = 0; k < 3; ++k) {
      const double v = std::clamp(c[k] * scale, 0.0, 1.0);
      display.pixels[3 * p + k] = static_cast<float>(v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055);
    }
  });
  return display;
}

namespace {

void WriteDisplayPng(const std::filesystem::path& path, const Image& display) {
  std::vector<std::uint8_t> data(display.pixels.size());
  for (std::size_t i = 0; i < data.size(); ++i)
    data[i] = static_cast<std::uint8_t>(std::lround(std::clamp(display.pixels[i], 0.0f, 1.0f) * 255));
  OIIO::ImageSpec spec(display.width, display.height, display.channels, OIIO::TypeDesc::UINT8);
  WriteImageAtomically(path, spec, OIIO::TypeDesc::UINT8, data.data());
}

}  // namespace

void WritePng(const std::filesystem::path& path, const Image& rgb, double exposure) {
  WriteDisplayPng(path, ToneMap(rgb, exposure));
}

void WriteContactSheet(const std::filesystem::path& path, const std::vector<Image>& frames,
                       const std::vector<std::string>& labels, int columns) {
  PHOS_CHECK(!frames.empty() && labels.size() == frames.size() && columns > 0);
  const int pad = 4, label_height = 22;
  const int w = frames[0].width, h = frames[0].height;
  columns = std::min<int>(columns, static_cast<int>(frames.size()));
  const int rows = (static_cast<int>(frames.size()) + columns - 1) / columns;
  const int cell_w = w + pad, cell_h = h + label_height + pad;
  OIIO::ImageBuf sheet(OIIO::ImageSpec(columns * cell_w + pad, rows * cell_h + pad, 3, OIIO::TypeDesc::FLOAT));
  const float background[3] = {0.12f, 0.12f, 0.12f};
  OIIO::ImageBufAlgo::fill(sheet, background);
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const int x0 = pad + static_cast<int>(f % columns) * cell_w, y0 = pad + static_cast<int>(f / columns) * cell_h;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) sheet.setpixel(x0 + x, y0 + label_height + y, frames[f].at(x, y), 3);
    // Labels need a font file; without one the sheet is still written.
    const float white[3] = {0.9f, 0.9f, 0.9f};
    OIIO::ImageBufAlgo::render_text(sheet, x0 + 2, y0 + 16, labels[f], 15,
                                    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", white);
  }
  Image display(sheet.spec().width, sheet.spec().height, 3);
  sheet.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, display.pixels.data());
  WriteDisplayPng(path, display);
}

std::string ChargingSources(const Scene& scene, int band) {
  const auto ever_on = [](const LightSchedule& schedule) {
    return schedule.keys.empty() || std::any_of(schedule.keys.begin(), schedule.keys.end(),
                                                [](const LightSchedule::Key& k) { return k.level > 0; });
  };
  std::vector<std::string> sources;
  for (const Light& light : scene.lights) {
    if (!ever_on(light.schedule) || !(light.E_per_band[band] > 0)) continue;
    const char* value = light.positional() ? "intensity" : light.area() ? "radiance" : "irradiance";
    sources.push_back("light '" + light.name + "' (" + value + " " + FormatShort(light.E_per_band[band]) +
                      " in that band)");
  }
  if (scene.environment && ever_on(scene.environment->schedule) && scene.environment->L_per_band[band] > 0)
    sources.push_back("the sky (radiance " + FormatShort(scene.environment->L_per_band[band]) + " in that band)");
  bool glows = false;
  for (const Object& object : scene.objects)
    if (object.phosphor)
      for (const ExcitedState& state : object.phosphor->states) glows = glows || state.Lambda[band] > 0;
  if (scene.settings.phosphor_irradiance && glows) sources.push_back("the glow of the scene's phosphors");
  return JoinComma(sources);
}

void RequireKnownKe(const Scene& scene, const Material& material, const std::vector<int>& excitation_bands,
                    const std::string& where) {
  std::vector<double> probe(static_cast<std::size_t>(material.band_count()), 0.0);
  for (int band : excitation_bands) probe[static_cast<std::size_t>(band)] = 1.0;
  ExcitationRates(material, probe, where, kUnknownKeRemedy, [&](int band) { return ChargingSources(scene, band); });
}

Image ReadImage(const std::filesystem::path& path) {
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) ThrowUserError(path.string(), "", "cannot read the image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  Image image(spec.width, spec.height, spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, image.pixels.data()))
    ThrowUserError(path.string(), "", "cannot read the image: " + in->geterror());
  return image;
}

Image ReadImageChannels(const std::filesystem::path& path, const std::vector<std::string>& names) {
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) ThrowUserError(path.string(), "", "cannot read the image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  std::vector<int> source;
  for (const std::string& name : names) {
    const int c = spec.channelindex(name);
    if (c < 0) ThrowUserError(path.string(), "", "the image has no channel '" + name + "'");
    source.push_back(c);
  }
  Image all(spec.width, spec.height, spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, all.pixels.data()))
    ThrowUserError(path.string(), "", "cannot read the image: " + in->geterror());
  Image image(spec.width, spec.height, static_cast<int>(names.size()));
  const std::size_t n = names.size(), pixels = std::size_t(spec.width) * spec.height;
  for (std::size_t p = 0; p < pixels; ++p)
    for (std::size_t k = 0; k < n; ++k) image.pixels[p * n + k] = all.pixels[p * spec.nchannels + source[k]];
  return image;
}

}  // namespace phos::render
