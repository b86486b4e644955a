#include "phos/util/digest.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

#include <xxhash.h>

#include "phos/util/error.h"

namespace phos {

std::uint64_t Xxh3(const void* data, std::size_t size) { return XXH3_64bits(data, size); }

std::string Xxh3Hex(const void* data, std::size_t size) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(Xxh3(data, size)));
  return text;
}

FileDigest DigestFile(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) ThrowUserError(path.string(), "", std::string("cannot open: ") + std::strerror(errno));
  XXH3_state_t* state = XXH3_createState();
  XXH3_64bits_reset(state);
  FileDigest digest;
  // 64 KiB reads, left uninitialized: a frame is a few KiB, and a zeroed
  // 1 MiB buffer per file was most of what a fit spent checking its frames
  // (a fresh mapping, page-faulted and cleared, for every one).
  constexpr std::size_t kChunkBytes = std::size_t{1} << 16;
  const std::unique_ptr<char[]> buffer = std::make_unique_for_overwrite<char[]>(kChunkBytes);
  for (;;) {
    const ssize_t n = ::read(fd, buffer.get(), kChunkBytes);
    if (n < 0) {
      ::close(fd);
      XXH3_freeState(state);
      ThrowUserError(path.string(), "", std::string("cannot read: ") + std::strerror(errno));
    }
    if (n == 0) break;
    XXH3_64bits_update(state, buffer.get(), static_cast<std::size_t>(n));
    digest.size_bytes += static_cast<std::uint64_t>(n);
  }
  ::close(fd);
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(XXH3_64bits_digest(state)));
  XXH3_freeState(state);
  digest.xxh3 = text;
  return digest;
}

}  // namespace phos
