#pragma once
// Numbers as text: the shortest form that reads back to the same double, so
// CSV and JSON output lose nothing and stay readable (0.1, not 0.10000000000000001).

#include <string>
#include <vector>

namespace phos {

std::string FormatDouble(double value);
// Parses a whole string as a finite double; false if it is not one.
bool ParseDouble(const std::string& text, double* value);
// Parses "a" or "a,b,c" into numbers; false (and *bad = offending item) on error.
bool ParseDoubleList(const std::string& text, std::vector<double>* values, std::string* bad);

}  // namespace phos
