#pragma once
// Checksums of files and bytes: a capture session's frame records
// (acquire/session_records.h), a fit batch's and a render range's done
// records (what their outputs were made from).

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

namespace phos {

// XXH3-64 of a file's bytes, as 16 hex digits, and its size. XXH3 because
// the records guard against accidents (a torn write, a truncated copy, a
// flipped bit on a failing disk, a file changed since), not against an
// adversary, and it hashes at memory speed: verifying a session costs no
// more than reading it. A file that cannot be read is a UserError naming it.
struct FileDigest {
  std::uint64_t size_bytes = 0;
  std::string xxh3;
};
FileDigest DigestFile(const std::filesystem::path& path);
std::string Xxh3Hex(const void* data, std::size_t size);
// The same hash as a number; allocates nothing, so a signal handler may call it.
std::uint64_t Xxh3(const void* data, std::size_t size);

}  // namespace phos
