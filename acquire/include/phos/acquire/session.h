#pragma once
// Capture sessions: directories written as they go (docs/capture.md), so a crash,
// a kill -9 or a full disk loses nothing already recorded.
//
//   session.json   start record: protocol, sample, devices, settings, versions, uid
//   frames.jsonl   one line per frame kept: file, seq, times, exposure, gain,
//                  black level, and the file's size and XXH3 checksum
//   events.jsonl   light switches and other events, with monotonic times
//   frames/        raw frames, lossless 16-bit TIFF
//   stop.json      how it ended: complete, aborted (signal), failed (why),
//                  and how many frames frames.jsonl lists; on SIGINT/SIGTERM
//                  (with a LightsOffGuard alive) the handler writes "aborted"
//                  after switching the lights off
//
// The records are typed in session_records.h. A frame file is complete on
// disk (temporary name, fsync, rename, fsync of the folder) before its line
// is written; every line is one write, then fsync, and a write that fails
// half-way is cut back off, so the files always end with whole records.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "phos/acquire/camera.h"
#include "phos/acquire/session_records.h"

namespace phos {

// What a session's records and frames hold, checked (capture verify, resume).
struct SessionCheck {
  struct BadFrame {
    FrameRecord frame;
    int line = 0;
    std::string problem;  // "is missing", "has checksum ... where its record says ..."
  };
  std::string protocol;
  int frames = 0;  // records in frames.jsonl
  std::optional<StopRecord> stop;
  std::vector<BadFrame> bad_frames;
  bool torn_frames = false, torn_events = false;  // a torn last line
  std::vector<std::filesystem::path> stale_temporaries;
  // Every problem as one line naming its file ("" prefix-free).
  std::vector<std::string> problems;
  // Those of `problems` that resume cannot mend: a record that does not read
  // as its type, a frame list missing under a complete stop. Resume mends the
  // rest (torn last lines, bad frames of a part that can be remeasured, a
  // stop record's miscount).
  std::vector<std::string> unrepairable;

  bool complete() const { return stop && stop->how == "complete"; }
  bool clean() const { return problems.empty(); }
};

// Checks a session folder (one part; not the parts of an `all` folder):
// every record parses as its type, every listed frame exists with its
// recorded size and checksum and (decode_frames) reads as an image of the
// session's size, stop.json counts what frames.jsonl lists, and a part that
// says it is complete has its frame list. Malformed records are problems,
// not exceptions.
SessionCheck CheckSession(const std::filesystem::path& dir, bool decode_frames = true);

class SessionWriter {
 public:
  // Creates `dir` (which must not exist, or be empty) and writes session.json.
  SessionWriter(std::filesystem::path dir, nlohmann::json start_record);
  // Reopens an interrupted session to go on with it. First it repairs what a
  // crash leaves: a torn last line of frames.jsonl or events.jsonl goes into
  // <file>.torn, stale temporaries are removed, and frames whose files are
  // bad (CheckSession) are set aside (SetAsideBadFrames) when
  // `set_aside_bad_frames`, else they are a UserError. Frames are numbered
  // on from the last one recorded or present on disk (never overwritten),
  // the old stop record (if any) is moved into events.jsonl as a "resume"
  // event, and stop.json goes until the session stops again. Every repair
  // is an event, and a line in `notes`. A session that completed whole is a
  // UserError.
  static std::unique_ptr<SessionWriter> Reopen(std::filesystem::path dir, bool set_aside_bad_frames = true,
                                               std::vector<std::string>* notes = nullptr);
  // Without a Stop, the session is marked failed ("ended without a stop record").
  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  const std::filesystem::path& dir() const { return dir_; }
  void Event(nlohmann::json event);
  // Writes frames/NNNNNN.tif and then its line in frames.jsonl (with `extra`
  // fields merged in); returns the file's path relative to the session.
  std::string WriteFrame(const Frame& frame, nlohmann::json extra);
  // how: "complete", "aborted" or "failed". The frame count is that of the
  // records frames.jsonl holds.
  void Stop(const std::string& how, const std::string& why = "");
  // Stop that never throws (for error paths, where the first error is the one to report).
  void StopQuietly(const std::string& how, const std::string& why) noexcept;
  int frame_count() const { return frames_; }
  // 0 for a new session, n for its n-th reopening: every frame it writes
  // records it (FrameRecord::run), since each run's clock starts anew.
  int run() const { return run_; }
  const nlohmann::json& start_record() const { return start_record_; }

 private:
  struct ReopenTag {};
  SessionWriter(ReopenTag, std::filesystem::path dir, bool set_aside_bad_frames, std::vector<std::string>* notes);
  // Moves each bad frame's file to frames/NNNNNN.tif.bad-K, rewrites
  // frames.jsonl without their lines, and records each as an event with its
  // record and what was wrong: what is listed is then what is good, and a
  // protocol that can measure again finds those measurements missing.
  void SetAsideBadFrames(const std::vector<SessionCheck::BadFrame>& bad, std::vector<std::string>* notes);
  void AppendLine(const std::string& file, const nlohmann::json& line);
  std::filesystem::path dir_;
  nlohmann::json start_record_;
  int frames_ = 0;  // the highest frame number used
  int run_ = 0;
  bool stopped_ = false;
  int abort_slot_ = -1;
};

// Reads a frame written by WriteFrame back: the pixels (and the exposure,
// from the TIFF's EXIF ExposureTime) from the file alone, or with everything
// its frames.jsonl line records (gain, black level, ADC bits, times).
Frame ReadFrame(const std::filesystem::path& path);
Frame ReadFrame(const std::filesystem::path& session_dir, const nlohmann::json& line);
Frame ReadFrame(const std::filesystem::path& session_dir, const FrameRecord& record);

}  // namespace phos
