// phos.constraints/1 (docs/formats.md): the irradiance at one point over time, the
// surface's albedo, how many states to solve for, and the constraints.

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "phos/editor/solve.h"
#include "phos/model/schedule.h"
#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos::editor {

namespace {
constexpr std::size_t kMaxFrames = 1000000;

// "irradiance": one row per frame, or phases ({"duration_s", "irradiance",
// "label"}; no "irradiance": dark) that FrameIrradiance lays on the frames,
// so that a charge then a decay is two lines instead of a row per frame.
std::vector<std::vector<double>> ReadIrradiance(const JsonField& irradiance, std::size_t nb, double dt_s) {
  if (irradiance.ArraySize() == 0) irradiance.Fail("expected at least one frame");
  std::vector<std::vector<double>> frames;
  if (!irradiance.At(0).value().is_object()) {
    if (irradiance.ArraySize() > kMaxFrames) irradiance.Fail("more than a million frames");
    for (std::size_t f = 0; f < irradiance.ArraySize(); ++f) {
      if (irradiance.At(f).value().is_object())
        irradiance.At(f).Fail("a phase among rows: give a row per frame, or phases only");
      frames.push_back(irradiance.At(f).NumberArray(nb, 0.0));
    }
    return frames;
  }
  IrradianceSchedule schedule;
  for (std::size_t k = 0; k < irradiance.ArraySize(); ++k) {
    const JsonField phase = irradiance.At(k);
    if (!phase.value().is_object()) phase.Fail("a row among phases: give phases only, or a row per frame");
    phase.RejectUnknownKeys({"duration_s", "irradiance", "label"});
    const double duration_s = phase["duration_s"].NumberInRange(0, static_cast<double>(kMaxFrames) * dt_s);
    std::vector<double> E =
        phase.Has("irradiance") ? phase["irradiance"].NumberArray(nb, 0.0) : std::vector<double>(nb, 0.0);
    schedule.Add(duration_s, std::move(E), phase.Has("label") ? phase["label"].String() : "");
  }
  const std::optional<long long> count = WholeFrames(schedule.total_s(), dt_s);
  if (!count)
    irradiance.Fail("the phases last " + FormatDouble(schedule.total_s()) +
                    " s, not a whole number of frames of dt_s = " + FormatDouble(dt_s) +
                    " s; lengthen or shorten the last phase");
  if (*count == 0) irradiance.Fail("the phases last 0 s: expected at least one frame");
  if (*count > static_cast<long long>(kMaxFrames)) irradiance.Fail("more than a million frames");
  return FrameIrradiance(schedule, dt_s);
}
}  // namespace

Problem LoadProblem(const std::filesystem::path& path) { return ProblemFromJson(ReadJsonFile(path), path.string()); }

