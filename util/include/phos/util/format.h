#pragma once
// Numbers as text: the shortest form that reads back to the same double, so
// CSV and JSON output lose nothing and stay readable (0.1, not 0.10000000000000001).

#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace phos {

std::string FormatDouble(double value);
// For messages a person reads: `digits` significant digits (%g), e.g. 1.506.
std::string FormatShort(double value, int digits = 4);
// The largest number with `digits` significant digits that is <= value (> 0),
// e.g. 0.4649 -> 0.46: a limit to suggest that is safely inside the true one.
double RoundDownSignificant(double value, int digits = 2);
// Each item of `items` as text (`to_text`, the item itself by default),
// joined by `separator` ("" for no items).
template <class Items, class ToText = std::identity>
std::string Join(const Items& items, std::string_view separator, ToText to_text = {}) {
  std::string list;
  for (const auto& item : items) {
    if (!list.empty()) list += separator;
    list += std::invoke(to_text, item);
  }
  return list;
}
// "a, b, c", for messages.
template <class Items, class ToText = std::identity>
std::string JoinComma(const Items& items, ToText to_text = {}) {
  return Join(items, ", ", to_text);
}
// Text from a file or a request made safe to print or to write into SVG: a
// control character (a newline, ESC, NUL) becomes \n, \r, \t or \xHH, and a
// byte that is not part of valid UTF-8 \xHH; the rest is kept. What reaches
// a terminal cannot move its cursor or split a line, and an SVG stays XML.
std::string Printable(std::string_view text);
// For "did you mean" in messages: the candidate fewest edits away from `word`
// (an insertion, deletion, substitution or swap of neighbours counts one:
// the optimal string alignment distance), if it is at most a third of the
// word's length (at least 1); "" when none is that close. Ties go to the first.
std::string Closest(std::string_view word, const std::vector<std::string>& candidates);
// Parses a whole string as a finite double; false if it is not one.
bool ParseDouble(const std::string& text, double* value);
// Parses "a" or "a,b,c" into numbers; false (and *bad = offending item) on error.
bool ParseDoubleList(const std::string& text, std::vector<double>* values, std::string* bad);

}  // namespace phos
