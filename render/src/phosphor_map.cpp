#include "phos/render/phosphor_map.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/imagebuf.h>

#include "phos/fit/decay_map_file.h"
#include "phos/model/closed_form.h"
#include "phos/model/schedule.h"
#include "phos/model/material.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos::render {
namespace {

// The channels of one state: its rate and its amplitude per camera channel.
struct StateChannels {
  int kr = -1;
  std::vector<int> amplitude;
};

// A pixel's place in the map's words: "pixel (x, y)".
struct MapPixel {
  int width = 0;
  std::size_t index = 0;
  std::string Name() const {
    return "pixel (" + std::to_string(index % static_cast<std::size_t>(width)) + ", " +
           std::to_string(index / static_cast<std::size_t>(width)) + ")";
  }
};

// A decaying pixel's numbers must stay in the ranges a material's do
// (model/material.h): a rate up to kMaxRate and finite amplitudes, or the
// products the renderer forms overflow (an amplitude of inf rendered NaN
// pixels; kr 1e30 was taken). A pixel that does not decay (kr NaN, 0 or
// negative) is left out as before, whatever its amplitudes.
void CheckMapPixel(const OIIO::ImageSpec& spec, const StateChannels& state, const float* px, float amplitude,
                   const MapPixel& pixel, const std::string& where, const std::string& field,
                   const std::string& named) {
  const float kr = px[state.kr];
  if (!(kr > 0)) return;  // no decay here (+inf decays, and is refused below)
  if (!(kr <= kMaxRate))
    ThrowUserError(where, field,
                   named + pixel.Name() + ": " + spec.channelnames[state.kr] + " " + FormatShort(kr) +
                       " /s is above the largest rate phos takes (" + FormatShort(kMaxRate) + " /s)");
  for (int c : state.amplitude)
    if (!std::isfinite(px[c]))
      ThrowUserError(where, field, named + pixel.Name() + ": " + spec.channelnames[c] + " is " + FormatShort(px[c]));
  if (!std::isfinite(amplitude))
    ThrowUserError(where, field, named + pixel.Name() + ": its amplitudes sum past the largest float");
}

// Channel indices by name (EXR keeps channels in its own order).
StateChannels FindStateChannels(const OIIO::ImageSpec& spec, const std::string& kr_name,
                                const std::string& amplitude_prefix) {
  StateChannels channels;
  for (int c = 0; c < spec.nchannels; ++c) {
    const std::string& name = spec.channelnames[c];
    if (name == kr_name) channels.kr = c;
    if (name.size() > amplitude_prefix.size() && name.compare(0, amplitude_prefix.size(), amplitude_prefix) == 0)
      channels.amplitude.push_back(c);
  }
  return channels;
}

}  // namespace

std::size_t PhosphorMap::PixelAt(float u, float v, bool v_up) const {
  const float t = v_up ? 1 - v : v;
  const int x = std::clamp(static_cast<int>(std::floor(u * static_cast<float>(width))), 0, width - 1);
  const int y = std::clamp(static_cast<int>(std::floor(t * static_cast<float>(height))), 0, height - 1);
  return static_cast<std::size_t>(y) * width + x;
}

PhosphorMap ReadPhosphorMap(const std::filesystem::path& file, const std::string& where, const std::string& field) {
  const std::string named = "map '" + file.string() + "' ";
  OIIO::ImageBuf image(file.string());
  if (!image.read(0, 0, /*force=*/true, OIIO::TypeDesc::FLOAT)) {
    std::string error = image.geterror();
    ThrowUserError(where, field, named + "is not an image OpenImageIO can read" + (error.empty() ? "" : ": " + error));
  }
  const OIIO::ImageSpec& spec = image.spec();
  if (spec.find_attribute(fit::kDecayMapFirstRow))
    ThrowUserError(where, field,
                   named + "is one tile of a map (phos fit map --tile): assemble it with phos fit map --merge");
  PhosphorMap map;
  map.file = file;
  map.width = spec.width;
  map.height = spec.height;
  std::vector<StateChannels> states = {FindStateChannels(spec, fit::kDecayMapKr, fit::kDecayMapAmplitude)};
  if (states[0].kr < 0 || states[0].amplitude.empty())
    ThrowUserError(where, field,
                   named + "has no 'kr' and 'amplitude.<channel>' channels: it is not a decay map of phos fit map");
  StateChannels second = FindStateChannels(spec, fit::kDecayMapKr2, fit::kDecayMapAmplitude2);
  if (second.kr >= 0) {
    if (second.amplitude.size() != states[0].amplitude.size())
      ThrowUserError(where, field, named + "has 'kr2' but not one 'amplitude2.<channel>' per 'amplitude.<channel>'");
    states.push_back(second);
  }
  map.states = static_cast<int>(states.size());

  std::vector<float> pixels(map.pixel_count() * spec.nchannels);
  image.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, pixels.data());
  const std::size_t n = map.pixel_count();
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  map.kr_per_s.assign(n * map.states, kNaN);
  map.amplitude_dn_per_s.assign(n * map.states, 0.0f);
  for (int i = 0; i < map.states; ++i)
    for (std::size_t p = 0; p < n; ++p) {
      const float* px = &pixels[p * spec.nchannels];
      float amplitude = 0;
      for (int c : states[i].amplitude) amplitude += px[c];
      const float kr = px[states[i].kr];
      CheckMapPixel(spec, states[i], px, amplitude, MapPixel{map.width, p}, where, field, named);
      // A state decays where its rate is a finite positive number and it
      // emitted something; the fast state of a two-state map only where the
      // slow one does too.
      const bool decays = std::isfinite(kr) && kr > 0 && amplitude > 0 && (i == 0 || map.Decays(p));
      if (!decays) continue;
      map.kr_per_s[i * n + p] = kr;
      map.amplitude_dn_per_s[i * n + p] = amplitude;
      if (i == 0) ++map.pixels_with_decay;
    }
  if (map.pixels_with_decay == 0)
    ThrowUserError(where, field, named + "has no pixel with a decay (a finite kr and an amplitude > 0)");
  const fit::DecayMapCharge charge = fit::DecayMapCharge::FromSpec(spec, where, field, named);
  map.charge_band_irradiance.assign(charge.band_irradiance.begin(), charge.band_irradiance.end());
  map.charge_s = charge.charge_s;
  return map;
}

