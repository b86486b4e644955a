#pragma once
// Capture sessions: directories written as they go (DESIGN.md), so a crash,
// a kill -9 or a full disk loses nothing already recorded.
//
//   session.json   start record: protocol, sample, devices, settings, versions, uid
//   frames.jsonl   one line per frame: file, seq, times, exposure, gain, black level
//   events.jsonl   light switches and other events, with monotonic times
//   frames/        raw frames, lossless 16-bit TIFF
//   stop.json      how it ended: complete, aborted (signal), failed (why);
//                  on SIGINT/SIGTERM (with a LightsOffGuard alive) the
//                  handler writes "aborted" after switching the lights off
//
// Every line is appended and fsync'ed before the call returns; every frame
// and JSON file is written to a temporary name and renamed into place.

#include <filesystem>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "phos/acquire/camera.h"

namespace phos {

class SessionWriter {
 public:
  // Creates `dir` (which must not exist, or be empty) and writes session.json.
  SessionWriter(std::filesystem::path dir, nlohmann::json start_record);
  // Reopens an interrupted session to go on with it: frames are numbered on
  // from the last one recorded (a torn last line or a frame file without
  // its line is skipped, never overwritten), the old stop record (if any) is
  // moved into events.jsonl as a "resume" event, and stop.json goes until the
  // session stops again. A session that completed is a UserError.
  static std::unique_ptr<SessionWriter> Reopen(std::filesystem::path dir);
  // Without a Stop, the session is marked failed ("ended without a stop record").
  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  const std::filesystem::path& dir() const { return dir_; }
  void Event(nlohmann::json event);
  // Writes frames/NNNNNN.tif and its line in frames.jsonl (with `extra`
  // fields merged in); returns the file's path relative to the session.
  std::string WriteFrame(const Frame& frame, nlohmann::json extra);
  // how: "complete", "aborted" or "failed".
  void Stop(const std::string& how, const std::string& why = "");
  int frame_count() const { return frames_; }
  const nlohmann::json& start_record() const { return start_record_; }

 private:
  struct ReopenTag {};
  SessionWriter(ReopenTag, std::filesystem::path dir);
  void AppendLine(const std::string& file, const nlohmann::json& line);
  std::filesystem::path dir_;
  nlohmann::json start_record_;
  int frames_ = 0;
  bool stopped_ = false;
};

// Reads a frame written by WriteFrame back: the pixels (and the exposure,
// from the TIFF's EXIF ExposureTime) from the file alone, or with everything
// its frames.jsonl line records (gain, black level, ADC bits, times).
Frame ReadFrame(const std::filesystem::path& path);
Frame ReadFrame(const std::filesystem::path& session_dir, const nlohmann::json& line);

}  // namespace phos
