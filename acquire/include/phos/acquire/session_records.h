#pragma once
// The records of a capture session (docs/capture.md, "The record format"):
// typed, with ToJson/FromJson, owned here and used by every reader (capture
// resume and verify, fit session, fit map, fit batch), so a missing or
// mistyped key is one line naming the file, the line and the key.
//
//   session.json   SessionRecord  the start: protocol, sample, devices, settings
//   frames.jsonl   FrameRecord    one line per frame kept, with its file's size and checksum
//   events.jsonl   (free-form)    light switches and other events, each one JSON object
//   stop.json      StopRecord     how it ended, and how many frames frames.jsonl lists
//
// Each record carries its own checksum, "record_xxh3" (see "Record
// checksums" below), so a number changed after it was written (an
// exposure_s multiplied by hand, a bit flipped on disk) is found, not fitted.
//
// JSON Lines files are append-only: each record is one write of one whole
// line, then fsync. A crash inside that write leaves a last line without
// its newline (torn); readers skip it and say so, and the writer that goes on
// (resume) moves it aside into <file>.torn first, so it never glues a new
// record onto it. Any other line that is not a JSON object is corruption.
//
// This library reads records and checks frame files by size and checksum
// only (no image decoding), so fits can check the frames they use without
// linking an image library.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/util/digest.h"

namespace phos {

// ---- JSON Lines ------------------------------------------------------------

struct JsonLine {
  int line = 0;  // 1-based line number in its file
  nlohmann::json value;
};

struct JsonLinesFile {
  std::vector<JsonLine> records;  // every whole line, each a JSON object
  // A last line cut short by a crash (no newline at its end): its text,
  // its line number, and where the whole lines end (bytes).
  std::optional<std::string> torn;
  int torn_line = 0;
  std::uint64_t whole_bytes = 0;
};

// Reads path (a missing file has no records). A whole line that is not a
// JSON object is a UserError naming path:line; so is a file over
// kMaxRecordFileBytes.
JsonLinesFile ReadJsonLinesFile(const std::filesystem::path& path);
inline constexpr std::uint64_t kMaxRecordFileBytes = std::uint64_t{1} << 30;

// Moves a torn last line aside: appends its text to <path>.torn and cuts
// path back to its whole lines (both fsync'ed). Returns the .torn path.
std::filesystem::path SetAsideTornLine(const std::filesystem::path& path, const JsonLinesFile& file);

// Appends one record as one whole line and fsyncs it. A write that fails
// half-way (a full disk) is cut back off, so the file ends with its last
// whole record; the UserError names path.
void AppendJsonLine(const std::filesystem::path& path, const nlohmann::json& record);

// ---- frames.jsonl ----------------------------------------------------------

// Exposures a frame record may carry: a microsecond to a day. Outside it a
// record is refused (5e-324 s made every pixel of a map NaN).
inline constexpr double kMinExposureS = 1e-6;
inline constexpr double kMaxExposureS = 86400;

// The keys of a frame record that are the record's own (FrameRecord); the
// others are its protocol's fields (protocol_records.h).
inline constexpr const char* kFrameRecordKeys[] = {"file",
                                                   "seq",
                                                   "t_start_s",
                                                   "exposure_s",
                                                   "gain",
                                                   "black_level_dn",
                                                   "adc_bits",
                                                   "sensor_temperature_c",
                                                   "camera_timestamp_ns",
                                                   "run",
                                                   "size_bytes",
                                                   "xxh3",
                                                   "packets_resent",
                                                   "retakes",
                                                   "record_xxh3"};

struct FrameRecord {
  std::string file;      // frames/NNNNNN.tif, relative to the session folder
  int seq = 0;           // 1, 2, ...: the NNNNNN of file
  double t_start_s = 0;  // exposure start on the protocol's clock
  double exposure_s = 0;
  double gain = 1;
  double black_level_dn = 0;
  int adc_bits = 16;
  double sensor_temperature_c = 0;
  std::uint64_t camera_timestamp_ns = 0;  // 0: the camera gave none
  // What the camera link took to deliver the frame whole: packets resent on
  // request, and frames retaken because one arrived incomplete. Absent in
  // sessions recorded before they were counted (read as 0).
  std::uint64_t packets_resent = 0;
  int retakes = 0;
  // The file's size and XXH3-64, written after the file was complete on
  // disk. Absent in sessions recorded before phos 0.2 (then only the file's
  // presence and, in resume and verify, its decoding are checked).
  std::optional<std::uint64_t> size_bytes;
  std::string xxh3;
  // The run of the session that took it: 0 for the first, n after its n-th
  // resume. Each run's clock (t_start_s, and a protocol's light_off_s)
  // starts anew, so times compare within a run only. Written when not 0;
  // absent in sessions recorded before runs were counted (read as 0).
  int run = 0;
  // Everything the protocol added (light, charge_s, delay_after_light_off_s,
  // tail, kind, mean_signal_dn, ...), read by the fits with these records.
  nlohmann::json protocol = nlohmann::json::object();

