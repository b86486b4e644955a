#pragma once
// Colour science in one place: the CIE 1931 colour matching functions, the
// one XYZ -> linear sRGB matrix of the project, CIELAB and the CIEDE2000
// colour difference. The renderer turns band radiance into sRGB through
// these; the appearance study (bench/appearance_study.cpp) judges fitted
// materials with them.

#include <array>
#include <vector>

namespace phos {

using Tristimulus = std::array<double, 3>;                  // XYZ, or linear RGB
using ColourMatrix = std::array<std::array<double, 3>, 3>;  // row-major: out[i] = sum_j m[i][j] in[j]

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

Tristimulus Apply(const ColourMatrix& m, const Tristimulus& v);

// The 3x3 matrix M minimizing sum_k |M from[k] - to[k]|^2 (linear least
// squares, by the normal equations): e.g. a camera's linear RGB of a set of
// spectra onto their CIE XYZ. Needs at least three linearly independent
// `from` vectors and as many `to` as `from`; throws std::invalid_argument
// otherwise.
ColourMatrix FitColourMatrix(const std::vector<Tristimulus>& from, const std::vector<Tristimulus>& to);

// The CIE D65 white (2-degree observer) with Y = 1, as sRGB uses it
// (IEC 61966-2-1; CIE 15:2004 gives x, y = 0.31272, 0.32903):
// XYZ = (0.95047, 1, 1.08883).
Tristimulus D65WhiteXyz();

struct Lab {
  double L = 0, a = 0, b = 0;
};

// CIE 1976 L*a*b* of XYZ against the reference white `white` (CIE 15:2004,
// Sec. 8.2.1), with its linear segment below (6/29)^3 so that dark colours
// stay finite.
Lab XyzToLab(const Tristimulus& xyz, const Tristimulus& white);

// The CIEDE2000 colour difference (CIE 142-2001) with parametric factors
// kL = kC = kH = 1, in the formulation and with the hue conventions of
// Sharma, Wu and Dalal, "The CIEDE2000 color-difference formula:
// implementation notes, supplementary test data, and mathematical
// observations", Color Res. Appl. 30(1):21-30, 2005 (their Eqs. 1-25).
// Symmetric; 0 for identical colours. About 1 is a just-noticeable difference.
double Ciede2000(const Lab& lab1, const Lab& lab2);

}  // namespace phos
