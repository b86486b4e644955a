// Preparing measured curves for the fits: order, windows, steps.

#include <algorithm>
#include <cmath>
#include <cctype>
#include <limits>
#include <numeric>
#include <string>

#include "phos/fit/curve.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {
namespace {

template <typename T>
std::vector<T> Permuted(const std::vector<T>& values, const std::vector<std::size_t>& index) {
  std::vector<T> out;
  out.reserve(index.size());
  for (std::size_t j : index) out.push_back(values[j]);
  return out;
}

// Keeps the samples index names, in that order, in every per-sample vector
// (one of another length than t is left for ValidateCurve to name).
void Select(Curve* curve, const std::vector<std::size_t>& index) {
  const std::size_t m = curve->t_s.size();
  curve->t_s = Permuted(curve->t_s, index);
  for (auto& channel : curve->channels)
    if (channel.size() == m) channel = Permuted(channel, index);
  if (curve->exposure_s.size() == m) curve->exposure_s = Permuted(curve->exposure_s, index);
}

}  // namespace

TimeOrder SortByTime(Curve* curve, const std::string& where) {
  const std::vector<double>& t = curve->t_s;
  for (std::size_t j = 0; j < t.size(); ++j)
    if (!std::isfinite(t[j])) ThrowUserError(where, "t", "sample " + std::to_string(j + 1) + " is not finite");
  TimeOrder order;
  order.samples = t.size();
  order.reordered = !std::is_sorted(t.begin(), t.end());
  if (order.reordered) {
    std::vector<std::size_t> index(t.size());
    std::iota(index.begin(), index.end(), 0);
    std::stable_sort(index.begin(), index.end(), [&](std::size_t a, std::size_t b) { return t[a] < t[b]; });
    Select(curve, index);
  }
  for (std::size_t j = 0; j < t.size();) {
    std::size_t end = j + 1;
    while (end < t.size() && t[end] == t[j]) ++end;
    ++order.distinct_times;
    order.repeated_times += end - j > 1;
    j = end;
  }
  return order;
}

std::optional<TimeUnit> TimeUnitOfColumn(std::string_view column, const std::string& where) {
  struct Unit {
    const char* word;
    double seconds;
  };
  static constexpr Unit kUnits[] = {
      {"s", 1},          {"sec", 1},        {"secs", 1},       {"second", 1},     {"seconds", 1},
      {"ms", 1e-3},      {"msec", 1e-3},    {"millisecond", 1e-3}, {"milliseconds", 1e-3},
      {"us", 1e-6},      {"microsecond", 1e-6}, {"microseconds", 1e-6},
      {"min", 60},       {"mins", 60},      {"minute", 60},    {"minutes", 60},
      {"h", 3600},       {"hr", 3600},      {"hrs", 3600},     {"hour", 3600},    {"hours", 3600},
      {"d", 86400},      {"day", 86400},    {"days", 86400},
  };
  std::optional<TimeUnit> found;
  std::size_t i = 0;
  while (i < column.size()) {
    // Words: runs of letters (so "t_min", "t(ms)", "time/h" and "t [s]" split alike).
    while (i < column.size() && !std::isalpha(static_cast<unsigned char>(column[i]))) ++i;
    const std::size_t begin = i;
    while (i < column.size() && std::isalpha(static_cast<unsigned char>(column[i]))) ++i;
    std::string word(column.substr(begin, i - begin));
    std::transform(word.begin(), word.end(), word.begin(), [](unsigned char c) { return std::tolower(c); });
    for (const Unit& unit : kUnits) {
      if (word != unit.word) continue;
      if (found && found->seconds != unit.seconds)
        ThrowUserError(where, std::string(column),
                       "names two units of time ('" + found->name + "' and '" + word + "'); give one");
      found = TimeUnit{unit.seconds, word};
    }
  }
  return found;
}

void KeepTimeWindow(Curve* curve, double from_s, double to_s) {
  std::vector<std::size_t> kept;
  for (std::size_t j = 0; j < curve->t_s.size(); ++j)
    if (curve->t_s[j] >= from_s && curve->t_s[j] <= to_s) kept.push_back(j);
  Select(curve, kept);
}

CurveScale ScaleOfCurve(const Curve& curve, const std::string& where) {
  CurveScale scale;
  double largest = 0;
  for (const auto& channel : curve.channels)
    for (double v : channel) largest = std::max(largest, std::fabs(v));
  // Divided by a subnormal, values keep only the bits it has (none at
  // 4.9e-324): the fit would see garbage. All zeros stay for the fits to name.
  constexpr double kSmallestNormal = std::numeric_limits<double>::min();
  if (largest > 0 && largest < kSmallestNormal)
    ThrowUserError(where, "",
                   "every |value| is at most " + FormatDouble(largest) + ", below " + FormatShort(kSmallestNormal, 2) +
                       " (the smallest normal double), too small to fit with precision: give the values in a "
                       "smaller unit");
  if (largest > 0) scale.value = largest;
  scale.time_s = curve.t_s.back() - curve.t_s.front();
  if (!(scale.time_s >= kSmallestNormal))
    ThrowUserError(where, "t",
                   "the times span " + FormatDouble(scale.time_s) +
                       " s, too short to fit with precision: give the times in a smaller unit");
  double longest = 0;
  for (double e : curve.exposure_s) longest = std::max(longest, e);
  if (longest > 0) scale.exposure_s = longest;
  return scale;
}

Curve ScaledCurve(const Curve& curve, const CurveScale& scale) {
  Curve scaled = curve;
  for (double& t : scaled.t_s) t /= scale.time_s;
  for (auto& channel : scaled.channels)
    for (double& v : channel) v /= scale.value;
  for (double& e : scaled.exposure_s) e /= scale.exposure_s;
  return scaled;
}

double SmallestTimeStep(const Curve& curve) {
  double step = 0;
  for (std::size_t j = 1; j < curve.t_s.size(); ++j) {
    const double dt = curve.t_s[j] - curve.t_s[j - 1];
    if (dt > 0 && (step == 0 || dt < step)) step = dt;
  }
  return step;
}

std::optional<double> PeakAfterRise(const Curve& curve) {
  const std::size_t m = curve.t_s.size();
  std::vector<double> total(m, 0.0);
  for (const auto& channel : curve.channels)
    for (std::size_t j = 0; j < m && j < channel.size(); ++j) total[j] += channel[j];
  const std::size_t run = std::max<std::size_t>(3, m / 20);
  if (m < 2 * run) return std::nullopt;
  std::vector<double> steps;
  for (std::size_t j = 1; j < m; ++j) steps.push_back(std::fabs(total[j] - total[j - 1]));
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  // The median |difference| of two independent Gaussian samples is 0.954 sigma.
  const double sigma = steps[steps.size() / 2] / 0.954;
  double sum = 0;
  for (std::size_t j = 0; j < run; ++j) sum += total[j];
  const double first = sum / run;
  double peak = first;
  std::size_t peak_start = 0;
  for (std::size_t i = 1; i + run <= m; ++i) {
    sum += total[i + run - 1] - total[i - 1];
    if (sum / run > peak) {
      peak = sum / run;
      peak_start = i;
    }
  }
  const bool falls_after = peak_start + run < m;
  if (!falls_after || !(peak - first > 5 * sigma * std::sqrt(2.0 / run)) || !(peak - first > 0.02 * std::fabs(peak)))
    return std::nullopt;
  const auto highest = std::max_element(total.begin() + peak_start, total.begin() + peak_start + run);
  return curve.t_s[highest - total.begin()];
}

}  // namespace phos
