#include "phos/util/image_file.h"

#include <memory>

#include "phos/util/atomic_file.h"
#include "phos/util/error.h"

namespace phos {

void WriteImageAtomically(const std::filesystem::path& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                          const void* data, const std::function<void(const std::filesystem::path&)>& after_close) {
  WriteAtomically(path, [&](const std::filesystem::path& temporary) {
    auto out = OIIO::ImageOutput::create(temporary.string());
    if (!out) ThrowUserError(path.string(), "", "no image writer for this format: " + OIIO::geterror());
    if (!out->open(temporary.string(), spec) || !out->write_image(type, data) || !out->close())
      ThrowUserError(path.string(), "", "could not write the image (disk full?): " + out->geterror());
    if (after_close) after_close(temporary);
  });
}

}  // namespace phos
