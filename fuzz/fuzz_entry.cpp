// The libFuzzer entry point of one harness: PHOS_FUZZ_TARGET names the
// function of targets.h it runs (fuzz/CMakeLists.txt builds one executable
// per target).

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "targets.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  phos::fuzz::PHOS_FUZZ_TARGET(std::string_view(reinterpret_cast<const char*>(data), size));
  return 0;
}
