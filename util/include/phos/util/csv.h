#pragma once
// Numeric tables from text files (simulate output, decay and charge curves
// from any instrument). Errors name the file, the line and the column.

#include <filesystem>
#include <string>
#include <vector>

namespace phos {

struct CsvTable {
  std::string source;
  std::vector<std::string> header;
  std::vector<std::vector<double>> columns;  // columns[c][row]
  // The separator found: ',', ';', '\t', or ' ' for runs of spaces and tabs.
  char separator = ',';
  // False when the file had no header line and the columns were named
  // "column 1", "column 2", ...
  bool has_header = true;

  std::size_t row_count() const { return columns.empty() ? 0 : columns[0].size(); }
  // Index of a column by name, or -1.
  int Find(const std::string& name) const;
};

// Reads a table whose lines hold finite numbers; blank lines and lines
// starting with '#' are skipped. The separator is read off the first line:
// the most frequent of comma, semicolon and tab (ties in that order), or runs
// of whitespace when it has none of them. The first line names the columns;
// when every field of it is a number it is data instead, and the columns are
// named "column 1", "column 2", ... A field in double quotes may hold the
// separator ("time, s"; "" is a quote inside it), and every column of a
// header needs a name. Decimal commas are not read ("0,5" with ';' is an
// error that says so).
// The file is read whole first (ReadFileText: a regular file, at most
// kMaxInputFileBytes); a table has at most kMaxCsvColumns columns and
// kMaxCsvRows rows of data (a curve's samples).
CsvTable ReadCsv(const std::filesystem::path& path);
// The same from text in memory; `source` names it in errors.
CsvTable ParseCsv(const std::string& text, const std::string& source);

inline constexpr std::size_t kMaxCsvColumns = 4096;
inline constexpr std::size_t kMaxCsvRows = 10'000'000;

}  // namespace phos
