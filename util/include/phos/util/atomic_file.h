#pragma once
// The one way phos replaces a file: whole or not at all. A crash, a full disk
// or a failed writer leaves the old file (or none), never a part of the new.
// The bytes go to a temporary beside the file, "<name>.tmp.<pid><ext>" (the
// extension kept for writers that choose the format by it, as OpenImageIO
// does), then it is renamed over the file. The temporary is created afresh:
// a stale one, or a symlink planted at its name, is unlinked first (never
// followed), and it is opened with O_EXCL | O_NOFOLLOW.

#include <filesystem>
#include <functional>
#include <span>
#include <string_view>

namespace phos {

struct AtomicWriteOptions {
  // fsync the temporary before the rename and the folder after it: the
  // rename then survives a power cut too (the capture's records and frames).
  bool sync = false;
};

// Missing folders of `path` are made first.
// `write` fills the temporary it is given (a regular file, empty, just
// created); it throws on failure, and then the temporary is removed and the
// error goes on to the caller with `path` unchanged.
void WriteAtomically(const std::filesystem::path& path,
                     const std::function<void(const std::filesystem::path& temporary)>& write,
                     const AtomicWriteOptions& options = {});

// Text (JSON, CSV, SVG) whole or not at all.
void WriteFileAtomically(const std::filesystem::path& path, std::string_view text,
                         const AtomicWriteOptions& options = {});

// The temporary's name for `path` (what WriteAtomically writes to; a resume
// recognises such names as leftovers by ".tmp.").
std::filesystem::path AtomicTemporaryPath(const std::filesystem::path& path);

// An output folder a command will create or write into: a file already at
// `path` is a UserError naming `option` ("'X' is a file, not a folder"), so
// that a check (phos render --check, fit map, fit batch) refuses it before
// any work; so is a folder that cannot be made or written (as for
// RequireOutputFile).
void RequireFolderOrNothing(const std::filesystem::path& path, std::string_view option);

// The 8-bit images phos writes through OpenImageIO (frames' PNGs, contact
// sheets): it picks the format by the extension, so these are the names it can write.
inline constexpr std::string_view kImageExtensions[] = {".png", ".jpg", ".jpeg", ".tif", ".tiff"};
inline constexpr std::string_view kSvgExtension[] = {".svg"};

// An output file a command will write (a material, report, plot, contact
// sheet), checked at the command's start: a long fit or render must not end
// in a refusal with nothing written (nor part of its outputs). A UserError
// naming `option` when `path` is a folder (or ends in '/'), has none of
// `extensions` (if any are given; any case), or lies under a file or a folder
// that cannot be written. Its folders need not exist: WriteAtomically makes
// them. An empty path (the option not given) passes.
void RequireOutputFile(const std::filesystem::path& path, std::string_view option,
                       std::span<const std::string_view> extensions = {});

// fsync a file (UserError naming it when the disk refuses) and a folder (its
// entries: a rename made durable).
void SyncFile(const std::filesystem::path& path);
void SyncDirectory(const std::filesystem::path& dir);

}  // namespace phos
