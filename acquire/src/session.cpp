#include "phos/acquire/session.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <set>
#include <csignal>
#include <cstring>
#include <cstdio>
#include <random>

#include <OpenImageIO/imageio.h>

#include "phos/acquire/lights.h"
#include "phos/acquire/protocol_records.h"
#include "phos/util/error.h"
#include "phos/util/image_file.h"
#include "phos/util/json.h"

namespace phos {
namespace {

std::string NewUid() {
  std::random_device device;
  std::mt19937_64 rng((static_cast<std::uint64_t>(device()) << 32) ^ device() ^
                      static_cast<std::uint64_t>(std::chrono::system_clock::now().time_since_epoch().count()));
  char text[40];
  std::snprintf(text, sizeof text, "%016llx%016llx", static_cast<unsigned long long>(rng()),
                static_cast<unsigned long long>(rng()));
  return text;
}

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return text;
}

// The sessions a signal would abort (a part inside an `all` folder, and the
// folder itself): their stop.json paths and records, and events.jsonl for
// the lights the handler switched off, prepared in advance because a signal
// handler may only make system calls (open, write, fsync, rename).
struct AbortRecord {
  std::atomic<bool> armed{false};
  char temporary[4096];
  char final_path[4096];
  char events_path[4096];
  char sigint[512];
  char sigterm[512];
  char resume_hint[4600];  // for the person at the terminal: what happened and how to go on
};
constexpr int kAbortSlots = 4;
AbortRecord g_abort_records[kAbortSlots];

void WriteAll(int fd, const char* text, std::size_t size) {
  while (size > 0) {
    const ssize_t n = ::write(fd, text, size);
    if (n <= 0) return;
    text += n;
    size -= static_cast<std::size_t>(n);
  }
}

void WriteAbortRecords(int signal_number, const char* const* switched_off, int switched_off_count) {
  // One line on stderr for the outermost open session (the lowest slot: an
  // `all` folder opens before its part), since the process ends without a word otherwise.
  for (AbortRecord& record : g_abort_records) {
    if (!record.armed.load()) continue;
    const char* signal_name =
        signal_number == SIGINT ? "phos capture: interrupted (SIGINT)" : "phos capture: terminated (SIGTERM)";
    WriteAll(STDERR_FILENO, signal_name, std::strlen(signal_name));
    WriteAll(STDERR_FILENO, record.resume_hint, std::strlen(record.resume_hint));
    break;
  }
  for (AbortRecord& record : g_abort_records) {
    if (!record.armed.load()) continue;
    // The lights the handler switched off, one whole line each (no time: the
    // protocol's clock is not reachable from here; the line says who did it).
    const int events = ::open(record.events_path, O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
    if (events >= 0) {
      for (int i = 0; i < switched_off_count; ++i) {
        // Keys in sorted order, compact, as nlohmann::json dumps them: the
        // text whose XXH3 is the line's record_xxh3 (session_records.h).
        const char* signal_text = signal_number == SIGINT ? "SIGINT" : "SIGTERM";
        char body[400];
        const int m = std::snprintf(body, sizeof body,
                                    "{\"by\":\"signal handler\",\"channel\":\"%s\",\"event\":\"light\",\"on\":false,"
                                    "\"signal\":\"%s\"}",
                                    switched_off[i], signal_text);
        if (m <= 0 || m >= static_cast<int>(sizeof body)) continue;
        char line[512];
        const int n = std::snprintf(
            line, sizeof line,
            "{\"by\":\"signal handler\",\"channel\":\"%s\",\"event\":\"light\",\"on\":false,"
            "\"record_xxh3\":\"%016llx\",\"signal\":\"%s\"}\n",
            switched_off[i], static_cast<unsigned long long>(Xxh3(body, static_cast<std::size_t>(m))), signal_text);
        if (n > 0 && n < static_cast<int>(sizeof line)) WriteAll(events, line, static_cast<std::size_t>(n));
      }
      ::fsync(events);
      ::close(events);
    }
    const char* text = signal_number == SIGINT ? record.sigint : record.sigterm;
    const int fd = ::open(record.temporary, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) continue;
    WriteAll(fd, text, std::strlen(text));
    ::fsync(fd);
    ::close(fd);
    ::rename(record.temporary, record.final_path);
  }
}

int ArmAbortRecord(const std::filesystem::path& dir) {
  const std::string final_path = (dir / "stop.json").string();
  const std::string temporary = final_path + ".tmp.signal";
  const std::string events_path = (dir / "events.jsonl").string();
  if (temporary.size() >= sizeof g_abort_records[0].temporary) return -1;  // too long to prepare: no record
  for (int slot = 0; slot < kAbortSlots; ++slot) {
    AbortRecord& record = g_abort_records[slot];
    if (record.armed.load()) continue;
    std::snprintf(record.final_path, sizeof record.final_path, "%s", final_path.c_str());
    std::snprintf(record.temporary, sizeof record.temporary, "%s", temporary.c_str());
    std::snprintf(record.events_path, sizeof record.events_path, "%s", events_path.c_str());
    const auto stop_text = [](const char* why) {
      StopRecord stop;
      stop.how = "aborted";
      stop.why = why;
      stop.frames = -1;  // the handler cannot count; the frame list is the count
      return WithRecordChecksum(stop.ToJson()).dump(2) + "\n";
    };
    std::snprintf(record.sigint, sizeof record.sigint, "%s",
                  stop_text("SIGINT (interrupted); lights switched off; frames.jsonl lists every frame kept").c_str());
    std::snprintf(record.sigterm, sizeof record.sigterm, "%s",
                  stop_text("SIGTERM (terminated); lights switched off; frames.jsonl lists every frame kept").c_str());
    std::snprintf(record.resume_hint, sizeof record.resume_hint,
                  ": the lights are off and every frame listed is kept; 'phos capture resume %s' goes on where it "
                  "can\n",
                  dir.string().c_str());
    record.armed.store(true);
    SetSignalCleanup(WriteAbortRecords);
    return slot;
  }
  return -1;
}

void DisarmAbortRecord(int slot) {
  if (slot >= 0) g_abort_records[slot].armed.store(false);
}

// Temporaries a crash leaves: frames/NNNNNN.tif.tmp.<pid>.tif, stop.json.tmp.*,
// and the temporaries of util/atomic_file.h (<name>.tmp.<pid><ext>).
bool IsTemporary(const std::string& name) { return name.find(".tmp.") != std::string::npos; }

std::vector<std::filesystem::path> StaleTemporaries(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> stale;
  std::error_code ec;
  for (const std::filesystem::path& folder : {dir, dir / "frames"})
    for (const auto& entry : std::filesystem::directory_iterator(folder, ec))
      if (entry.is_regular_file(ec) && IsTemporary(entry.path().filename().string())) stale.push_back(entry.path());
  std::sort(stale.begin(), stale.end());
  return stale;
}

// The highest frame number a file in frames/ carries (a frame written
// without its record, or set aside, still holds its number).
int HighestFrameFile(const std::filesystem::path& dir) {
  int highest = 0;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "frames", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.size() >= 10 && name.find_first_not_of("0123456789") == 6)
      highest = std::max(highest, std::atoi(name.c_str()));
  }
  return highest;
}

}  // namespace

