#pragma once
// A measured curve: samples in time, one or more channels (camera colours,
// bands) sharing the time axis. The input of the decay and charge fits, from
// `phos fit decay-curve` CSVs or from sessions.

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace phos {

struct Curve {
  std::vector<double> t_s;                    // strictly increasing
  std::vector<std::vector<double>> channels;  // channels[c][j], same length as t_s
  std::vector<std::string> names;             // one per channel (for reports)
  // Optional, per sample: how long each value integrated (a frame's
  // exposure), when values are rates (counts / exposure). A rate's photon
  // noise variance is value / exposure, so Poisson weights grow with
  // sqrt(exposure): a 0.05 s frame must not count as much as a 3 s one.
  std::vector<double> exposure_s = {};

  std::size_t size() const { return t_s.size(); }
  int channel_count() const { return static_cast<int>(channels.size()); }
};

// How residuals are weighted. The reported rss is always the plain sum of
// squared residuals in the data's units, whatever the weighting.
enum class Weighting {
  kNone,     // every sample counts the same
  kPoisson,  // photon counting: variance proportional to the signal, weight 1/sqrt(max(y, floor))
};
std::optional<Weighting> ParseWeighting(std::string_view name);
const char* WeightingName(Weighting weighting);

// Checks that a curve can be fitted at all: at least `min_points` samples,
// strictly increasing finite times, finite values, channels of equal length.
// Problems are UserErrors naming `where`.
void ValidateCurve(const Curve& curve, std::size_t min_points, const std::string& where);

// Per-sample weights of one channel (1 for kNone). For kPoisson the floor is
// 1e-3 of the channel's largest |value| (so a zero or slightly negative
// sample, which photon noise makes common at the end of a decay, does not get
// an infinite weight).
std::vector<double> SampleWeights(const std::vector<double>& values, Weighting weighting);

}  // namespace phos
