#pragma once
// Colour science in one place: the CIE 1931 colour matching functions and
// the one XYZ -> linear sRGB matrix of the project. The renderer turns band
// radiance into sRGB through these.

#include <array>

namespace phos {

using Tristimulus = std::array<double, 3>;  // XYZ, or linear RGB

// CIE 1931 2-degree colour matching functions (xbar, ybar, zbar) at a
// wavelength: the multi-lobe fit of Wyman, Sloan and Shirley, "Simple
// Analytic Approximations to the CIE XYZ Color Matching Functions", JCGT
// 2(2), 2013, within a few percent of the CIE tables.
Tristimulus Cie1931Cmf(double wavelength_nm);
// Their mean over [lower_nm, upper_nm] (a radiance of uniform density inside
// a band), by the midpoint rule on max(8, width in nm) steps.
Tristimulus Cie1931CmfBandMean(double lower_nm, double upper_nm);

// XYZ to linear sRGB (IEC 61966-2-1, D65 white): the primaries' matrix.
// Inline, like the luminance below: they run per pixel.
inline Tristimulus XyzToLinearSrgb(const Tristimulus& xyz) {
  return {3.2404542 * xyz[0] - 1.5371385 * xyz[1] - 0.4985314 * xyz[2],
          -0.9692660 * xyz[0] + 1.8760108 * xyz[1] + 0.0415560 * xyz[2],
          0.0556434 * xyz[0] - 0.2040259 * xyz[1] + 1.0572252 * xyz[2]};
}
// Luminance of linear sRGB (ITU-R BT.709 coefficients, the Y row of the
// inverse of that matrix rounded to four digits).
inline double LinearSrgbLuminance(double r, double g, double b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

}  // namespace phos
