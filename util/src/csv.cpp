#include "phos/util/csv.h"

#include <algorithm>
#include <sstream>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos {
namespace {

constexpr const char* kBlank = " \t\r";

// The separator of a table, from its first line (see ReadCsv).
char DetectSeparator(const std::string& line) {
  char best = ' ';
  std::ptrdiff_t best_count = 0;
  for (char candidate : {',', ';', '\t'}) {
    const std::ptrdiff_t count = std::count(line.begin(), line.end(), candidate);
    if (count > best_count) {
      best = candidate;
      best_count = count;
    }
  }
  return best;
}

// At most kMaxCsvColumns + 1 fields: one more than the limit is enough to refuse the line.
std::vector<std::string> SplitFields(const std::string& line, char separator) {
  std::vector<std::string> fields;
  if (separator == ' ') {
    // Runs of spaces and tabs are one separator (aligned columns).
    for (std::size_t a = line.find_first_not_of(kBlank); a != std::string::npos && fields.size() <= kMaxCsvColumns;
         a = line.find_first_not_of(kBlank, a)) {
      const std::size_t b = line.find_first_of(kBlank, a);
      fields.push_back(line.substr(a, b == std::string::npos ? std::string::npos : b - a));
      a = b;
    }
    return fields;
  }
  std::size_t start = 0;
  while (true) {
    // A field in double quotes (RFC 4180, as spreadsheets write a header
    // such as "time, s") may hold the separator; "" inside it is one quote.
    const std::size_t first = line.find_first_not_of(kBlank, start);
    std::string quoted;
    std::size_t after_quote = std::string::npos;
    if (first != std::string::npos && line[first] == '"') {
      std::size_t i = first + 1;
      for (; i < line.size(); ++i) {
        if (line[i] != '"') {
          quoted += line[i];
        } else if (i + 1 < line.size() && line[i + 1] == '"') {
          quoted += '"';
          ++i;
        } else {
          break;
        }
      }
      if (i < line.size()) after_quote = i + 1;  // an unclosed quote is read as plain text
    }
    std::size_t end = line.find(separator, after_quote == std::string::npos ? start : after_quote);
    if (after_quote != std::string::npos) {
      fields.push_back(quoted);
    } else {
      std::string field = line.substr(start, end == std::string::npos ? std::string::npos : end - start);
      // Trim spaces and a trailing carriage return (files from Windows instruments).
      std::size_t a = field.find_first_not_of(kBlank), b = field.find_last_not_of(kBlank);
      fields.push_back(a == std::string::npos ? "" : field.substr(a, b - a + 1));
    }
    if (end == std::string::npos || fields.size() > kMaxCsvColumns) return fields;
    start = end + 1;
  }
}

bool AllNumbers(const std::vector<std::string>& fields) {
  double v = 0;
  return std::all_of(fields.begin(), fields.end(), [&](const std::string& f) { return ParseDouble(f, &v); });
}

}  // namespace

int CsvTable::Find(const std::string& name) const {
  for (std::size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return static_cast<int>(i);
  return -1;
}

CsvTable ReadCsv(const std::filesystem::path& path) { return ParseCsv(ReadFileText(path), path.string()); }

CsvTable ParseCsv(const std::string& text, const std::string& source) {
  std::istringstream in(text);
  CsvTable table;
  table.source = source;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.find_first_not_of(kBlank) == std::string::npos || line[0] == '#') continue;
    if (table.header.empty()) table.separator = DetectSeparator(line);
    std::vector<std::string> fields = SplitFields(line, table.separator);
    if (fields.size() > kMaxCsvColumns)
      ThrowUserError(table.source, "line " + std::to_string(line_number),
                     "more than the limit of " + std::to_string(kMaxCsvColumns) + " columns");
    if (table.header.empty()) {
      table.columns.resize(fields.size());
      if (!AllNumbers(fields)) {
        for (std::size_t c = 0; c < fields.size(); ++c)
          if (fields[c].empty())
            ThrowUserError(table.source, "line " + std::to_string(line_number),
                           "header: column " + std::to_string(c + 1) + " of " + std::to_string(fields.size()) +
                               " has no name" +
                               (c + 1 == fields.size() ? " (a separator at the end of the line?)" : ""));
        table.header = fields;
        continue;
      }
      table.has_header = false;
      for (std::size_t c = 0; c < fields.size(); ++c) table.header.push_back("column " + std::to_string(c + 1));
    }
    if (table.row_count() >= kMaxCsvRows)
      ThrowUserError(table.source, "line " + std::to_string(line_number),
                     "more than the limit of " + std::to_string(kMaxCsvRows) + " rows");
    if (fields.size() != table.header.size())
      ThrowUserError(
          table.source, "line " + std::to_string(line_number),
          "expected " + std::to_string(table.header.size()) + " columns, got " + std::to_string(fields.size()));
    for (std::size_t c = 0; c < fields.size(); ++c) {
      double v = 0;
      if (!ParseDouble(fields[c], &v)) {
        const bool decimal_comma = table.separator != ',' && fields[c].find(',') != std::string::npos;
        ThrowUserError(table.source, "line " + std::to_string(line_number) + ", column " + table.header[c],
                       "expected a finite number, got \"" + fields[c] + "\"" +
                           (decimal_comma ? " (decimal commas are not read: write 0.5, not 0,5)" : ""));
      }
      table.columns[c].push_back(v);
    }
  }
  if (table.header.empty()) ThrowUserError(table.source, "", "empty file (expected a header line)");
  return table;
}

}  // namespace phos