SessionWriter::SessionWriter(std::filesystem::path dir, nlohmann::json start_record) : dir_(std::move(dir)) {
  std::error_code ec;
  if (std::filesystem::exists(dir_, ec) && !std::filesystem::is_empty(dir_, ec))
    ThrowUserError(dir_.string(), "",
                   "already holds files: a new session needs a new or empty folder (to go on with an interrupted one, "
                   "use resume)");
  start_record["uid"] = NewUid();
  start_record["started_utc"] = UtcNow();
  start_record["schema"] = kSessionSchema;
  // Through the typed record, so what is written is what every reader reads.
  const SessionRecord record = SessionRecord::FromJson(start_record, (dir_ / "session.json").string());
  std::filesystem::create_directories(dir_ / "frames", ec);
  if (ec) ThrowUserError(dir_.string(), "", "cannot create the session folder: " + ec.message());
  start_record_ = WithRecordChecksum(std::move(start_record));
  WriteFileAtomically(dir_ / "session.json", start_record_.dump(2) + "\n");
  abort_slot_ = ArmAbortRecord(dir_);
}

std::unique_ptr<SessionWriter> SessionWriter::Reopen(std::filesystem::path dir, bool set_aside_bad_frames,
                                                     std::vector<std::string>* notes) {
  return std::unique_ptr<SessionWriter>(new SessionWriter(ReopenTag{}, std::move(dir), set_aside_bad_frames, notes));
}

