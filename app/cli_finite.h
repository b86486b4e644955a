#pragma once
// NaN and infinity in a numeric option: CLI11 converts
// "nan", "inf" and "1e999" to doubles without a word, and a time, rate or
// irradiance of NaN then runs silently into every later computation. Every
// numeric option of every command takes this check:
//
//   command->add_option("--charge-s", args->charge_s, "...")->check(phos::app::kFinite);
//
// For a list option (a delimiter, or a std::vector), CLI11 applies the
// check to each element. Text that is not a number at all is left to
// CLI11's own conversion, which names the option too.

#include <cmath>
#include <cstdlib>
#include <string>

#include <CLI/CLI.hpp>

namespace phos::app {

// The error text for an option value that parses as a number but not a
// finite one ("" when it is finite or no number at all).
inline std::string NonFiniteOptionValue(const std::string& text) {
  const char* begin = text.c_str();
  char* end = nullptr;
  const double value = std::strtod(begin, &end);
  if (end == begin) return "";  // not a number: CLI11's conversion says so
  while (*end == ' ') ++end;
  if (*end != '\0') return "";
  if (std::isfinite(value)) return "";  // an underflow to a denormal or 0 is finite too
  return "expected a finite number, got " + text;
}

inline const CLI::Validator kFinite(NonFiniteOptionValue, "FINITE", "finite");

// Bounds on a floating-point option, said as a person would: CLI11's own
// PositiveNumber printed "Value 0 not in range 0.000000 to " and DBL_MAX in
// 309 digits, and its Range(1e-9, 1) read "not in range 0.000000 to
// 1.000000" for 0, as if 0 were inside. Text that is no number is left to
// CLI11's conversion, and NaN to kFinite.
inline std::string OptionValueAbove(const std::string& text, double lower, double upper, const char* expected) {
  const char* begin = text.c_str();
  char* end = nullptr;
  const double value = std::strtod(begin, &end);
  if (end == begin || std::isnan(value)) return "";  // no number, or NaN: kFinite and CLI11 say so
  return value > lower && value <= upper ? "" : std::string("expected ") + expected + ", got " + text;
}
// > 0.
inline const CLI::Validator kPositive(
    [](const std::string& text) { return OptionValueAbove(text, 0, HUGE_VAL, "a number > 0"); }, "POSITIVE",
    "positive");
// >= 0.
inline const CLI::Validator kNonNegative(
    [](const std::string& text) {
      const char* begin = text.c_str();
      char* end = nullptr;
      const double value = std::strtod(begin, &end);
      return end == begin || std::isnan(value) || value >= 0 ? std::string() : "expected a number >= 0, got " + text;
    },
    "NONNEGATIVE", "non-negative");
// In (0, 1].
inline const CLI::Validator kFraction(
    [](const std::string& text) { return OptionValueAbove(text, 0, 1, "a number above 0 and at most 1"); },
    "(0,1]", "fraction");

// Whether an option already has kFinite (given where it was declared), so
// that --help does not list it twice ("FLOAT:FINITE:FINITE").
inline bool ChecksFinite(CLI::Option& option) {
  try {
    option.get_validator(kFinite.get_name());
    return true;
  } catch (const CLI::OptionNotFound&) {
    return false;
  }
}

// kFinite on every floating-point option of a command and its subcommands
// (CLI11's type name FLOAT), so a command added later cannot forget one.
inline void RequireFiniteNumbers(CLI::App& app) {
  for (CLI::Option* option : app.get_options())
    if (option->get_type_name().find("FLOAT") != std::string::npos && !ChecksFinite(*option)) option->check(kFinite);
  for (CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) RequireFiniteNumbers(*sub);
}

}  // namespace phos::app
