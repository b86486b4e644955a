// `phos fit decay-curve` and `phos fit charge-curve` as a user runs them.

#include <cmath>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <algorithm>
#include <random>
#include <string>
#include <vector>
#include <sstream>

#include "test_util.h"

namespace phos {
namespace {

using testing::RunPhos;

// A two-component decay with noise, as CSV; returns the file.
std::string WriteDecay(const testing::TempDir& dir, const std::string& name, int points = 300) {
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0, 0.5);
  std::ostringstream csv;
  csv << "t,value\n";
  for (int j = 0; j < points; ++j) {
    const double t = j * 0.1;
    csv << t << "," << 400 * std::exp(-1.2 * t) + 150 * std::exp(-0.07 * t) + noise(rng) << "\n";
  }
  testing::WriteText(dir / name, csv.str());
  return (dir / name).string();
}

double PlainRss(const std::string& csv_text, const nlohmann::json& fit) {
  std::istringstream in(csv_text);
  std::string line;
  std::getline(in, line);
  double rss = 0;
  while (std::getline(in, line)) {
    const double t = std::stod(line.substr(0, line.find(','))), y = std::stod(line.substr(line.find(',') + 1));
    double model = 0;
    for (const auto& k : fit["components"])
      model += k["amplitude"].get<double>() * std::exp(-k["rate"].get<double>() * t);
    rss += (y - model) * (y - model);
  }
  return rss;
}

TEST(FitDecayCommand, JsonFollowsTheContract) {
  testing::TempDir dir;
  const std::string csv = WriteDecay(dir, "d.csv");
  for (const char* weights : {"none", "poisson"}) {
    auto result = RunPhos("fit decay-curve --csv " + csv + " --max-components 3 --weights " + weights + " --json");
    ASSERT_EQ(result.exit_code, 0) << result.err;
    nlohmann::json j = nlohmann::json::parse(result.out);
    ASSERT_EQ(j["n_components"], 2) << j.dump();
    ASSERT_EQ(j["components"].size(), 2u);
    for (const auto& k : j["components"]) {
      EXPECT_TRUE(k.contains("amplitude") && k.contains("rate") && k.contains("rate_stderr")) << k.dump();
      EXPECT_GT(k["rate_stderr"].get<double>(), 0);
    }
    EXPECT_NEAR(j["components"][0]["rate"].get<double>(), 1.2, 0.05);
    EXPECT_NEAR(j["components"][1]["rate"].get<double>(), 0.07, 0.003);
    EXPECT_GT(j["seconds"].get<double>(), 0);
    EXPECT_EQ(j["file"], csv);
    EXPECT_EQ(j["samples"], 300);
    EXPECT_EQ(j["time_order"]["reordered"], false);
    EXPECT_EQ(j["warnings"], nlohmann::json::array());
    EXPECT_EQ(testing::LineCount(result.out), 1);
    // rss is the plain sum of squares in the data's units, whatever the weighting.
    EXPECT_NEAR(j["rss"].get<double>(), PlainRss(testing::ReadText(csv), j), 1e-6 * j["rss"].get<double>()) << weights;
  }
  auto fixed = RunPhos("fit decay-curve --csv " + csv + " --components 1 --json");
  ASSERT_EQ(fixed.exit_code, 0) << fixed.err;
  EXPECT_EQ(nlohmann::json::parse(fixed.out)["n_components"], 1);
}

// A fit stopped at its iteration limit is not a result: the file fails
// (exit 2, one line) unless --keep-unconverged, which reports it with a warning.
TEST(FitCurveCommands, AFitThatDidNotConvergeFailsUnlessKept) {
  const std::string decay = testing::Fixture("curves/decay-two-components.csv").string();
  const std::string charge = testing::Fixture("curves/charge.csv").string();
  for (const std::string& command : {"fit decay-curve " + decay, "fit charge-curve " + charge}) {
    const auto whole = RunPhos(command + " --json");
    ASSERT_EQ(whole.exit_code, 0) << whole.err;
    EXPECT_EQ(nlohmann::json::parse(whole.out)["converged"], true);
    EXPECT_TRUE(testing::IsOneLineUserError(RunPhos(command + " --max-iterations 1"), "the fit did not converge"))
        << command;
    const auto kept = RunPhos(command + " --max-iterations 1 --keep-unconverged --json");
    ASSERT_EQ(kept.exit_code, 0) << kept.err;
    EXPECT_EQ(nlohmann::json::parse(kept.out)["converged"], false);
    EXPECT_NE(kept.err.find("did not converge"), std::string::npos) << kept.err;
  }
}

TEST(FitChargeCommand, JsonFollowsTheContract) {
  testing::TempDir dir;
  std::ostringstream csv;
  csv.precision(17);
  csv << "t,value\n";
  for (int j = 0; j < 100; ++j) csv << j << "," << 5 - 4 * std::exp(-0.03 * j) << "\n";
  testing::WriteText(dir / "c.csv", csv.str());
  auto result = RunPhos("fit charge-curve --csv " + (dir / "c.csv").string() + " --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  nlohmann::json j = nlohmann::json::parse(result.out);
  for (const char* key : {"L0", "Linf", "rate", "rss", "seconds"}) EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_NEAR(j["rate"].get<double>(), 0.03, 1e-8);
  EXPECT_NEAR(j["Linf"].get<double>(), 5, 1e-8);
  EXPECT_NEAR(j["L0"].get<double>(), 1, 1e-8);
}

TEST(FitCommands, BadInputGivesOneLineAndExitCode2) {
  testing::TempDir dir;
  const std::string good = WriteDecay(dir, "good.csv");
  testing::WriteText(dir / "empty.csv", "");
  testing::WriteText(dir / "header.csv", "t,value\n");
  testing::WriteText(dir / "one.csv", "t,value\n0,1\n");
  testing::WriteText(dir / "flat.csv", "t,value\n0,1\n1,1\n2,1\n3,1\n4,1\n5,1\n6,1\n7,1\n");
  testing::WriteText(dir / "nan.csv", "t,value\n0,1\n1,nan\n");
  testing::WriteText(dir / "rising.csv", "t,value\n0,1\n1,2\n2,3\n3,4\n4,5\n5,6\n6,7\n7,8\n");
  testing::WriteText(dir / "onecol.csv", "t\n0\n1\n");
  {
    // Negative times crashed fit charge-curve (under ASan: ceres::Covariance
    // on the overflowing e^{-kt} of this curve).
    std::ostringstream negative_t;
    negative_t.precision(17);
    negative_t << "t,value\n";
    for (int j = 0; j < 61; ++j) {
      const double t = -389.848 + j * 1.48306;
      negative_t << t << "," << 5 - 4 * std::exp(-0.943978 * t) << "\n";
    }
    testing::WriteText(dir / "negative-t.csv", negative_t.str());
  }
  testing::WriteText(dir / "few-times.csv", "t,value\n0,9\n0,9.1\n0,8.9\n0,9\n1,5\n1,5.1\n1,4.9\n1,5\n");
  testing::WriteText(dir / "negative.csv", "t,value\n0,-1\n1,-2\n2,-3\n3,-4\n4,-5\n5,-6\n6,-7\n7,-8\n");
  struct Case {
    std::string arguments, expected;
  } cases[] = {
      {"fit decay-curve --csv " + (dir / "none.csv").string() + " --json", "none.csv: cannot open"},
      {"fit decay-curve --csv " + (dir / "empty.csv").string() + " --json", "empty.csv: empty file"},
      {"fit decay-curve --csv " + (dir / "header.csv").string() + " --json", "header.csv: has 0 samples"},
      {"fit decay-curve --csv " + (dir / "one.csv").string() + " --json", "one.csv: has 1 sample"},
      {"fit decay-curve --csv " + (dir / "flat.csv").string() + " --components 1 --json", "every value is the same"},
      {"fit decay-curve --csv " + (dir / "nan.csv").string() + " --json",
       "nan.csv: line 3, column value: expected a finite number"},
      {"fit decay-curve --csv " + (dir / "rising.csv").string() + " --components 1 --json", "no decaying component"},
      {"fit decay-curve --csv " + (dir / "onecol.csv").string() + " --json", "expected columns t,value"},
      {"fit decay-curve --csv " + (dir / "negative.csv").string() + " --components 1 --json", "no decaying component"},
      {"fit decay-curve --csv " + good + " --components 5 --json", "--components: expected 1 to 4, got 5"},
      {"fit decay-curve --csv " + good + " --components 2 --max-components 3 --json", "excludes"},
      {"fit decay-curve --csv " + good + " --weights gauss --json", "--weights: expected none or poisson"},
      {"fit charge-curve --csv " + (dir / "flat.csv").string() + " --json", "no growth to fit"},
      {"fit charge-curve --csv " + good + " --weights x --json", "--weights"},
      {"fit charge-curve --csv " + (dir / "negative-t.csv").string() + " --json",
       "negative-t.csv: t: sample 1 is at a negative time"},
      {"fit decay-curve " + (dir / "negative-t.csv").string(), "negative-t.csv: t: sample 1 is at a negative time"},
      {"fit decay-curve " + (dir / "few-times.csv").string() + " --components 1",
       "few-times.csv: t: has 8 samples at only 2 distinct times"},
      {"fit decay-curve " + good + " --from 100", "good.csv: --from: no sample in the window"},
      {"fit decay-curve " + good + " --from 5 --to 1", "--from: 5 s is after --to 1 s"},
      {"fit decay-curve " + good + " " + good + " --plot p.svg", "--plot: draws one curve; got 2 files"},
      {"fit decay-curve --json", "no curve file given"},
      {"fit charge-curve", "no curve file given"},
      {"fit", "phos fit: A subcommand is required"},
  };
  for (const Case& c : cases) {
    auto result = RunPhos(c.arguments);
    EXPECT_TRUE(testing::IsOneLineUserError(result, c.expected)) << c.arguments;
  }
}

nlohmann::json FitJson(const std::string& arguments) {
  auto result = RunPhos(arguments + " --json");
  EXPECT_EQ(result.exit_code, 0) << arguments << ": " << result.err;
  return nlohmann::json::parse(result.out);
}

std::vector<double> Rates(const nlohmann::json& fit) {
  std::vector<double> rates;
  for (const auto& k : fit["components"]) rates.push_back(k["rate"].get<double>());
  return rates;
}

// The rows of a CSV without its header, and the header.
std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) lines.push_back(line);
  return lines;
}