  nlohmann::json ToJson() const;
  // where: "dir/frames.jsonl:12", for the error.
  static FrameRecord FromJson(const nlohmann::json& j, const std::string& where);
};

struct FrameRecords {
  std::vector<FrameRecord> frames;
  std::vector<int> lines;           // each frame's line number in frames.jsonl
  std::optional<std::string> torn;  // a torn last line, skipped
};

// frames.jsonl of a session folder, typed. Frames out of order or listed
// twice are a UserError (a record is written once, after its file).
FrameRecords ReadFrameRecords(const std::filesystem::path& session_dir);

// What is wrong with a frame's file against its record: "" when it exists,
// is a regular file, and has the recorded size and checksum (when recorded).
std::string CheckFrameFile(const std::filesystem::path& session_dir, const FrameRecord& frame);

// Checks every listed frame's file (CheckFrameFile); the first bad one is a
// UserError naming the frame and what is wrong. For the fits, which must
// never be built on a bad frame.
void RequireGoodFrames(const std::filesystem::path& session_dir, const FrameRecords& records);

// ---- session.json ----------------------------------------------------------

// ---- record checksums -------------------------------------------------------

// Every record a session writes (session.json, each line of frames.jsonl and
// events.jsonl, stop.json) carries "record_xxh3": the XXH3-64 of the record's
// compact JSON text without that key, keys in sorted order (nlohmann::json's
// own dump, which gives back the same text for a parsed record: numbers
// print in their shortest round-trip form). The frame file's xxh3 protects
// the pixels; this protects the numbers fits use (exposure_s,
// mean_signal_dn, charge_s, ...). Sessions of schema kSessionSchema (from
// phos 0.3) have it on every record; those of "phos.session/1" have none and
// are read as before.
inline constexpr const char* kRecordChecksumKey = "record_xxh3";
inline constexpr const char* kSessionSchema = "phos.session/2";
inline constexpr const char* kSessionSchemaWithoutChecksums = "phos.session/1";

// The checksum of a record (its "record_xxh3", if any, left out).
std::string RecordChecksum(const nlohmann::json& record);
// The record with its "record_xxh3" set.
nlohmann::json WithRecordChecksum(nlohmann::json record);
// What a record's "record_xxh3" says of it: "" when it matches, else the
// problem ("has no record_xxh3", "does not match its record_xxh3 ...").
std::string RecordChecksumProblem(const nlohmann::json& record);

// Every record of a session folder whose checksum is wrong, or missing in a
// session that must have them (kSessionSchema), and every frame record that
// gives no size_bytes and xxh3 for its file (nothing could then tell a
// replaced frame): one line each, naming file:line. For `capture verify`.
std::vector<std::string> RecordChecksumProblems(const std::filesystem::path& session_dir);
// The first of them as a UserError, for the fits and resume, which are never
// built on a record that changed after it was written.
void RequireRecordChecksums(const std::filesystem::path& session_dir);

// ---- session.json ----------------------------------------------------------

struct SessionRecord {
  std::string schema = kSessionSchema;
  std::string protocol;  // lvf-calibration, spectrum, decay, excitation, all
  std::string uid, started_utc, phos_version;
  nlohmann::json sample = nlohmann::json::object();
  nlohmann::json devices = nlohmann::json::object();
  nlohmann::json settings = nlohmann::json::object();
  std::string part_of;  // the `all` folder this part belongs to ("" if none)
  int resume = 0;       // a part started anew by the n-th resume of its folder

  nlohmann::json ToJson() const;
  static SessionRecord FromJson(const nlohmann::json& j, const std::string& where);
};
SessionRecord ReadSessionRecord(const std::filesystem::path& session_dir);

// ---- stop.json -------------------------------------------------------------

struct StopRecord {
  std::string how;  // complete, aborted, failed
  std::string why;
  int frames = 0;  // the frame records frames.jsonl held when it stopped
  std::string stopped_utc;

  nlohmann::json ToJson() const;
  static StopRecord FromJson(const nlohmann::json& j, const std::string& where);
};
// nullopt when there is none (killed, or still running).
std::optional<StopRecord> ReadStopRecord(const std::filesystem::path& session_dir);

// ---- events.jsonl ----------------------------------------------------------

// The events of a session, each an object with a string "event" (a torn last
// line is skipped).
std::vector<nlohmann::json> ReadEventRecords(const std::filesystem::path& session_dir);

// Reads a required key of a record, naming the file and the key when it is
// missing or of the wrong type: RequiredKey<double>(j, "exposure_s", where).
template <typename T>
T RequiredKey(const nlohmann::json& j, const char* key, const std::string& where);

}  // namespace phos
