#include "phos/util/error.h"

#include <cstdio>
#include <cstdlib>

#include "phos/util/format.h"

namespace phos {

void ThrowUserError(std::string_view where, std::string_view field, std::string_view message) {
  std::string text;
  if (!where.empty()) text.append(where).append(": ");
  if (!field.empty()) text.append(field).append(": ");
  text.append(message);
  // One line, whatever the input held: a value quoted from a file or a
  // request may carry a newline or a carriage return (every rejection is
  // one line: docs/design.md, "Errors"), or an escape sequence for the terminal.
  const std::string line = Printable(text);
  throw UserError(line);
}

void CheckFailed(const char* file, int line, const char* condition) {
  std::fprintf(stderr, "phos: internal error: %s:%d: check failed: %s\n", file, line, condition);
  std::abort();
}

}  // namespace phos