std::string Join(const std::vector<std::string>& lines) {
  std::string text;
  for (const std::string& line : lines) text += line + "\n";
  return text;
}

TEST(FitCurveFiles, ShuffledReplicatesGiveTheSortedResult) {
  testing::TempDir dir;
  // The replicate fixture is written one aliquot after the other; sorted by
  // time (stably) it is the same curve as the file sorted by hand.
  const std::string fixture = testing::Fixture("curves/decay-replicates.csv").string();
  std::vector<std::string> rows = Lines(testing::ReadText(fixture));
  rows.erase(rows.begin());  // the comment
  const std::string header = rows.front();
  rows.erase(rows.begin());
  std::vector<std::string> by_time = rows;
  std::stable_sort(by_time.begin(), by_time.end(), [](const std::string& a, const std::string& b) {
    return std::stod(a.substr(0, a.find(','))) < std::stod(b.substr(0, b.find(',')));
  });
  std::vector<std::string> shuffled = rows;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(9));
  by_time.insert(by_time.begin(), header);
  shuffled.insert(shuffled.begin(), header);
  testing::WriteText(dir / "sorted.csv", Join(by_time));
  testing::WriteText(dir / "shuffled.csv", Join(shuffled));

  const nlohmann::json file = FitJson("fit decay-curve " + fixture);
  const nlohmann::json sorted = FitJson("fit decay-curve " + (dir / "sorted.csv").string());
  const nlohmann::json mixed = FitJson("fit decay-curve " + (dir / "shuffled.csv").string());
  EXPECT_EQ(Rates(file), Rates(sorted));  // the same samples in the same order: bit for bit
  ASSERT_EQ(Rates(mixed).size(), 2u);
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(Rates(mixed)[i], Rates(sorted)[i], 1e-9 * Rates(sorted)[i]);
  EXPECT_NEAR(mixed["rss"].get<double>(), sorted["rss"].get<double>(), 1e-9 * sorted["rss"].get<double>());
  // The truth: 300 e^{-0.8 t} + 100 e^{-0.05 t}.
  EXPECT_NEAR(Rates(file)[0], 0.8, 4 * file["components"][0]["rate_stderr"].get<double>());
  EXPECT_NEAR(Rates(file)[1], 0.05, 4 * file["components"][1]["rate_stderr"].get<double>());
  EXPECT_EQ(file["samples"], 120);
  EXPECT_EQ(file["time_order"], (nlohmann::json{{"reordered", true}, {"distinct_times", 40}, {"repeated_times", 40}}));
  EXPECT_EQ(sorted["time_order"]["reordered"], false);
  EXPECT_EQ(sorted["time_order"]["repeated_times"], 40);
  auto text = RunPhos("fit decay-curve " + fixture);
  EXPECT_NE(text.out.find("  sorted 120 samples by time; 40 repeated times (replicates)\n"), std::string::npos)
      << text.out;
  text = RunPhos("fit decay-curve " + (dir / "sorted.csv").string());
  EXPECT_NE(text.out.find("  120 samples; 40 repeated times (replicates)\n"), std::string::npos) << text.out;
}

