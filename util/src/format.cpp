#include "phos/util/format.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <system_error>

namespace phos {

std::string FormatDouble(double value) {
  if (std::isnan(value)) return "nan";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  char buffer[64];
  auto [end, ec] = std::to_chars(buffer, buffer + sizeof buffer, value);
  if (ec != std::errc()) return "nan";
  return std::string(buffer, end);
}

std::string FormatShort(double value, int digits) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*g", digits, value);
  return buffer;
}

double RoundDownSignificant(double value, int digits) {
  if (!(value > 0) || !std::isfinite(value)) return value;
  const double scale = std::pow(10.0, digits - 1 - static_cast<int>(std::floor(std::log10(value))));
  double rounded = std::floor(value * scale) / scale;
  if (rounded > value) rounded = std::nextafter(rounded, 0.0);  // guard against the division rounding up
  return rounded;
}

bool ParseDouble(const std::string& text, double* value) {
  if (text.empty()) return false;
  const char* first = text.data();
  const char* last = first + text.size();
  if (*first == '+') ++first;
  auto [end, ec] = std::from_chars(first, last, *value);
  return ec == std::errc() && end == last && std::isfinite(*value);
}

bool ParseDoubleList(const std::string& text, std::vector<double>* values, std::string* bad) {
  values->clear();
  std::size_t start = 0;
  while (true) {
    std::size_t comma = text.find(',', start);
    std::string item = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    double v = 0;
    if (!ParseDouble(item, &v)) {
      *bad = item;
      return false;
    }
    values->push_back(v);
    if (comma == std::string::npos) return true;
    start = comma + 1;
  }
}

}  // namespace phos
