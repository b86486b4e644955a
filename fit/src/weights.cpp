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

void ValidateCurve(const Curve& curve, std::size_t min_points, const std::string& where) {
  if (curve.channels.empty()) ThrowUserError(where, "", "no value column (expected t,value[,value...])");
  const std::size_t m = curve.t_s.size();
  if (m < min_points)
    ThrowUserError(where, "", "has " + std::to_string(m) + " sample" + (m == 1 ? "" : "s") + "; this fit needs at least " +
                                  std::to_string(min_points));
  for (std::size_t j = 0; j < m; ++j) {
    if (!std::isfinite(curve.t_s[j])) ThrowUserError(where, "t", "sample " + std::to_string(j + 1) + " is not finite");
    if (j > 0 && !(curve.t_s[j] > curve.t_s[j - 1]))
      ThrowUserError(where, "t", "times must increase strictly (" + FormatDouble(curve.t_s[j]) + " follows " +
                                     FormatDouble(curve.t_s[j - 1]) + " at sample " + std::to_string(j + 1) + ")");
  }
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
