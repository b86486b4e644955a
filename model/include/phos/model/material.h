#pragma once
// A phosphorescent material (Sec. 8.3, Eq. 8.1-8.2) and its file format
// `phos.material/1` (docs/formats.md, "Material").
//
// Per excited state i (nc = 1..kMaxStates of them):
//   kr      decay rate, 1/s
//   ke[b]   excitation rate per unit band-integrated irradiance E[b], 1/s per
//           unit irradiance; a value may be unknown (JSON null) when it was
//           never measured (Table 8.1 has ke only for bands 1-3, and none for
//           bottle, gloves, stickers). Unknown is not zero: a material whose
//           ke is unknown in a band refuses to be charged there.
//   Lambda[b] emitted radiance per unit kr*r (the re-radiation function)
//   kr_stderr, ke_stderr[b]  optional 1-sigma uncertainties of a fitted
//           material (`phos fit session` writes them); readers that do not
//           know them still load the file, and nothing in the model uses them
// Albedo (diffuse reflectance per band) is optional: Table 8.1 does not give it.
//
// Units (docs/formats.md, "Units"): a material is relative (the default,
// Table 8.1's normalized irradiance and radiance) or physical: ke in 1/s per
// W/m² of band-integrated irradiance, Lambda in W/(sr m²) of band-integrated
// radiance per 1/s of kr r, so that Eq. 8.2's Lp[b] is in W/(sr m²) and its
// luminance in cd/m² (photometry.h).

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "phos/model/spectral.h"

namespace phos {

inline constexpr int kMaxStates = 16;
// The finite ranges a material file's values must lie in (docs/fuzzing.md,
// "Limits"), so that every product the model forms (ke E, kr r, Lambda kr r,
// e^{-kr t}) stays finite, in float as in double: kr and every ke in
// [0, kMaxRate] (1/s, and 1/s per unit irradiance), Lambda in
// [0, kMaxLambda], band edges in [0, kMaxWavelengthNm] nm, at most kMaxBands
// bands. Far beyond any phosphor (Table 8.1: kr 0.01 to 0.3/s), and wide
// enough for ke in any irradiance unit; the uncertainties (*_stderr) need
// only be finite.
inline constexpr double kMaxRate = 1e9;
inline constexpr double kMaxLambda = 1e9;
inline constexpr double kMaxWavelengthNm = 1e5;
inline constexpr int kMaxBands = 256;
// The largest band-integrated irradiance any input may give (a scene's light,
// `phos simulate --irradiance`): with kMaxRate, ke E stays below 1e18/s.
inline constexpr double kMaxIrradiance = 1e9;
inline constexpr const char* kMaterialSchema = "phos.material/1";

enum class Units {
  kRelative,  // "relative": irradiance and radiance in the unit the ke and Lambda were measured in
  kPhysical,  // "physical": E in W/m², Lp in W/(sr m²), per band
};
// "relative" or "physical", as the file says it.
const char* UnitsName(Units units);
class JsonField;  // phos/util/json.h
// The "units" member of a material's or a scene's root: absent is relative,
// as every file written before units existed; another name fails at it.
Units ReadUnits(const JsonField& root);

struct ExcitedState {
  double kr = 0.0;                        // 1/s
  std::vector<std::optional<double>> ke;  // per band, 1/s per unit irradiance; nullopt = unknown
  std::vector<double> Lambda;             // per band, radiance per unit kr*r
  // Optional 1-sigma uncertainties of a fit (same units); nullopt: not given.
  std::optional<double> kr_stderr;
  std::vector<std::optional<double>> ke_stderr;  // empty, or one per band (nullopt where ke is unknown)

  bool ke_known(int b) const { return ke[b].has_value(); }
};

struct Material {
  std::string name;
  SpectralGrid bands;
  std::optional<std::vector<double>> albedo;  // per band, in [0, 1]
  std::vector<ExcitedState> states;
  std::string source;  // provenance (optional, free text)
  Units units = Units::kRelative;

  int band_count() const { return bands.band_count(); }
  int state_count() const { return static_cast<int>(states.size()); }
  // True if every ke of every state is known in band b.
  bool ChargeableIn(int b) const;
};

// Loads and validates a material file. Any problem is a UserError naming the
// file and the field, e.g. "green.json: states[0].kr: expected a number >= 0, got -1".
Material LoadMaterial(const std::filesystem::path& path);
// Validates and converts already-parsed JSON; `source` names it in errors.
Material MaterialFromJson(const nlohmann::json& json, const std::string& source);
nlohmann::json MaterialToJson(const Material& material);
// Writes atomically (temporary file + rename): an existing file is never left half-written.
void SaveMaterial(const Material& material, const std::filesystem::path& path);
// Sets every unknown ke to 0. Only for callers that state this assumption
// (a scene's "unknown_ke": "zero"), never as phos's own guess.
void AssumeUnknownKeZero(Material& material);

// Checks a material built in code by the same rules as a loaded one.
void ValidateMaterial(const Material& material, const std::string& source);

}  // namespace phos