TEST(FitCurveFiles, AWindowFitsLikeTheCutFile) {
  testing::TempDir dir;
  const std::string fixture = testing::Fixture("curves/decay-two-components.csv").string();
  const std::vector<std::string> rows = Lines(testing::ReadText(fixture));
  auto time_of = [](const std::string& row) { return row.substr(0, row.find(',')); };
  // The window's ends are two of the file's times, written as the file has
  // them, so "inclusive" is tested at both ends.
  std::string from, to;
  for (std::size_t j = 1; j < rows.size(); ++j) {
    if (std::fabs(std::stod(time_of(rows[j])) - 2.5) < 1e-9) from = time_of(rows[j]);
    if (std::fabs(std::stod(time_of(rows[j])) - 20) < 1e-9) to = time_of(rows[j]);
  }
  ASSERT_FALSE(from.empty() || to.empty());
  std::vector<std::string> cut = {rows.front()};
  for (std::size_t j = 1; j < rows.size(); ++j) {
    const double t = std::stod(time_of(rows[j]));
    if (t >= std::stod(from) && t <= std::stod(to)) cut.push_back(rows[j]);
  }
  testing::WriteText(dir / "cut.csv", Join(cut));
  const std::string window_options = " --from " + from + " --to " + to;
  const nlohmann::json window = FitJson("fit decay-curve " + fixture + window_options);
  const nlohmann::json pre_cut = FitJson("fit decay-curve " + (dir / "cut.csv").string());
  EXPECT_EQ(window["samples"], 176);  // 2.5 s to 20 s every 0.1 s, both ends in
  EXPECT_EQ(window["samples"], cut.size() - 1);
  EXPECT_EQ(window["window"]["samples_in_file"], 300);
  EXPECT_EQ(Rates(window), Rates(pre_cut));
  EXPECT_EQ(window["rss"], pre_cut["rss"]);
  EXPECT_EQ(window["components"], pre_cut["components"]);
  auto text = RunPhos("fit decay-curve " + fixture + window_options);
  EXPECT_NE(text.out.find("  window 2.5 s to 20 s: 176 of 300 samples"), std::string::npos) << text.out;
}

