#pragma once
// The one way phos reports a mistake in what the user gave it (a file, an
// option, a field, a request). Every loader and command throws UserError with
// a message that names where the mistake is; the `phos` command prints it as
// one line and exits with code 2 (docs/design.md, "Errors").
//
// Message form: "<where>: <field>: <what is wrong>", for example
//   fixtures/materials/green.json: states[0].kr: expected a number >= 0, got -1
// Invariants of phos itself are not user errors: they are checked with
// PHOS_CHECK, which aborts with the file and line.

#include <stdexcept>
#include <string>
#include <string_view>

namespace phos {

class UserError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Throws UserError("<where>: <field>: <message>"); an empty where or field is left out.
[[noreturn]] void ThrowUserError(std::string_view where, std::string_view field, std::string_view message);

[[noreturn]] void CheckFailed(const char* file, int line, const char* condition);

}  // namespace phos

// For invariants (programming errors), not for user input.
#define PHOS_CHECK(condition)                                              \
  do {                                                                     \
    if (!(condition)) ::phos::CheckFailed(__FILE__, __LINE__, #condition); \
  } while (false)
