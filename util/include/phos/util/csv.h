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
// named "column 1", "column 2", ... Decimal commas are not read ("0,5" with
// ';' is an error that says so).
CsvTable ReadCsv(const std::filesystem::path& path);

}  // namespace phos