// A time column whose name gives its unit is read in it: the same curve in
// minutes or milliseconds fits the rates of the file in seconds, and says
// that it converted. (Read as seconds, minutes gave rates 60 times too high.)
TEST(FitCurveFiles, ATimeColumnInMinutesOrMillisecondsIsReadInIt) {
  testing::TempDir dir;
  const std::string fixture = testing::Fixture("curves/decay-two-components.csv").string();
  const nlohmann::json seconds = FitJson("fit decay-curve " + fixture);
  const std::vector<std::string> rows = Lines(testing::ReadText(fixture));
  struct Case {
    const char* header;
    double per_second;  // the file's number for one second
  } cases[] = {{"time_min", 1.0 / 60}, {"t (ms)", 1000}, {"Time [Hours]", 1.0 / 3600}, {"t/s", 1}};
  for (const Case& c : cases) {
    std::vector<std::string> scaled = {std::string(c.header) + ",value"};
    for (std::size_t j = 1; j < rows.size(); ++j) {
      const std::size_t comma = rows[j].find(',');
      char t[64];
      std::snprintf(t, sizeof t, "%.17g", std::stod(rows[j].substr(0, comma)) * c.per_second);
      scaled.push_back(t + rows[j].substr(comma));
    }
    const std::filesystem::path file = dir / "scaled.csv";
    testing::WriteText(file, Join(scaled));
    auto result = RunPhos("fit decay-curve " + file.string() + " --json");
    ASSERT_EQ(result.exit_code, 0) << c.header << ": " << result.err;
    const nlohmann::json fit = nlohmann::json::parse(result.out);
    ASSERT_EQ(Rates(fit).size(), Rates(seconds).size()) << c.header;
    for (std::size_t i = 0; i < Rates(fit).size(); ++i)
      EXPECT_NEAR(Rates(fit)[i], Rates(seconds)[i], 1e-6 * Rates(seconds)[i]) << c.header;
    if (c.per_second == 1) {
      EXPECT_EQ(fit["warnings"].size(), 0u) << c.header;  // seconds: nothing to say
      continue;
    }
    ASSERT_EQ(fit["warnings"].size(), 1u) << c.header;
    EXPECT_NE(fit["warnings"][0].get<std::string>().find("time column '" + std::string(c.header) + "' read in "),
              std::string::npos)
        << fit["warnings"];
    EXPECT_NE(result.err.find("phos: warning: "), std::string::npos) << result.err;
  }
  // Two units in one name: which one is meant is not guessed.
  testing::WriteText(dir / "two.csv", "t_s_min,value\n0,1\n1,0.5\n2,0.25\n");
  EXPECT_TRUE(testing::IsOneLineUserError(RunPhos("fit decay-curve " + (dir / "two.csv").string()),
                                          "names two units of time ('s' and 'min'); give one"));
}