void ApplyPhosphorMap(const PhosphorMap& map, const Material& material, const std::vector<std::uint32_t>& pixels,
                      BatchCoefficients<float>& c, const std::string& where) {
  PHOS_CHECK(material.state_count() == c.nc);
  // The scene's loader checks this too; a material swapped in later (--material, the editor) is checked here.
  if (c.nc != map.states)
    ThrowUserError(where, "phosphor_map",
                   "the map has " + std::to_string(map.states) + " state(s) and the material '" + material.name + "' " +
                       std::to_string(c.nc) + ": fit both with the same number (phos fit map --states)");
  // order[k]: the material's state with the k-th smallest kr, to take the map's state k.
  std::vector<int> order(static_cast<std::size_t>(c.nc));
  for (int i = 0; i < c.nc; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return c.kr[a] < c.kr[b]; });
  // a = sum_b ke_i[b] E_b under the session's charge light, per material state.
  std::vector<double> a(static_cast<std::size_t>(c.nc), 0.0);
  if (!map.charge_band_irradiance.empty()) {
    if (static_cast<int>(map.charge_band_irradiance.size()) != material.band_count())
      ThrowUserError(where, "phosphor_map",
                     "the map's charge has " + std::to_string(map.charge_band_irradiance.size()) +
                         " bands and the material " + std::to_string(material.band_count()));
    a = ExcitationRates(material, map.charge_band_irradiance, where + " charged as the map's session was");
  }
  const std::size_t n = pixels.size(), P = map.pixel_count();
  // The level the lab's charge left in a state of rate kr (Eq. 8.1 from 0); 1 without a recorded charge.
  auto level = [&](int i, double kr) {
    if (map.charge_band_irradiance.empty()) return 1.0;
    return ChargedState(a[i], kr, map.charge_s);
  };
  // Until the map says otherwise: the material's rates, and no glow.
  c.kr_per_point.resize(static_cast<std::size_t>(c.nc) * n);
  for (int i = 0; i < c.nc; ++i) std::fill_n(c.kr_per_point.begin() + static_cast<std::ptrdiff_t>(i * n), n, c.kr[i]);
  c.emission_scale.assign(c.kr_per_point.size(), 0.0f);
  for (int k = 0; k < c.nc; ++k) {
    const int i = order[k];
    if (!map.charge_band_irradiance.empty() && !(a[i] > 0))
      ThrowUserError(where, "phosphor_map",
                     "the map's charge light does not excite the material's state " + std::to_string(i) +
                         " (ke 0 where it shines): its levels cannot be told from its charge");
    // The map's typical pixel: the median of the glow at a full charge over the pixels where state k decays.
    std::vector<double> full;
    for (std::size_t p = 0; p < P; ++p) {
      const float kr = map.kr_per_s[k * P + p];
      if (kr == kr) full.push_back(map.amplitude_dn_per_s[k * P + p] / level(i, kr));
    }
    if (full.empty()) continue;  // the fast state suffices nowhere: it keeps emission 0 everywhere
    const auto middle = full.begin() + static_cast<std::ptrdiff_t>(full.size() / 2);
    std::nth_element(full.begin(), middle, full.end());
    const double median = *middle;
    for (std::size_t j = 0; j < n; ++j) {
      const float kr = map.kr_per_s[k * P + pixels[j]];
      if (kr != kr) continue;  // NaN: this state does not decay here
      c.kr_per_point[i * n + j] = kr;
      const double scale = map.amplitude_dn_per_s[k * P + pixels[j]] / level(i, kr) / median;
      // The scale multiplies the material's Lambda, so it is held to
      // Lambda's range (model/material.h, kMaxLambda): one pixel 3e38 times
      // the map's typical one rendered NaN.
      if (!(scale <= kMaxLambda))
        ThrowUserError(where, "phosphor_map",
                       MapPixel{map.width, pixels[j]}.Name() + " glows " + FormatShort(scale) +
                           " times the map's typical pixel (the median), above the " + FormatShort(kMaxLambda) +
                           " a material's Lambda may reach: not a decay map phos fit map writes");
      c.emission_scale[i * n + j] = static_cast<float>(scale);
    }
  }
}

}  // namespace phos::render
