#include "relative_covariance.h"

#include <cmath>
#include <limits>

#include <Eigen/Dense>

#include "phos/fit/small_nnls.h"

namespace phos {

RelativeCovariance ComputeRelativeCovariance(ceres::Problem& problem, const std::vector<CovarianceBlock>& blocks,
                                             double chi2) {
  RelativeCovariance result;
  for (const CovarianceBlock& block : blocks)
    result.stderr_per_block.emplace_back(static_cast<std::size_t>(block.size), 0.0);
  ceres::Problem::EvaluateOptions evaluate;
  std::vector<double> scale;
  std::vector<std::pair<int, int>> where;  // column -> (block, index)
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    evaluate.parameter_blocks.push_back(blocks[b].values);
    for (int i = 0; i < blocks[b].size; ++i) {
      scale.push_back(i < blocks[b].relative ? blocks[b].values[i] : 1.0);
      where.emplace_back(static_cast<int>(b), i);
    }
  }
  ceres::CRSMatrix crs;
  if (!problem.Evaluate(evaluate, nullptr, nullptr, nullptr, &crs)) return result;
  // Columns kept: every parameter not at its bound 0.
  std::vector<int> index(scale.size(), -1), kept;
  for (std::size_t c = 0; c < scale.size(); ++c)
    if (scale[c] != 0) {
      index[c] = static_cast<int>(kept.size());
      kept.push_back(static_cast<int>(c));
    }
  if (kept.empty() || kept.size() > 64) return result;
  // J'J accumulated row by row (J has a row per sample: thousands).
  const Eigen::Index n = static_cast<Eigen::Index>(kept.size());
  BoundedMatrix normal = BoundedMatrix::Zero(n, n);
  for (int r = 0; r < crs.num_rows; ++r)
    for (int p = crs.rows[r]; p < crs.rows[r + 1]; ++p) {
      const int i = index[crs.cols[p]];
      if (i < 0) continue;
      const double u = crs.values[p] * scale[crs.cols[p]];
      for (int q = crs.rows[r]; q < crs.rows[r + 1]; ++q) {
        const int j = index[crs.cols[q]];
        if (j >= 0) normal(i, j) += u * crs.values[q] * scale[crs.cols[q]];
      }
    }
  const Eigen::SelfAdjointEigenSolver<BoundedMatrix> eigen(normal);
  const auto& lambda = eigen.eigenvalues();  // ascending
  if (!(lambda(n - 1) > 0)) return result;
  result.condition_number =
      lambda(0) > 0 ? std::sqrt(lambda(n - 1) / lambda(0)) : std::numeric_limits<double>::infinity();
  // A direction 1e-14 below the largest is numerically null: no inverse.
  if (!(lambda(0) > 1e-14 * lambda(n - 1))) return result;
  const BoundedMatrix inverse =
      eigen.eigenvectors() * lambda.cwiseInverse().asDiagonal() * eigen.eigenvectors().transpose();
  for (Eigen::Index k = 0; k < n; ++k) {
    const auto [b, i] = where[kept[k]];
    result.stderr_per_block[b][i] = std::fabs(scale[kept[k]]) * std::sqrt(std::max(0.0, inverse(k, k) * chi2));
  }
  result.ok = true;
  return result;
}

}  // namespace phos
