#include "phos/model/material.h"

#include <cmath>

#include <nlohmann/json.hpp>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos {

const char* UnitsName(Units units) { return units == Units::kPhysical ? "physical" : "relative"; }

Units ReadUnits(const JsonField& root) {
  const auto field = root.Optional("units");
  if (!field) return Units::kRelative;
  const std::string name = field->String();
  for (Units units : {Units::kRelative, Units::kPhysical})
    if (name == UnitsName(units)) return units;
  field->Fail("unknown units \"" + name + "\" (expected \"relative\" or \"physical\")");
}

bool Material::ChargeableIn(int b) const {
  for (const ExcitedState& s : states)
    if (!s.ke_known(b)) return false;
  return true;
}

namespace {

// A number >= 0 and at most `limit` (the finite ranges of material.h).
double NonNegativeUpTo(const JsonField& field, double limit) {
  const double v = field.NumberAtLeast(0.0);
  if (v > limit)
    field.Fail("expected at most " + FormatDouble(limit) + " (the limit phos accepts), got " + FormatDouble(v));
  return v;
}

}  // namespace

Material MaterialFromJson(const nlohmann::json& json, const std::string& source) {
  JsonField root(json, source);
  root.RejectUnknownKeys({"schema", "name", "units", "bands_nm", "albedo", "states", "source"});
  Material m;
  std::string schema = root["schema"].String();
  if (schema != kMaterialSchema)
    root["schema"].Fail("unknown schema \"" + schema + "\" (expected \"" + kMaterialSchema + "\")");
  m.name = root["name"].NonEmptyString();
  if (auto s = root.Optional("source")) m.source = s->String();
  m.units = ReadUnits(root);

  JsonField bands = root["bands_nm"];
  if (bands.ArraySize() < 2) bands.Fail("expected at least 2 band edges (one band)");
  if (bands.ArraySize() > static_cast<size_t>(kMaxBands) + 1)
    bands.Fail("more than the limit of " + std::to_string(kMaxBands) + " bands");
  m.bands.edges_nm = bands.NumberArray(0, 0.0);
  for (size_t i = 0; i < m.bands.edges_nm.size(); ++i)
    if (m.bands.edges_nm[i] > kMaxWavelengthNm)
      bands.At(i).Fail("expected a wavelength of at most " + FormatDouble(kMaxWavelengthNm) + " nm, got " +
                       FormatDouble(m.bands.edges_nm[i]));
  for (size_t i = 1; i < m.bands.edges_nm.size(); ++i)
    if (!(m.bands.edges_nm[i] > m.bands.edges_nm[i - 1]))
      bands.At(i).Fail("band edges must increase strictly (" + FormatDouble(m.bands.edges_nm[i]) + " follows " +
                       FormatDouble(m.bands.edges_nm[i - 1]) + ")");
  const size_t n = static_cast<size_t>(m.bands.band_count());

  if (auto albedo = root.Optional("albedo"); albedo && !albedo->IsNull()) {
    std::vector<double> a = albedo->NumberArray(n, 0.0);
    for (size_t b = 0; b < n; ++b)
      if (a[b] > 1.0) albedo->At(b).Fail("expected a reflectance in [0, 1], got " + FormatDouble(a[b]));
    m.albedo = a;
  }

  JsonField states = root["states"];
  size_t nc = states.ArraySize();
  if (nc < 1 || nc > static_cast<size_t>(kMaxStates))
    states.Fail("expected 1 to " + std::to_string(kMaxStates) + " excited states, got " + std::to_string(nc));
  for (size_t i = 0; i < nc; ++i) {
    JsonField s = states.At(i);
    s.RejectUnknownKeys({"kr", "ke", "Lambda", "kr_stderr", "ke_stderr"});
    ExcitedState state;
    state.kr = NonNegativeUpTo(s["kr"], kMaxRate);
    JsonField ke = s["ke"];
    if (ke.IsNull()) {
      state.ke.assign(n, std::nullopt);  // never measured: the material can decay but not be charged
    } else {
      if (ke.ArraySize() != n)
        ke.Fail("expected " + std::to_string(n) + " values (one per band), got " + std::to_string(ke.ArraySize()));
      for (size_t b = 0; b < n; ++b) {
        JsonField v = ke.At(b);
        state.ke.push_back(v.IsNull() ? std::nullopt : std::optional<double>(NonNegativeUpTo(v, kMaxRate)));
      }
    }
    state.Lambda = s["Lambda"].NumberArray(n, 0.0);
    for (size_t b = 0; b < n; ++b) NonNegativeUpTo(s["Lambda"].At(b), kMaxLambda);
    if (auto kr_stderr = s.Optional("kr_stderr"); kr_stderr && !kr_stderr->IsNull())
      state.kr_stderr = kr_stderr->NumberAtLeast(0.0);
    if (auto ke_stderr = s.Optional("ke_stderr"); ke_stderr && !ke_stderr->IsNull()) {
      if (ke_stderr->ArraySize() != n)
        ke_stderr->Fail("expected " + std::to_string(n) + " values (one per band), got " +
                        std::to_string(ke_stderr->ArraySize()));
      for (size_t b = 0; b < n; ++b) {
        JsonField v = ke_stderr->At(b);
        if (!v.IsNull() && !state.ke[b]) v.Fail("an uncertainty for a ke that is unknown");
        state.ke_stderr.push_back(v.IsNull() ? std::nullopt : std::optional<double>(v.NumberAtLeast(0.0)));
      }
    }
    m.states.push_back(std::move(state));
  }
  return m;
}

