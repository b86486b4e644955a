#pragma once
// The constants every part shares: one pi, in double and in float (the
// renderer works in float; a float literal of pi written by hand elsewhere
// differed in its last digits from one file to the next).

#include <numbers>

namespace phos {

inline constexpr double kPi = std::numbers::pi;
inline constexpr float kPiF = std::numbers::pi_v<float>;
// 1 / pi, for multiplying where a division would sit on a hot path (a
// division by the constant kPiF is not turned into a multiplication without
// -ffast-math).
inline constexpr float kInvPiF = std::numbers::inv_pi_v<float>;

}  // namespace phos