// A decay given to charge-curve fits (the model falls as well as it rises),
// and says it looks like a decay; a charge does not.
TEST(FitCurveFiles, AFallingChargeCurveIsWarnedAbout) {
  const std::string decay = testing::Fixture("curves/decay-two-components.csv").string();
  auto result = RunPhos("fit charge-curve " + decay + " --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(result.err, "phos: warning: " + decay +
                            ": the fitted curve falls (Linf below L0): a decay? 'phos fit decay-curve' fits a decay "
                            "with its components\n");
  EXPECT_EQ(nlohmann::json::parse(result.out)["warnings"].size(), 1u);
  result = RunPhos("fit charge-curve " + testing::Fixture("curves/charge.csv").string());
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(result.err, "");
}

TEST(FitCurveFiles, EverySeparatorGivesTheCommaResult) {
  testing::TempDir dir;
  const std::string comma = testing::ReadText(testing::Fixture("curves/decay-tab.txt"));
  std::string as_comma = comma;
  std::replace(as_comma.begin(), as_comma.end(), '\t', ',');
  std::string semicolon = comma, spaces;
  std::replace(semicolon.begin(), semicolon.end(), '\t', ';');
  for (char c : comma) spaces += c == '\t' ? std::string("   ") : std::string(1, c);
  testing::WriteText(dir / "comma.csv", as_comma);
  testing::WriteText(dir / "semicolon.csv", semicolon);
  testing::WriteText(dir / "spaces.dat", spaces);
  const nlohmann::json reference = FitJson("fit decay-curve " + (dir / "comma.csv").string());
  ASSERT_EQ(reference["channels"], (nlohmann::json{"red", "green", "blue"}));
  for (const std::string& file : {(dir / "semicolon.csv").string(), (dir / "spaces.dat").string(),
                                  testing::Fixture("curves/decay-tab.txt").string()}) {
    const nlohmann::json fit = FitJson("fit decay-curve " + file);
    EXPECT_EQ(fit["components"], reference["components"]) << file;
    EXPECT_EQ(fit["rss"], reference["rss"]) << file;
    EXPECT_EQ(fit["channels"], reference["channels"]) << file;
  }
  // The fixture's truth: rates 1.5 and 0.1 /s in every channel.
  EXPECT_NEAR(Rates(reference)[0], 1.5, 0.01);
  EXPECT_NEAR(Rates(reference)[1], 0.1, 0.001);
}