Problem ProblemFromJson(const nlohmann::json& json, const std::string& source) {
  const JsonField root(json, source);
  root.RejectUnknownKeys(
      {"schema", "description", "bands_nm", "dt_s", "irradiance", "albedo", "states", "constraints"});
  if (root["schema"].String() != "phos.constraints/1")
    root["schema"].Fail("expected \"phos.constraints/1\", got " + DescribeJson(root["schema"].value()));
  Problem p;
  p.source = source;
  p.bands.edges_nm = root["bands_nm"].NumberArray(0, 1.0);
  if (p.bands.edges_nm.size() < 2) root["bands_nm"].Fail("expected at least two band edges");
  for (std::size_t i = 1; i < p.bands.edges_nm.size(); ++i)
    if (!(p.bands.edges_nm[i] > p.bands.edges_nm[i - 1])) root["bands_nm"].At(i).Fail("band edges must increase");
  const std::size_t nb = static_cast<std::size_t>(p.bands.band_count());
  p.dt_s = root["dt_s"].NumberInRange(1e-6, 1e6);
  const JsonField irradiance = root["irradiance"];
  Point point;
  point.irradiance = ReadIrradiance(irradiance, nb, p.dt_s);
  bool lit = false;
  for (const std::vector<double>& frame : point.irradiance)
    for (double e : frame) lit = lit || e > 0;
  // As the editor page refuses such a point: nothing charges it, and every
  // target could only be met with Lambda = 0.
  if (!lit) irradiance.Fail("zero at every frame: nothing charges the point, so no glow can be designed there");
  point.albedo = root["albedo"].NumberArray(nb, 0.0);
  for (std::size_t b = 0; b < nb; ++b)
    if (point.albedo[b] > 1)
      root["albedo"].At(b).Fail("expected an albedo in [0, 1], got " + FormatDouble(point.albedo[b]));
  p.points.push_back(std::move(point));
  if (root.Has("states")) p.states = root["states"].Integer(1, 3);
  const JsonField constraints = root["constraints"];
  if (constraints.ArraySize() == 0) constraints.Fail("expected at least one constraint");
  if (constraints.ArraySize() > kMaxConstraints)
    constraints.Fail("has " + std::to_string(constraints.ArraySize()) + " constraints, more than the limit of " +
                     std::to_string(kMaxConstraints));
  for (std::size_t c = 0; c < constraints.ArraySize(); ++c) {
    const JsonField f = constraints.At(c);
    f.RejectUnknownKeys({"t_s", "until_s", "radiance", "at_least", "at_most", "weight", "label"});
    Constraint con;
    con.label = f.Has("label") ? f["label"].String() : "constraints[" + std::to_string(c) + "]";
    con.t_s = f["t_s"].NumberInRange(0, p.end_s());
    const int kinds = f.Has("radiance") + f.Has("at_least") + f.Has("at_most");
    if (kinds != 1) f.Fail("give exactly one of \"radiance\" (a target), \"at_least\" or \"at_most\"");
    const char* key = f.Has("radiance") ? "radiance" : f.Has("at_least") ? "at_least" : "at_most";
    con.kind = f.Has("radiance")   ? Constraint::Kind::kTarget
               : f.Has("at_least") ? Constraint::Kind::kAtLeast
                                   : Constraint::Kind::kAtMost;
    con.radiance = f[key].NumberArray(nb, 0.0);
    for (std::size_t b = 0; b < nb; ++b)
      if (con.radiance[b] > kMaxConstraintRadiance)
        f[key].At(b).Fail("expected a radiance of at most " + FormatDouble(kMaxConstraintRadiance) + ", got " +
                          FormatDouble(con.radiance[b]) + " (the cost squares it)");
    // A target's weight is 1 / |T|^2, and a zero target is met with Lambda =
    // 0: the material would not glow at all (the editor page refuses it too).
    if (con.kind == Constraint::Kind::kTarget &&
        std::all_of(con.radiance.begin(), con.radiance.end(), [](double v) { return v == 0; }))
      f[key].Fail(
          "a target of zero in every band would give Lambda = 0 (no glow at all); give the radiance it "
          "should have, or say \"at_most\" for a time it should be dark");
    // A target's weight 1 / |T|^2 must be finite: a target of 1e-200 squares to 0.
    double squares = 0;
    for (double v : con.radiance) squares += v * v;
    if (con.kind == Constraint::Kind::kTarget && !std::isfinite(1 / squares))  // not all 0: refused above
      f[key].Fail(
          "a target this small (its square is 0 in double precision) cannot weigh the cost; give at least "
          "1e-150 in some band");
    con.until_s = con.t_s;
    if (f.Has("until_s")) {
      if (con.kind == Constraint::Kind::kTarget)
        f["until_s"].Fail("a target holds at one time; ranges are for at_least and at_most");
      con.until_s = f["until_s"].NumberInRange(con.t_s, p.end_s());
    }
    if (f.Has("weight")) con.weight = f["weight"].NumberInRange(0, kMaxConstraintWeight);
    p.constraints.push_back(con);
  }
  return p;
}

}  // namespace phos::editor