nlohmann::json MaterialToJson(const Material& m) {
  nlohmann::json j;
  j["schema"] = kMaterialSchema;
  j["name"] = m.name;
  if (!m.source.empty()) j["source"] = m.source;
  if (m.units != Units::kRelative) j["units"] = UnitsName(m.units);  // relative files stay as they were
  j["bands_nm"] = m.bands.edges_nm;
  if (m.albedo) j["albedo"] = *m.albedo;
  j["states"] = nlohmann::json::array();
  for (const ExcitedState& s : m.states) {
    nlohmann::json state;
    state["kr"] = s.kr;
    bool any_known = false;
    nlohmann::json ke = nlohmann::json::array();
    for (const auto& v : s.ke) {
      ke.push_back(v ? nlohmann::json(*v) : nlohmann::json(nullptr));
      any_known = any_known || v.has_value();
    }
    state["ke"] = any_known ? ke : nlohmann::json(nullptr);
    state["Lambda"] = s.Lambda;
    if (s.kr_stderr) state["kr_stderr"] = *s.kr_stderr;
    if (!s.ke_stderr.empty()) {
      nlohmann::json ke_stderr = nlohmann::json::array();
      for (const auto& v : s.ke_stderr) ke_stderr.push_back(v ? nlohmann::json(*v) : nlohmann::json(nullptr));
      state["ke_stderr"] = ke_stderr;
    }
    j["states"].push_back(state);
  }
  return j;
}

Material LoadMaterial(const std::filesystem::path& path) { return MaterialFromJson(ReadJsonFile(path), path.string()); }

void ValidateMaterial(const Material& material, const std::string& source) {
  // JSON has no NaN (nlohmann writes it as null, which would read back as an
  // unknown ke), so non-finite values are caught here, before the round trip.
  auto finite = [&](double v, const std::string& field) {
    if (!std::isfinite(v)) ThrowUserError(source, field, "expected a finite number, got " + FormatDouble(v));
  };
  for (size_t i = 0; i < material.states.size(); ++i) {
    const ExcitedState& s = material.states[i];
    std::string at = "states[" + std::to_string(i) + "]";
    finite(s.kr, at + ".kr");
    for (size_t b = 0; b < s.ke.size(); ++b)
      if (s.ke[b]) finite(*s.ke[b], at + ".ke[" + std::to_string(b) + "]");
    for (size_t b = 0; b < s.Lambda.size(); ++b) finite(s.Lambda[b], at + ".Lambda[" + std::to_string(b) + "]");
    if (s.kr_stderr) finite(*s.kr_stderr, at + ".kr_stderr");
    for (size_t b = 0; b < s.ke_stderr.size(); ++b)
      if (s.ke_stderr[b]) finite(*s.ke_stderr[b], at + ".ke_stderr[" + std::to_string(b) + "]");
  }
  // One set of rules: a material built in code goes through the loader's checks.
  MaterialFromJson(MaterialToJson(material), source);
}

void SaveMaterial(const Material& material, const std::filesystem::path& path) {
  ValidateMaterial(material, path.string());
  WriteFileAtomically(path, MaterialToJson(material).dump(2) + "\n");
}

void AssumeUnknownKeZero(Material& material) {
  for (ExcitedState& state : material.states)
    for (std::optional<double>& ke : state.ke)
      if (!ke) ke = 0.0;
}

}  // namespace phos
