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
  // Non-decreasing for the fits (SortByTime orders a file's samples); equal
  // times are replicates: several aliquots measured at the same time or dose.
  std::vector<double> t_s;
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

// Checks that a curve can be fitted at all: finite, non-negative,
// non-decreasing times (the fits count time from the start of the charge or
// the decay; e^{-kt} of a negative time overflows at the rates they scan), at
// least `min_times` distinct ones, finite values, channels of equal length.
// Problems are UserErrors naming `where`.
void ValidateCurve(const Curve& curve, std::size_t min_times, const std::string& where);

// What SortByTime found: whether it had to move samples, and how many times
// carry replicates (occur more than once).
struct TimeOrder {
  bool reordered = false;
  std::size_t samples = 0, distinct_times = 0, repeated_times = 0;
};
// Orders the samples by time, stably (replicates keep the file's order).
// Non-finite times are UserErrors naming `where` (they cannot be ordered).
TimeOrder SortByTime(Curve* curve, const std::string& where);

// The time unit a curve table's time column names, as seconds per unit: a
// word of its header ("time_min", "t (ms)", "Time [hours]") that is a unit
// of time: s, sec, second(s); ms, msec, millisecond(s); us, microsecond(s);
// min, minute(s); h, hr, hour(s); d, day(s). None: no unit word (read as
// seconds). Two different units in one name are a UserError naming `where`.
struct TimeUnit {
  double seconds = 1;
  std::string name;  // as written
};
std::optional<TimeUnit> TimeUnitOfColumn(std::string_view column, const std::string& where);

// Keeps the samples with from_s <= t <= to_s.
void KeepTimeWindow(Curve* curve, double from_s, double to_s);

// The smallest step between consecutive distinct times of a sorted curve
// (replicates are not a step), or 0 if all times are equal: the fastest rate
// the samples resolve is a few per step.
double SmallestTimeStep(const Curve& curve);

// When a sorted curve first rises clearly and then falls (a charge followed
// by its decay, fed to a decay fit), the time of its peak; otherwise none.
// "Clearly": the mean of the channels' sum over a run of samples (a
// twentieth of them, at least 3) climbs above the first run's by more than
// 5 standard errors of such a mean (noise from the median step between
// neighbours) and by more than 2% of the peak.
std::optional<double> PeakAfterRise(const Curve& curve);

// The units a fit solves in. A curve's values may be radiances of 1e-9
// W/(sr m^2) or counts of 1e5 DN, its times milliseconds or hours: every
// fit divides the times by `time_s` and the values by `value` before it
// solves, so that rates, amplitudes, residuals and weights are of order 1
// there whatever the data's units, and so are the solvers' absolute
// tolerances, floors and initial trust regions. The results are multiplied
// back (rates by 1 / time_s, levels by value, squared residuals by value^2):
// a fit of the curve in other units is the same fit, its parameters in
// those units.
struct CurveScale {
  double time_s = 1;      // the span of the times (last - first)
  double value = 1;       // the largest |value| of any channel (1 if all are 0)
  double exposure_s = 1;  // the longest exposure (1 without exposures)
};
// Of a curve that passed ValidateCurve. Values too small to keep their
// precision when divided (largest |value| a subnormal double, below 2.2e-308)
// and times that span less than that are UserErrors naming `where`.
CurveScale ScaleOfCurve(const Curve& curve, const std::string& where);
// The curve in those units: times / time_s, values / value, exposures /
// exposure_s.
Curve ScaledCurve(const Curve& curve, const CurveScale& scale);

// Per-sample weights of one channel (1 for kNone). For kPoisson the floor is
// 1e-3 of the channel's largest |value| (so a zero or slightly negative
// sample, which photon noise makes common at the end of a decay, does not get
// an infinite weight).
std::vector<double> SampleWeights(const std::vector<double>& values, Weighting weighting);

}  // namespace phos
