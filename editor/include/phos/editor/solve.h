#pragma once
// The material editor's solver (Sec. 8.6, Eq. 8.7): find the phosphor whose
// appearance at one surface point meets an artist's space-time constraints,
// "this bright, this colour, 1 s after the light goes off; still this bright
// at 60 s", given the irradiance there over time.
//
// Radiance at the point (docs/editor.md, "The problem"):
//   L_b(t) = albedo_b E_b(t) / pi + sum_i Lambda_i[b] kr_i r_i(t)     (Eq. 8.2, diffuse)
// with r_i from Eq. 8.1 under the frames' piecewise-constant irradiance.
//
// Constraints: targets ("radiance": L = T at t_s) and bounds ("at_least",
// "at_most": at every frame from t_s to until_s), each with a weight.
// Cost (Eq. 8.7): sum over targets of w |L(t) - T|^2 plus, over bounds, w
// times the squared violation at each frame of its range.
//
// Ours: Lambda enters linearly, so for any (kr, ke) it is solved in closed
// form (non-negative least squares per band); only kr and the excitation
// scale are searched, on a log grid shared by all states (a curve library,
// one curve per plateau of look-alike excitations), then the best candidates
// with distinct kr are refined with Ceres over kr and ke with Lambda
// projected out (variable projection), and over every parameter when bounds
// pull on Lambda too. Runs of frames with one irradiance are one exact step.
// Baseline (the paper): the log grid of Table 8.2 over the 7 parameters of
// nc = 1 in three bands, best cost wins (evaluated band by band, which finds
// exactly the grid's best since the cost separates over bands).

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "phos/model/material.h"
#include "phos/model/spectral.h"

namespace phos::editor {

struct Constraint {
  enum class Kind { kTarget, kAtLeast, kAtMost } kind = Kind::kTarget;
  int point = 0;  // index into Problem::points
  double t_s = 0;
  double until_s = 0;            // bounds: the range's end (>= t_s); targets: = t_s
  std::vector<double> radiance;  // per band
  double weight = 1;
  std::string label;  // "constraints[2]"
};

// A surface point the material is seen at: its irradiance over time (from
// the renderer, once per edit session) and its albedo. A file has one; the
// editor page adds one per clicked point, all sharing one material.
struct Point {
  std::vector<std::vector<double>> irradiance;  // per frame, per band
  std::vector<double> albedo;                   // per band
};

// The most excited states the solve designs (the curve library's
// combinations grow as its size to this power).
inline constexpr int kMaxEditStates = 3;

struct Problem {
  std::string source;
  SpectralGrid bands;
  double dt_s = 0.1;
  std::vector<Point> points;  // at least one; all with the same frame count
  int states = 1;
  std::vector<Constraint> constraints;
  // The material the points wear now (the editor's object), when it has
  // `states` states: the solve keeps it as it is when it already meets the
  // constraints (a constraint placed at a point's current look changes
  // nothing), and else refines from it as from the library's candidates.
  // Its unknown ke count as 0 here, as the editor's curves take them.
  std::optional<Material> start;
  std::size_t frames() const { return points.empty() ? 0 : points[0].irradiance.size(); }
  double end_s() const { return dt_s * static_cast<double>(frames()); }
};

// The most constraints a problem may hold, from a file or placed in the
// editor: the solve's time grows about as n^1.7 (10,000 took 20 s); 1000
// take a fraction of a second (docs/editor.md).
inline constexpr std::size_t kMaxConstraints = 1000;
// The largest band radiance or weight a constraint may give: the cost squares
// them (1e300 printed a cost of inf, exit 0). The editor page's bounds too.
inline constexpr double kMaxConstraintRadiance = 1e6;
inline constexpr double kMaxConstraintWeight = 1e6;

// phos.constraints/1 (docs/formats.md). Bad input: a UserError naming the file and field.
Problem LoadProblem(const std::filesystem::path& path);
Problem ProblemFromJson(const nlohmann::json& json, const std::string& source);

struct ConstraintResult {
  std::string label;
  double residual = 0;            // targets: |L - T| over bands; bounds: the largest violation
  std::vector<double> predicted;  // L per band at t_s
};

struct Solution {
  Material material;
  double cost = 0;
  std::vector<ConstraintResult> constraints;
  // Contradictions and constraints the model cannot meet: which, and by how much.
  std::vector<std::string> feedback;
  double seconds = 0;
  int evaluations = 0;      // curve simulations (ours: library + Ceres)
  bool kept_start = false;  // the material is Problem::start, unchanged: it met the constraints
};

struct SolveOptions {
  int library_kr = 20, library_excitation = 20;  // the curve library's log grid
  int refine_starts = 5;                         // candidates (distinct kr) refined with Ceres
  bool refine = true;
};

Solution Solve(const Problem& problem, const SolveOptions& options = {});
// The paper's baseline; nullopt (with `why`) when the problem is not nc = 1 in
// at most three bands, where Table 8.2's grid is defined.
std::optional<Solution> SolveGridBaseline(const Problem& problem, std::string* why = nullptr);

// The cost (Eq. 8.7) of any material on the problem, and its radiance at
// `point` at the given times, per band (for curves).
double Cost(const Problem& problem, const Material& material);
std::vector<std::vector<double>> PredictRadiance(const Problem& problem, const Material& material,
                                                 const std::vector<double>& times_s, int point = 0);

nlohmann::json SolutionToJson(const Solution& solution);

}  // namespace phos::editor
