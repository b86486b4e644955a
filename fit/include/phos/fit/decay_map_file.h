#pragma once
// decay-map.exr, the file `phos fit map` writes (docs/formats.md, "Decay
// maps"): its channels' names and the charge its header records, written
// here once for the writer (app/cmd_fit.cpp) and every reader (the merge of
// tiles, the renderer's phosphor maps, render/phosphor_map.h). Its own
// library (phos_decay_map_file), so that a reader links OpenImageIO and
// nothing of the fits.

#include <filesystem>
#include <string>
#include <vector>

#include <OpenImageIO/imageio.h>

namespace phos {
struct DecayMap;
}  // namespace phos

namespace phos::fit {

// Channels: kr, then amplitude.<c> and background.<c> per camera channel c,
// then rms; a two-state map then kr2 and amplitude2.<c> (1/s, DN/s).
inline constexpr const char* kDecayMapKr = "kr";
inline constexpr const char* kDecayMapAmplitude = "amplitude.";  // + the camera channel's name
inline constexpr const char* kDecayMapBackground = "background.";
inline constexpr const char* kDecayMapRms = "rms";
inline constexpr const char* kDecayMapKr2 = "kr2";
inline constexpr const char* kDecayMapAmplitude2 = "amplitude2.";

// The channel names of a map of these camera channels, in the file's order.
std::vector<std::string> DecayMapChannelNames(const std::vector<std::string>& camera_channels, bool two_states);

// A tile of a map (phos fit map --tile) records its first row; a whole map
// does not.
inline constexpr const char* kDecayMapFirstRow = "phos:first_row";

// How the session charged the sample before the decay: its charge time and
// the lab's calibrated band irradiance of the charge light (W/m^2 per
// band). A renderer that takes the map as a phosphor needs it to tell a
// texel's level from its charge. Empty irradiance: not recorded.
struct DecayMapCharge {
  float charge_s = 0;
  std::vector<float> band_irradiance;

  bool recorded() const { return !band_irradiance.empty(); }
  // phos:charge_s and phos:charge_band_irradiance; nothing when not recorded.
  void Annotate(OIIO::ImageSpec& spec) const;
  // The charge a header records, or none. One line (ThrowUserError at
  // where / field, after `subject`) when it records one that is not floats,
  // or not finite and positive.
  static DecayMapCharge FromSpec(const OIIO::ImageSpec& spec, const std::string& where, const std::string& field,
                                 const std::string& subject);
};

// A map's parameter image as decay-map.exr holds it: DecayMapChannelNames'
// channels interleaved per pixel, with what its header records.
struct DecayMapImage {
  int width = 0, height = 0;
  std::vector<std::string> names;
  std::vector<float> pixels;
  std::size_t no_decay = 0;   // pixels without a decay
  std::size_t one_state = 0;  // two states: decaying pixels where one state sufficed
  std::size_t frames = 0;
  int clipped = 0;  // clipped frames left out
  double seconds = 0;
  DecayMapCharge charge;

  bool two_states() const;
};

// Packs a fitted map (decay_map.h) of these camera channels.
DecayMapImage PackDecayMap(const DecayMap& map, const std::vector<std::string>& camera_channels);

// decay-map.exr of a whole map: its channels (zip) and the charge.
void WriteDecayMap(const std::filesystem::path& path, const DecayMapImage& map);
// A tile of a map (phos fit map --tile): its rows from first_row of a map
// map_height rows high, and its counts, for the merge.
void WriteDecayMapTile(const std::filesystem::path& path, const DecayMapImage& tile, int first_row, int map_height);
// The tiles of one map, in any order, merged: a tile that does not fit the
// others (size, channels, rows) or does not read is one line naming it.
DecayMapImage MergeDecayMapTiles(const std::vector<std::filesystem::path>& tiles);

}  // namespace phos::fit