SessionWriter::SessionWriter(ReopenTag, std::filesystem::path dir, bool set_aside_bad_frames,
                             std::vector<std::string>* notes)
    : dir_(std::move(dir)) {
  std::vector<std::string> ignored_notes;
  if (notes == nullptr) notes = &ignored_notes;
  ReadSessionRecord(dir_);  // typed: a broken start record is one line
  start_record_ = ReadJsonFile(dir_ / "session.json");
  const SessionCheck check = CheckSession(dir_);
  if (check.complete() && check.clean()) ThrowUserError(dir_.string(), "", "completed already: nothing to resume");
  if (!check.bad_frames.empty() && !set_aside_bad_frames) {
    const SessionCheck::BadFrame& bad = check.bad_frames.front();
    ThrowUserError((dir_ / bad.frame.file).string(), "",
                   bad.problem + ": a " + check.protocol +
                       " frame cannot be measured again (the glow it saw is gone); "
                       "the session stays incomplete (" +
                       std::to_string(check.bad_frames.size()) + " bad frame(s))");
  }
  // Repairs, each said: torn lines aside, stale temporaries removed.
  std::vector<nlohmann::json> repairs;
  for (const char* name : {"frames.jsonl", "events.jsonl"}) {
    const JsonLinesFile file = ReadJsonLinesFile(dir_ / name);
    if (!file.torn) continue;
    const std::filesystem::path aside = SetAsideTornLine(dir_ / name, file);
    notes->push_back(std::string(name) + ": its last line was torn (a crash mid-write); kept aside in " +
                     aside.filename().string());
    repairs.push_back({{"torn_line", name}, {"line", file.torn_line}, {"kept_in", aside.filename().string()}});
  }
  for (const std::filesystem::path& stale : check.stale_temporaries) {
    std::error_code ec;
    std::filesystem::remove(stale, ec);
    const std::string relative = std::filesystem::relative(stale, dir_, ec).string();
    notes->push_back("removed the stale temporary " + relative);
    repairs.push_back({{"removed_temporary", relative}});
  }
  nlohmann::json previous_stop =
      check.stop ? check.stop->ToJson() : nlohmann::json("none (killed, or the machine went down)");
  // Number on from the highest frame recorded or present on disk.
  for (const FrameRecord& frame : ReadFrameRecords(dir_).frames) frames_ = std::max(frames_, frame.seq);
  frames_ = std::max(frames_, HighestFrameFile(dir_));
  // This run: one more than the reopenings before it (their resume events,
  // which alone carry resumed_utc; a protocol's own resume event does not).
  run_ = 1;
  for (const nlohmann::json& event : ReadEventRecords(dir_))
    run_ += event.value("event", "") == "resume" && event.contains("resumed_utc");
  nlohmann::json resume = {{"event", "resume"}, {"resumed_utc", UtcNow()}, {"previous_stop", previous_stop}};
  if (!repairs.empty()) resume["repairs"] = repairs;
  Event(resume);
  if (!check.bad_frames.empty()) SetAsideBadFrames(check.bad_frames, notes);
  std::error_code ec;
  std::filesystem::remove(dir_ / "stop.json", ec);
  abort_slot_ = ArmAbortRecord(dir_);
}

