#include "phos/util/error.h"

#include <cstdio>
#include <cstdlib>

namespace phos {

void ThrowUserError(std::string_view where, std::string_view field, std::string_view message) {
  std::string text;
  if (!where.empty()) text.append(where).append(": ");
  if (!field.empty()) text.append(field).append(": ");
  text.append(message);
  throw UserError(text);
}

void CheckFailed(const char* file, int line, const char* condition) {
  std::fprintf(stderr, "phos: internal error: %s:%d: check failed: %s\n", file, line, condition);
  std::abort();
}

}  // namespace phos
