// decay-map.exr's pixels and headers, written and merged (decay_map_file.h).
// Apart from decay_map_file.cpp, which the fuzz harnesses build alone to read
// maps.

#include <algorithm>

#include "phos/fit/decay_map.h"
#include "phos/fit/decay_map_file.h"
#include "phos/util/error.h"
#include "phos/util/image_file.h"

namespace phos::fit {

namespace {
// Header attributes of a tile, for the merge.
constexpr const char* kMapHeight = "phos:map_height";
constexpr const char* kPixelsWithoutDecay = "phos:pixels_without_decay";
constexpr const char* kPixelsWithOneState = "phos:pixels_with_one_state";
constexpr const char* kFrames = "phos:frames";
constexpr const char* kClippedFrames = "phos:clipped_frames";
constexpr const char* kSeconds = "phos:seconds";

OIIO::ImageSpec MapSpec(const DecayMapImage& map, int height) {
  OIIO::ImageSpec spec(map.width, height, static_cast<int>(map.names.size()), OIIO::TypeDesc::FLOAT);
  spec.channelnames = map.names;
  spec.attribute("compression", "zip");
  return spec;
}
}  // namespace

bool DecayMapImage::two_states() const { return std::find(names.begin(), names.end(), kDecayMapKr2) != names.end(); }

DecayMapImage PackDecayMap(const DecayMap& map, const std::vector<std::string>& camera_channels) {
  const bool two_states = !map.kr2.empty();
  DecayMapImage image;
  image.width = map.width;
  image.height = map.height;
  image.names = DecayMapChannelNames(camera_channels, two_states);
  image.no_decay = map.no_decay;
  image.one_state = map.one_state;
  image.seconds = map.seconds;
  const int C = map.channels, nch = 2 + 2 * C + (two_states ? 1 + C : 0);
  PHOS_CHECK(image.names.size() == static_cast<std::size_t>(nch));
  const std::size_t pixels = static_cast<std::size_t>(map.width) * map.height;
  image.pixels.resize(pixels * nch);
  for (std::size_t p = 0; p < pixels; ++p) {
    float* out = &image.pixels[p * nch];
    out[0] = map.kr[p];
    for (int c = 0; c < C; ++c) {
      out[1 + c] = map.amplitude[p * C + c];
      out[1 + C + c] = map.background[p * C + c];
    }
    out[1 + 2 * C] = map.rms[p];
    if (two_states) {
      out[2 + 2 * C] = map.kr2[p];
      for (int c = 0; c < C; ++c) out[3 + 2 * C + c] = map.amplitude2[p * C + c];
    }
  }
  return image;
}

void WriteDecayMap(const std::filesystem::path& path, const DecayMapImage& map) {
  OIIO::ImageSpec spec = MapSpec(map, map.height);
  map.charge.Annotate(spec);
  WriteImageAtomically(path, spec, OIIO::TypeDesc::FLOAT, map.pixels.data());
}

void WriteDecayMapTile(const std::filesystem::path& path, const DecayMapImage& tile, int first_row, int map_height) {
  OIIO::ImageSpec spec = MapSpec(tile, tile.height);
  spec.attribute(kDecayMapFirstRow, first_row);
  spec.attribute(kMapHeight, map_height);
  spec.attribute(kPixelsWithoutDecay, static_cast<int>(tile.no_decay));
  if (tile.two_states()) spec.attribute(kPixelsWithOneState, static_cast<int>(tile.one_state));
  spec.attribute(kFrames, static_cast<int>(tile.frames));
  spec.attribute(kClippedFrames, tile.clipped);
  spec.attribute(kSeconds, static_cast<float>(tile.seconds));
  tile.charge.Annotate(spec);
  WriteImageAtomically(path, spec, OIIO::TypeDesc::FLOAT, tile.pixels.data());
}

DecayMapImage MergeDecayMapTiles(const std::vector<std::filesystem::path>& tiles) {
  DecayMapImage map;
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    const std::filesystem::path& exr = tiles[i];
    auto in = OIIO::ImageInput::open(exr.string());
    if (!in) ThrowUserError(exr.string(), "", "cannot read: " + OIIO::geterror());
    const OIIO::ImageSpec& spec = in->spec();
    const int first_row = spec.get_int_attribute(kDecayMapFirstRow, -1);
    if (i == 0) {
      map.width = spec.width;
      map.height = spec.get_int_attribute(kMapHeight, 0);
      map.names = spec.channelnames;
      map.frames = static_cast<std::size_t>(spec.get_int_attribute(kFrames, 0));
      map.clipped = spec.get_int_attribute(kClippedFrames, 0);
      map.charge = DecayMapCharge::FromSpec(spec, exr.string(), "", "");
      map.pixels.resize(static_cast<std::size_t>(map.width) * map.height * map.names.size());
    }
    if (spec.width != map.width || spec.channelnames != map.names || first_row < 0 ||
        first_row + spec.height > map.height)
      ThrowUserError(exr.string(), "", "does not fit the other tiles (size, channels or rows)");
    const std::size_t row_values = static_cast<std::size_t>(map.width) * map.names.size();
    if (!in->read_image(0, 0, 0, static_cast<int>(map.names.size()), OIIO::TypeDesc::FLOAT,
                        map.pixels.data() + first_row * row_values))
      ThrowUserError(exr.string(), "", "cannot read: " + in->geterror());
    map.no_decay += static_cast<std::size_t>(spec.get_int_attribute(kPixelsWithoutDecay, 0));
    map.one_state += static_cast<std::size_t>(spec.get_int_attribute(kPixelsWithOneState, 0));
    map.seconds += spec.get_float_attribute(kSeconds, 0.0f);
  }
  return map;
}

}  // namespace phos::fit
