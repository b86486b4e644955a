#pragma once
// Numeric CSV tables with a header line (simulate output, decay curves from
// any instrument). Errors name the file, the line and the column.

#include <filesystem>
#include <string>
#include <vector>

namespace phos {

struct CsvTable {
  std::string source;
  std::vector<std::string> header;
  std::vector<std::vector<double>> columns;  // columns[c][row]

  std::size_t row_count() const { return columns.empty() ? 0 : columns[0].size(); }
  // Index of a column by name, or -1.
  int Find(const std::string& name) const;
};

// Reads a file whose first line names the columns and whose other lines hold
// finite numbers; blank lines and lines starting with '#' are skipped.
CsvTable ReadCsv(const std::filesystem::path& path);

}  // namespace phos