TEST(FitCurveFiles, AChargeBeforeTheDecayIsWarnedAbout) {
  const std::string file = testing::Fixture("curves/charge-then-decay.csv").string();
  auto result = RunPhos("fit decay-curve " + file + " --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(testing::LineCount(result.err), 1) << result.err;
  EXPECT_NE(result.err.find("phos: warning: " + file + ": the curve rises from its start to a peak at t = 60 s"),
            std::string::npos)
      << result.err;
  EXPECT_NE(result.err.find("--from 60"), std::string::npos) << result.err;
  const nlohmann::json j = nlohmann::json::parse(result.out);
  ASSERT_EQ(j["warnings"].size(), 1u);
  EXPECT_NE(j["warnings"][0].get<std::string>().find("--from 60"), std::string::npos);
  // As suggested: the decay alone, no warning, its rate (0.05 /s).
  result = RunPhos("fit decay-curve " + file + " --from 60 --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(result.err, "");
  const nlohmann::json decay = nlohmann::json::parse(result.out);
  EXPECT_EQ(decay["warnings"].size(), 0u);
  EXPECT_EQ(decay["n_components"], 1);
  EXPECT_NEAR(Rates(decay)[0], 0.05, 4 * decay["components"][0]["rate_stderr"].get<double>());
  // And the charge before it, with charge-curve.
  const nlohmann::json charge = FitJson("fit charge-curve " + file + " --to 60");
  EXPECT_NEAR(charge["rate"].get<double>(), 0.05, 4 * charge["rate_stderr"].get<double>());
  EXPECT_NEAR(charge["Linf"].get<double>(), 500, 4 * charge["Linf_stderr"].get<double>());
}

TEST(FitCurveFiles, ManyFilesGiveOneResultEachInOrder) {
  testing::TempDir dir;
  const std::string a = WriteDecay(dir, "a.csv"), b = testing::Fixture("curves/decay-semicolon.csv").string(),
                    c = testing::Fixture("curves/decay-replicates.csv").string();
  auto result = RunPhos("fit decay-curve " + a + " --csv " + b + " " + c + " --json");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const std::vector<std::string> lines = Lines(result.out);
  ASSERT_EQ(lines.size(), 3u) << result.out;
  const std::string files[] = {a, b, c};
  for (int i = 0; i < 3; ++i) {
    const nlohmann::json j = nlohmann::json::parse(lines[i]);
    EXPECT_EQ(j["file"], files[i]);
    // Each line is what the file gives alone (but the time it took).
    nlohmann::json alone = FitJson("fit decay-curve --csv " + files[i]);
    EXPECT_EQ(j["components"], alone["components"]) << files[i];
    EXPECT_EQ(j["rss"], alone["rss"]) << files[i];
  }
  // Text: one table row per file, in order, under a header.
  result = RunPhos("fit decay-curve --csv " + a + " --csv " + b + " " + c + " --background");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const std::vector<std::string> rows = Lines(result.out);
  ASSERT_EQ(rows.size(), 4u) << result.out;
  EXPECT_EQ(rows[0].rfind("file", 0), 0u) << rows[0];
  for (const char* column : {"nc", "rates (1/s)", "rss", "background", "samples"})
    EXPECT_NE(rows[0].find(column), std::string::npos) << column;
  for (int i = 0; i < 3; ++i) EXPECT_EQ(rows[i + 1].rfind(files[i], 0), 0u) << rows[i + 1];
  EXPECT_NE(rows[2].find("12.0"), std::string::npos) << rows[2];  // the semicolon file's dark offset
  EXPECT_NE(rows[3].find("120 (40 repeated times) sorted"), std::string::npos) << rows[3];
}

TEST(FitCurveFiles, ABadFileAmongManyIsOneLineAndTheOthersAreFitted) {
  testing::TempDir dir;
  const std::string a = WriteDecay(dir, "a.csv"), b = WriteDecay(dir, "b.csv");
  testing::WriteText(dir / "bad.csv", "t,value\n0,1\n1,x\n");
  const std::string bad = (dir / "bad.csv").string();
  auto result = RunPhos("fit decay-curve " + a + " " + bad + " " + b + " --json");
  EXPECT_TRUE(testing::IsOneLineUserError(result, bad + ": line 3, column value: expected a finite number"));
  const std::vector<std::string> lines = Lines(result.out);
  ASSERT_EQ(lines.size(), 2u) << result.out;
  EXPECT_EQ(nlohmann::json::parse(lines[0])["file"], a);
  EXPECT_EQ(nlohmann::json::parse(lines[1])["file"], b);
  // Two bad files: a line each, still exit code 2.
  result = RunPhos("fit charge-curve " + bad + " " + testing::Fixture("curves/charge.csv").string() + " " +
                   (dir / "missing.csv").string());
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(testing::LineCount(result.err), 2) << result.err;
  EXPECT_NE(result.err.find(bad + ": line 3"), std::string::npos) << result.err;
  EXPECT_NE(result.err.find("missing.csv: cannot open"), std::string::npos) << result.err;
  EXPECT_EQ(Lines(result.out).size(), 2u) << result.out;  // the table of the one good file
}

TEST(FitCurveFiles, ChargeChannelsShareOneRate) {
  // The fixture: three bands charging at 0.08 /s, two readings per time.
  const std::string file = testing::Fixture("curves/charge-channels.dat").string();
  const nlohmann::json j = FitJson("fit charge-curve --csv " + file);
  EXPECT_NEAR(j["rate"].get<double>(), 0.08, 4 * j["rate_stderr"].get<double>());
  ASSERT_EQ(j["levels"].size(), 3u);
  const double Linf[] = {3.0, 8.0, 1.5};
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(j["levels"][c]["Linf"].get<double>(), Linf[c], 4 * j["levels"][c]["Linf_stderr"].get<double>()) << c;
  EXPECT_EQ(j["levels"][1]["channel"], "band_520");
  EXPECT_EQ(j["L0"], j["levels"][0]["L0"]);
  EXPECT_EQ(j["time_order"]["repeated_times"], 50);
  auto text = RunPhos("fit charge-curve " + file);
  EXPECT_NE(text.out.find("(shared by 3 channels)"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("  band_610: L0 "), std::string::npos) << text.out;
}

TEST(FitCurveFiles, TheFittedBackgroundIsPrinted) {
  // 250 e^{-0.3 t} + 12 (noise 0.5).
  auto result = RunPhos("fit decay-curve " + testing::Fixture("curves/decay-semicolon.csv").string() + " --background");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const std::size_t at = result.out.find("  background  signal (counts/s) ");
  ASSERT_NE(at, std::string::npos) << result.out;
  const double background = std::stod(result.out.substr(at + std::string("  background  signal (counts/s) ").size()));
  EXPECT_NEAR(background, 12, 0.3);
}

}  // namespace
}  // namespace phos