void SessionWriter::SetAsideBadFrames(const std::vector<SessionCheck::BadFrame>& bad, std::vector<std::string>* notes) {
  std::set<int> bad_seq;
  for (const SessionCheck::BadFrame& b : bad) {
    bad_seq.insert(b.frame.seq);
    std::error_code ec;
    const std::filesystem::path file = dir_ / b.frame.file;
    std::string kept = "(no file)";
    if (std::filesystem::exists(std::filesystem::symlink_status(file, ec))) {
      std::filesystem::path aside;
      for (int k = 1; std::filesystem::exists(aside = file.string() + ".bad-" + std::to_string(k), ec); ++k) {}
      std::filesystem::rename(file, aside, ec);
      if (ec) ThrowUserError(file.string(), "", "cannot set the bad frame aside: " + ec.message());
      kept = std::filesystem::relative(aside, dir_, ec).string();
    }
    Event({{"event", "frame_set_aside"}, {"why", b.problem}, {"kept_as", kept}, {"record", b.frame.ToJson()}});
    notes->push_back(b.frame.file + " " + b.problem + ": set aside as " + kept + ", to be measured again");
  }
  // frames.jsonl without them, replaced whole (the records are in events.jsonl).
  std::string text;
  for (const JsonLine& line : ReadJsonLinesFile(dir_ / "frames.jsonl").records) {
    const nlohmann::json& seq = line.value.contains("seq") ? line.value["seq"] : nlohmann::json();
    if (seq.is_number_integer() && bad_seq.count(seq.get<int>())) continue;
    text += line.value.dump() + "\n";
  }
  WriteFileAtomically(dir_ / "frames.jsonl", text, {.sync = true});
}

SessionWriter::~SessionWriter() {
  if (!stopped_) StopQuietly("failed", "ended without a stop record (an error or exception interrupted the protocol)");
}

void SessionWriter::AppendLine(const std::string& file, const nlohmann::json& line) {
  AppendJsonLine(dir_ / file, WithRecordChecksum(line));
}

void SessionWriter::Event(nlohmann::json event) { AppendLine("events.jsonl", event); }

namespace {
// A frame's file as written, before it has a name: on disk (fsync), and read
// back whole, every pixel as captured. OpenImageIO's TIFF writer reports
// success for a file a full disk cut short (no image directory after 8 KiB),
// so its word is not enough; a frame that does not read back is never named
// nor listed. Returns the file's checksum.
FileDigest CheckWrittenFrame(const std::filesystem::path& temporary, const Frame& frame,
                             const std::filesystem::path& final_path) {
  const std::string cut = "could not write the frame (disk full?): it did not reach the disk whole";
  try {
    SyncFile(temporary);
    const Frame back = ReadFrame(temporary);
    if (back.width != frame.width || back.height != frame.height || back.channels != frame.channels ||
        back.pixels != frame.pixels)
      ThrowUserError(final_path.string(), "", cut);
    return DigestFile(temporary);
  } catch (const UserError&) {
    ThrowUserError(final_path.string(), "", cut);
  }
}
}  // namespace

