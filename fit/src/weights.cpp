#include <algorithm>
#include <cmath>

#include "phos/fit/curve.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

std::optional<Weighting> ParseWeighting(std::string_view name) {
  if (name == "none") return Weighting::kNone;
  if (name == "poisson") return Weighting::kPoisson;
  return std::nullopt;
}

const char* WeightingName(Weighting weighting) { return weighting == Weighting::kNone ? "none" : "poisson"; }

void ValidateCurve(const Curve& curve, std::size_t min_times, const std::string& where) {
  if (curve.channels.empty()) ThrowUserError(where, "", "no value column (expected t,value[,value...])");
  const std::size_t m = curve.t_s.size();
  if (m < min_times)
    ThrowUserError(where, "",
                   "has " + std::to_string(m) + " sample" + (m == 1 ? "" : "s") + "; this fit needs at least " +
                       std::to_string(min_times));
  std::size_t distinct = 0;
  for (std::size_t j = 0; j < m; ++j) {
    const double t = curve.t_s[j];
    if (!std::isfinite(t)) ThrowUserError(where, "t", "sample " + std::to_string(j + 1) + " is not finite");
    if (t < 0)
      ThrowUserError(where, "t",
                     "sample " + std::to_string(j + 1) + " is at a negative time (" + FormatDouble(t) +
                         " s); time counts from the start of the charge or the decay (keep t >= 0, e.g. "
                         "with --from 0)");
    if (j > 0 && t < curve.t_s[j - 1])
      ThrowUserError(where, "t",
                     "times must not decrease (" + FormatDouble(t) + " follows " + FormatDouble(curve.t_s[j - 1]) +
                         " at sample " + std::to_string(j + 1) + "): sort the samples by time first");
    distinct += j == 0 || t > curve.t_s[j - 1];
  }
  if (distinct < min_times)
    ThrowUserError(where, "t",
                   "has " + std::to_string(m) + " samples at only " + std::to_string(distinct) + " distinct time" +
                       (distinct == 1 ? "" : "s") + "; this fit needs at least " + std::to_string(min_times));
  for (std::size_t c = 0; c < curve.channels.size(); ++c) {
    const std::string name = c < curve.names.size() ? curve.names[c] : "channel " + std::to_string(c + 1);
    if (curve.channels[c].size() != m) ThrowUserError(where, name, "length differs from t");
    for (std::size_t j = 0; j < m; ++j)
      if (!std::isfinite(curve.channels[c][j]))
        ThrowUserError(where, name, "sample " + std::to_string(j + 1) + " is not finite");
  }
}

std::vector<double> SampleWeights(const std::vector<double>& values, Weighting weighting) {
  std::vector<double> w(values.size(), 1.0);
  if (weighting == Weighting::kNone) return w;
  double peak = 0;
  for (double v : values) peak = std::max(peak, std::fabs(v));
  const double floor = peak > 0 ? 1e-3 * peak : 1.0;
  for (std::size_t j = 0; j < values.size(); ++j) w[j] = 1.0 / std::sqrt(std::max(values[j], floor));
  return w;
}

}  // namespace phos
