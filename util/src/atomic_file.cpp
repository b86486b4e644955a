#include "phos/util/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <string>

#include "phos/util/error.h"

namespace phos {

std::filesystem::path AtomicTemporaryPath(const std::filesystem::path& path) {
  std::filesystem::path temporary = path;
  temporary += ".tmp." + std::to_string(::getpid()) + path.extension().string();
  return temporary;
}

namespace {

// The nearest folder of `folder` that exists (itself, if it does) must be a
// folder this process can write into: else a UserError naming `option` and
// `path`, the output to be written there.
void RequireWritableFolderAbove(const std::filesystem::path& folder, const std::filesystem::path& path,
                                std::string_view option) {
  std::error_code ec;
  std::filesystem::path existing = folder.empty() ? "." : folder;
  while (!std::filesystem::exists(existing, ec) && existing.has_relative_path()) {
    existing = existing.parent_path();
    if (existing.empty()) existing = ".";
  }
  if (!std::filesystem::is_directory(existing, ec))
    ThrowUserError("", option,
                   "'" + path.string() + "' cannot be written: '" + existing.string() + "' is a file, not a folder");
  if (::access(existing.c_str(), W_OK | X_OK) != 0)
    ThrowUserError(
        "", option,
        "'" + path.string() + "' cannot be written: folder '" + existing.string() + "': " + std::strerror(errno));
}

}  // namespace

void RequireFolderOrNothing(const std::filesystem::path& path, std::string_view option) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_directory(path, ec))
    ThrowUserError("", option, "'" + path.string() + "' is a file, not a folder");
  RequireWritableFolderAbove(path, path, option);
}

void RequireOutputFile(const std::filesystem::path& path, std::string_view option,
                       std::span<const std::string_view> extensions) {
  if (path.empty()) return;
  std::error_code ec;
  if (!path.has_filename() || std::filesystem::is_directory(path, ec))
    ThrowUserError("", option, "'" + path.string() + "' is a folder, not a file");
  if (!extensions.empty()) {
    std::string extension = path.extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (std::find(extensions.begin(), extensions.end(), extension) == extensions.end()) {
      std::string names;
      for (std::size_t i = 0; i < extensions.size(); ++i)
        names.append(i == 0 ? "" : i + 1 == extensions.size() ? " or " : ", ").append(extensions[i]);
      ThrowUserError("", option, "'" + path.string() + "': expected a file name ending in " + names);
    }
  }
  RequireWritableFolderAbove(path.parent_path(), path, option);
}

void SyncDirectory(const std::filesystem::path& dir) {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

void SyncFile(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) ThrowUserError(path.string(), "", std::string("cannot reopen to flush: ") + std::strerror(errno));
  const bool synced = ::fsync(fd) == 0;
  ::close(fd);
  if (!synced) ThrowUserError(path.string(), "", "could not be flushed to disk (disk full?)");
}

void WriteAtomically(const std::filesystem::path& path,
                     const std::function<void(const std::filesystem::path& temporary)>& write,
                     const AtomicWriteOptions& options) {
  const std::filesystem::path temporary = AtomicTemporaryPath(path);
  if (path.has_parent_path()) {
    std::error_code ignored;  // a folder that cannot be made is named by the open below
    std::filesystem::create_directories(path.parent_path(), ignored);
  }
  ::unlink(temporary.c_str());  // a stale temporary, or a symlink planted there: removed, not followed
  const int fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
  if (fd < 0)
    ThrowUserError(path.string(), "", std::string("cannot open the file for writing: ") + std::strerror(errno));
  ::close(fd);
  const auto remove_temporary = [&] {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
  };
  try {
    write(temporary);
    if (options.sync) SyncFile(temporary);
  } catch (...) {
    remove_temporary();
    throw;
  }
  std::error_code ec;
  std::filesystem::rename(temporary, path, ec);
  if (ec) {
    remove_temporary();
    ThrowUserError(path.string(), "", "cannot replace the file: " + ec.message());
  }
  if (options.sync) SyncDirectory(path.parent_path());
}

void WriteFileAtomically(const std::filesystem::path& path, std::string_view text, const AtomicWriteOptions& options) {
  WriteAtomically(
      path,
      [&](const std::filesystem::path& temporary) {
        const int fd = ::open(temporary.c_str(), O_WRONLY | O_TRUNC | O_NOFOLLOW | O_CLOEXEC);
        if (fd < 0)
          ThrowUserError(path.string(), "", std::string("cannot open the file for writing: ") + std::strerror(errno));
        std::size_t written = 0;
        while (written < text.size()) {
          const ssize_t n = ::write(fd, text.data() + written, text.size() - written);
          if (n < 0 && errno == EINTR) continue;
          if (n <= 0) {
            ::close(fd);
            ThrowUserError(path.string(), "", "writing failed (disk full?)");
          }
          written += static_cast<std::size_t>(n);
        }
        if (::close(fd) != 0) ThrowUserError(path.string(), "", "writing failed (disk full?)");
      },
      options);
}

}  // namespace phos