std::string SessionWriter::WriteFrame(const Frame& frame, nlohmann::json extra) {
  const int seq = frames_ + 1;
  char name[32];
  std::snprintf(name, sizeof name, "frames/%06d.tif", seq);
  const std::filesystem::path final_path = dir_ / name;
  // Complete on disk before it has a name, and named before it has a record.
  FileDigest digest;
  OIIO::ImageSpec spec(frame.width, frame.height, frame.channels, OIIO::TypeDesc::UINT16);
  spec.channelnames = frame.channel_names;
  spec.attribute("compression", "zip");  // lossless
  spec.attribute("oiio:BitsPerSample", 16);
  spec.attribute("ExposureTime", static_cast<float>(frame.exposure_s));  // EXIF; frames.jsonl holds the rest
  WriteImageAtomically(
      final_path, spec, OIIO::TypeDesc::UINT16, frame.pixels.data(),
      [&](const std::filesystem::path& temporary) { digest = CheckWrittenFrame(temporary, frame, final_path); });
  SyncDirectory(dir_ / "frames");
  frames_ = seq;  // the number is used, with or without its record
  FrameRecord record;
  record.file = name;
  record.seq = seq;
  record.t_start_s = frame.t_start_s;
  record.exposure_s = frame.exposure_s;
  record.gain = frame.gain;
  record.black_level_dn = frame.black_level_dn;
  record.adc_bits = frame.adc_bits;
  record.sensor_temperature_c = frame.sensor_temperature_c;
  record.camera_timestamp_ns = frame.camera_timestamp_ns;
  record.packets_resent = frame.packets_resent;
  record.retakes = frame.retakes;
  record.run = run_;
  record.size_bytes = digest.size_bytes;
  record.xxh3 = digest.xxh3;
  record.protocol = std::move(extra);
  AppendLine("frames.jsonl", record.ToJson());
  return name;
}

void SessionWriter::Stop(const std::string& how, const std::string& why) {
  DisarmAbortRecord(abort_slot_);  // from here on, a signal finds the session already ended
  abort_slot_ = -1;
  stopped_ = true;
  StopRecord stop;
  stop.how = how;
  stop.why = why;
  stop.stopped_utc = UtcNow();
  // Counted from the records written, never from a counter.
  stop.frames = static_cast<int>(ReadFrameRecords(dir_).frames.size());
  WriteFileAtomically(dir_ / "stop.json", WithRecordChecksum(stop.ToJson()).dump(2) + "\n", {.sync = true});
}

void SessionWriter::StopQuietly(const std::string& how, const std::string& why) noexcept {
  try {
    Stop(how, why);
  } catch (...) {
    // A full disk can refuse the stop record too; the missing stop.json then
    // says "interrupted", which resume handles.
  }
}

// ---- checking ----------------------------------------------------------------

SessionCheck CheckSession(const std::filesystem::path& dir, bool decode_frames) {
  SessionCheck check;
  // What resume cannot mend (a record that does not read, a list missing
  // under a complete stop) is also kept apart; torn lines, bad frames and a
  // stop's miscount it mends.
  auto problem = [&](const std::string& text) {
    check.problems.push_back(text);
    check.unrepairable.push_back(text);
  };
  auto repairable = [&](const std::string& text) { check.problems.push_back(text); };
  std::error_code ec;
  try {
    check.protocol = ReadSessionRecord(dir).protocol;
  } catch (const UserError& e) {
    problem(e.what());
  }
  try {
    check.stop = ReadStopRecord(dir);
  } catch (const UserError& e) {
    problem(e.what());
  }
  FrameRecords records;
  bool frames_read = false;
  try {
    records = ReadFrameRecords(dir);
    frames_read = true;
  } catch (const UserError& e) {
    problem(e.what());
  }
  check.frames = static_cast<int>(records.frames.size());
  if (records.torn) {
    check.torn_frames = true;
    repairable((dir / "frames.jsonl").string() + ": its last line is torn (a crash mid-write); resume keeps it aside");
  }
  try {
    const JsonLinesFile events = ReadJsonLinesFile(dir / "events.jsonl");
    if (events.torn) {
      check.torn_events = true;
      repairable((dir / "events.jsonl").string() + ":" + std::to_string(events.torn_line) +
                 ": torn last line (a crash mid-write); resume keeps it aside");
    }
  } catch (const UserError& e) {
    problem(e.what());
  }
  // Every frame record holds its protocol's fields, and the start record its
  // settings and devices, whole: resume cannot mend a record that lacks one.
  for (const std::string& text : ProtocolFieldProblems(dir, check.protocol, records)) problem(text);
  // Every record as written: a number changed since (by hand, by a failing
  // disk) cannot be mended, only reported.
  for (const std::string& text : RecordChecksumProblems(dir)) problem(text);
  try {
    if (!check.protocol.empty()) CheckStartRecord(ReadSessionRecord(dir), (dir / "session.json").string());
  } catch (const UserError& e) {
    problem(e.what());
  }
  check.stale_temporaries = StaleTemporaries(dir);
  // Frames: each file whole, as recorded, and an image of the session's size.
  int width = 0, height = 0, channels = 0;
  for (std::size_t i = 0; i < records.frames.size(); ++i) {
    const FrameRecord& frame = records.frames[i];
    std::string what = CheckFrameFile(dir, frame);
    if (what.empty() && decode_frames) {
      try {
        const Frame image = ReadFrame(dir / frame.file);
        if (width == 0) width = image.width, height = image.height, channels = image.channels;
        if (image.width != width || image.height != height || image.channels != channels)
          what = "is " + std::to_string(image.width) + "x" + std::to_string(image.height) + "x" +
                 std::to_string(image.channels) + " where the session's frames are " + std::to_string(width) + "x" +
                 std::to_string(height) + "x" + std::to_string(channels);
      } catch (const UserError& e) {
        what = "does not read as an image";
      }
    }
    if (!what.empty()) {
      check.bad_frames.push_back({frame, records.lines[i], what});
      repairable((dir / frame.file).string() + ": " + what + " (frames.jsonl:" + std::to_string(records.lines[i]) +
                 ")");
    }
  }
  if (check.stop && frames_read) {
    const bool has_list = std::filesystem::exists(dir / "frames.jsonl", ec);
    if (check.stop->frames >= 0 && check.stop->frames != check.frames)
      repairable((dir / "stop.json").string() + ": counts " + std::to_string(check.stop->frames) +
                 " frames where frames.jsonl lists " + std::to_string(check.frames));
    if (check.complete() && check.protocol != "all" && !has_list)
      problem((dir / "frames.jsonl").string() + ": missing, in a session whose stop.json says complete");
  }
  return check;
}

