#pragma once
// The one image writer of phos: a capture's frames, rendered EXR and PNG
// frames, decay maps and contact sheets are all written through it, whole or
// not at all (WriteAtomically: a temporary, then a rename). OpenImageIO picks
// the format from the extension. In a library of its own (phos_image_file),
// so only the parts that write images link OpenImageIO for it.

#include <filesystem>
#include <functional>

#include <OpenImageIO/imageio.h>

namespace phos {

// Writes `data` (of `type`, laid out as `spec` says) to `path`. `after_close`
// runs on the complete temporary before it takes the final name (a capture
// syncs and checksums its frame there). A format without a writer, or a
// write that fails (a full disk), is one line naming `path`; the old file, if
// any, is left as it was.
void WriteImageAtomically(const std::filesystem::path& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                          const void* data,
                          const std::function<void(const std::filesystem::path& temporary)>& after_close = {});

}  // namespace phos
