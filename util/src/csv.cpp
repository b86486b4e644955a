#include "phos/util/csv.h"

#include <fstream>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {
namespace {

std::vector<std::string> SplitFields(const std::string& line) {
  std::vector<std::string> fields;
  std::size_t start = 0;
  while (true) {
    std::size_t comma = line.find(',', start);
    std::string field = line.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    // Trim spaces and a trailing carriage return (files from Windows instruments).
    std::size_t a = field.find_first_not_of(" \t\r"), b = field.find_last_not_of(" \t\r");
    fields.push_back(a == std::string::npos ? "" : field.substr(a, b - a + 1));
    if (comma == std::string::npos) return fields;
    start = comma + 1;
  }
}

}  // namespace

int CsvTable::Find(const std::string& name) const {
  for (std::size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return static_cast<int>(i);
  return -1;
}

CsvTable ReadCsv(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) ThrowUserError(path.string(), "", "cannot open the file for reading");
  CsvTable table;
  table.source = path.string();
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
    std::vector<std::string> fields = SplitFields(line);
    if (table.header.empty()) {
      table.header = fields;
      table.columns.resize(fields.size());
      continue;
    }
    if (fields.size() != table.header.size())
      ThrowUserError(table.source, "line " + std::to_string(line_number),
                     "expected " + std::to_string(table.header.size()) + " columns, got " + std::to_string(fields.size()));
    for (std::size_t c = 0; c < fields.size(); ++c) {
      double v = 0;
      if (!ParseDouble(fields[c], &v))
        ThrowUserError(table.source, "line " + std::to_string(line_number) + ", column " + table.header[c],
                       "expected a finite number, got \"" + fields[c] + "\"");
      table.columns[c].push_back(v);
    }
  }
  if (table.header.empty()) ThrowUserError(table.source, "", "empty file (expected a header line)");
  return table;
}

}  // namespace phos