Frame ReadFrame(const std::filesystem::path& session_dir, const nlohmann::json& line) {
  return ReadFrame(session_dir, FrameRecord::FromJson(line, (session_dir / "frames.jsonl").string()));
}

Frame ReadFrame(const std::filesystem::path& session_dir, const FrameRecord& record) {
  Frame frame = ReadFrame(session_dir / record.file);
  frame.exposure_s = record.exposure_s;
  frame.gain = record.gain;
  frame.black_level_dn = record.black_level_dn;
  frame.adc_bits = record.adc_bits;
  frame.t_start_s = record.t_start_s;
  frame.sensor_temperature_c = record.sensor_temperature_c;
  frame.camera_timestamp_ns = record.camera_timestamp_ns;
  frame.packets_resent = record.packets_resent;
  frame.retakes = record.retakes;
  return frame;
}

Frame ReadFrame(const std::filesystem::path& path) {
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) ThrowUserError(path.string(), "", "cannot read the frame: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  Frame frame;
  frame.width = spec.width;
  frame.height = spec.height;
  frame.channels = spec.nchannels;
  frame.channel_names = spec.channelnames;
  frame.pixels.resize(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
  // A frame phos wrote is 16-bit already: read natively, straight into the
  // pixels. A requested format, even the file's own, took OpenImageIO 2.4's
  // converting path, which allocates a 64 MiB chunk buffer for every read
  // (ImageInput::read_scanlines; perf): that was most of what checking a
  // session's frames cost.
  const bool native = spec.format == OIIO::TypeDesc::UINT16 && spec.channelformats.empty();
  if (!in->read_image(0, 0, 0, spec.nchannels, native ? OIIO::TypeDesc::UNKNOWN : OIIO::TypeDesc::UINT16,
                      frame.pixels.data()))
    ThrowUserError(path.string(), "", "cannot read the frame: " + in->geterror());
  frame.exposure_s = spec.get_float_attribute("ExposureTime", 0.0f);
  return frame;
}

}  // namespace phos
