#include "phos/util/error.h"

#include <cstdio>
#include <cstdlib>

namespace phos {

void ThrowUserError(std::string_view where, std::string_view field, std::string_view message) {
  std::string text;
  if (!where.empty()) text.append(where).append(": ");
  if (!field.empty()) text.append(field).append(": ");
  text.append(message);
  // One line, whatever the input held: a value quoted from a file or a
  // request may carry a newline or a carriage return (issue 16: every
  // rejection is one line).
  std::string line;
  line.reserve(text.size());
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '\n')
      line += "\\n";
    else if (c == '\r')
      line += "\\r";
    else if (c == '\t')
      line += "\\t";
    else if (u < 0x20 || u == 0x7f)
      line += "\\x" + std::string(1, "0123456789abcdef"[u >> 4]) + "0123456789abcdef"[u & 15];
    else
      line += c;
  }
  throw UserError(line);
}

void CheckFailed(const char* file, int line, const char* condition) {
  std::fprintf(stderr, "phos: internal error: %s:%d: check failed: %s\n", file, line, condition);
  std::abort();
}

}  // namespace phos
