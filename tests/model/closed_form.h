#pragma once
// Closed-form solutions of Eq. 8.1 in long double, independent of the code
// under test, and the comparison the model tests use.

#include <cmath>
#include <gtest/gtest.h>

namespace phos::testing {

// r(t) from r0 under constant a and kr: r0 e^{-kt} + r_inf (1 - e^{-kt}).
inline long double ClosedForm(long double r0, long double a, long double kr, long double t) {
  long double k = a + kr;
  if (k == 0) return r0;
  return r0 * std::exp(-k * t) + (a / k) * -std::expm1(-k * t);
}

// |value - expected| <= tolerance * |expected|; values below `floor` in
// magnitude (subnormal territory, where relative precision does not exist)
// are compared absolutely against floor.
inline ::testing::AssertionResult RelativelyNear(double value, long double expected, double tolerance,
                                                 double floor = 1e-290) {
  long double error = std::fabs(static_cast<long double>(value) - expected);
  long double allowed = std::max<long double>(tolerance * std::fabs(expected), floor);
  if (std::isfinite(value) && error <= allowed) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "value " << value << " expected " << static_cast<double>(expected)
                                       << " relative error " << static_cast<double>(error / std::fabs(expected));
}

}  // namespace phos::testing
