#include "phos/acquire/session.h"

#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <atomic>
#include <csignal>
#include <cstring>
#include <cstdio>
#include <random>

#include <OpenImageIO/imageio.h>

#include "phos/acquire/lights.h"
#include "phos/util/error.h"
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

// The session a signal would abort: its stop.json path and the records to
// write there, prepared in advance because a signal handler may only make
// system calls (open, write, fsync, rename).
struct AbortRecord {
  char temporary[4096];
  char final_path[4096];
  char sigint[512];
  char sigterm[512];
};
AbortRecord g_abort_record;
std::atomic<bool> g_abort_armed{false};

void WriteAbortRecord(int signal_number) {
  if (!g_abort_armed.load()) return;
  const char* text = signal_number == SIGINT ? g_abort_record.sigint : g_abort_record.sigterm;
  const int fd = ::open(g_abort_record.temporary, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return;
  const ssize_t ignored = ::write(fd, text, std::strlen(text));
  (void)ignored;
  ::fsync(fd);
  ::close(fd);
  ::rename(g_abort_record.temporary, g_abort_record.final_path);
}

void ArmAbortRecord(const std::filesystem::path& dir) {
  const std::string final_path = (dir / "stop.json").string();
  const std::string temporary = final_path + ".tmp.signal";
  if (final_path.size() >= sizeof g_abort_record.final_path) return;  // too long to prepare: no record
  std::snprintf(g_abort_record.final_path, sizeof g_abort_record.final_path, "%s", final_path.c_str());
  std::snprintf(g_abort_record.temporary, sizeof g_abort_record.temporary, "%s", temporary.c_str());
  std::snprintf(g_abort_record.sigint, sizeof g_abort_record.sigint,
                "{\n  \"how\": \"aborted\",\n  \"why\": \"SIGINT (interrupted); lights switched off; frames.jsonl lists every frame kept\"\n}\n");
  std::snprintf(g_abort_record.sigterm, sizeof g_abort_record.sigterm,
                "{\n  \"how\": \"aborted\",\n  \"why\": \"SIGTERM (terminated); lights switched off; frames.jsonl lists every frame kept\"\n}\n");
  g_abort_armed.store(true);
  SetSignalCleanup(WriteAbortRecord);
}

}  // namespace

SessionWriter::SessionWriter(std::filesystem::path dir, nlohmann::json start_record) : dir_(std::move(dir)) {
  std::error_code ec;
  if (std::filesystem::exists(dir_, ec) && !std::filesystem::is_empty(dir_, ec))
    ThrowUserError(dir_.string(), "", "already holds files: a new session needs a new or empty folder (to go on with an interrupted one, use resume)");
  std::filesystem::create_directories(dir_ / "frames", ec);
  if (ec) ThrowUserError(dir_.string(), "", "cannot create the session folder: " + ec.message());
  start_record["uid"] = NewUid();
  start_record["started_utc"] = UtcNow();
  start_record["schema"] = "phos.session/1";
  WriteFileAtomically(dir_ / "session.json", start_record.dump(2) + "\n");
  start_record_ = std::move(start_record);
  ArmAbortRecord(dir_);
}

std::unique_ptr<SessionWriter> SessionWriter::Reopen(std::filesystem::path dir) {
  return std::unique_ptr<SessionWriter>(new SessionWriter(ReopenTag{}, std::move(dir)));
}

SessionWriter::SessionWriter(ReopenTag, std::filesystem::path dir) : dir_(std::move(dir)) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(dir_ / "session.json", ec))
    ThrowUserError(dir_.string(), "", "is not a capture session (no session.json)");
  start_record_ = ReadJsonFile(dir_ / "session.json");
  nlohmann::json previous_stop;
  if (std::filesystem::exists(dir_ / "stop.json", ec)) {
    previous_stop = ReadJsonFile(dir_ / "stop.json");
    if (previous_stop.value("how", "") == "complete")
      ThrowUserError(dir_.string(), "", "completed already: nothing to resume");
  }
  // Number on from the highest frame recorded or present on disk.
  for (const nlohmann::json& line : ReadJsonLines(dir_ / "frames.jsonl"))
    if (line.contains("seq")) frames_ = std::max(frames_, line["seq"].get<int>());
  for (const auto& entry : std::filesystem::directory_iterator(dir_ / "frames", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.size() >= 10 && name.find_first_not_of("0123456789") == 6) frames_ = std::max(frames_, std::atoi(name.c_str()));
  }
  Event({{"event", "resume"},
         {"resumed_utc", UtcNow()},
         {"previous_stop", previous_stop.is_null() ? nlohmann::json("none (killed, or the machine went down)") : previous_stop}});
  std::filesystem::remove(dir_ / "stop.json", ec);
  ArmAbortRecord(dir_);
}

SessionWriter::~SessionWriter() {
  if (!stopped_) {
    try {
      Stop("failed", "ended without a stop record (an error or exception interrupted the protocol)");
    } catch (...) {
    }
  }
}

void SessionWriter::AppendLine(const std::string& file, const nlohmann::json& line) {
  const std::string text = line.dump() + "\n";
  const std::string path = (dir_ / file).string();
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) ThrowUserError(path, "", "cannot open for appending");
  const ssize_t written = ::write(fd, text.data(), text.size());
  const bool synced = ::fsync(fd) == 0;
  ::close(fd);
  if (written != static_cast<ssize_t>(text.size()) || !synced)
    ThrowUserError(path, "", "could not record a line (disk full?): what was recorded before it is intact");
}

void SessionWriter::Event(nlohmann::json event) { AppendLine("events.jsonl", event); }

std::string SessionWriter::WriteFrame(const Frame& frame, nlohmann::json extra) {
  ++frames_;
  char name[32];
  std::snprintf(name, sizeof name, "frames/%06d.tif", frames_);
  const std::filesystem::path final_path = dir_ / name;
  const std::filesystem::path temporary = dir_ / (std::string(name) + ".tmp.tif");
  auto out = OIIO::ImageOutput::create(temporary.string());
  if (!out) ThrowUserError(temporary.string(), "", "no TIFF writer: " + OIIO::geterror());
  OIIO::ImageSpec spec(frame.width, frame.height, frame.channels, OIIO::TypeDesc::UINT16);
  spec.channelnames = frame.channel_names;
  spec.attribute("compression", "zip");  // lossless
  spec.attribute("oiio:BitsPerSample", 16);
  spec.attribute("ExposureTime", static_cast<float>(frame.exposure_s));  // EXIF; frames.jsonl holds the rest
  if (!out->open(temporary.string(), spec) || !out->write_image(OIIO::TypeDesc::UINT16, frame.pixels.data()) ||
      !out->close()) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    ThrowUserError(final_path.string(), "", "could not write the frame (disk full?): " + out->geterror());
  }
  std::error_code ec;
  std::filesystem::rename(temporary, final_path, ec);
  if (ec) ThrowUserError(final_path.string(), "", "could not move the frame into place: " + ec.message());
  extra["file"] = name;
  extra["seq"] = frames_;
  extra["t_start_s"] = frame.t_start_s;
  extra["exposure_s"] = frame.exposure_s;
  extra["gain"] = frame.gain;
  extra["black_level_dn"] = frame.black_level_dn;
  extra["adc_bits"] = frame.adc_bits;
  extra["sensor_temperature_c"] = frame.sensor_temperature_c;
  if (frame.camera_timestamp_ns != 0) extra["camera_timestamp_ns"] = frame.camera_timestamp_ns;
  AppendLine("frames.jsonl", extra);
  return name;
}

void SessionWriter::Stop(const std::string& how, const std::string& why) {
  g_abort_armed.store(false);  // from here on, a signal finds the session already ended
  nlohmann::json stop = {{"how", how}, {"frames", frames_}, {"stopped_utc", UtcNow()}};
  if (!why.empty()) stop["why"] = why;
  stopped_ = true;
  WriteFileAtomically(dir_ / "stop.json", stop.dump(2) + "\n");
}

Frame ReadFrame(const std::filesystem::path& session_dir, const nlohmann::json& line) {
  if (!line.is_object() || !line.contains("file") || !line["file"].is_string())
    ThrowUserError((session_dir / "frames.jsonl").string(), "", "a frame line has no file");
  Frame frame = ReadFrame(session_dir / line["file"].get<std::string>());
  frame.exposure_s = line.value("exposure_s", frame.exposure_s);
  frame.gain = line.value("gain", 1.0);
  frame.black_level_dn = line.value("black_level_dn", 0.0);
  frame.adc_bits = line.value("adc_bits", 16);
  frame.t_start_s = line.value("t_start_s", 0.0);
  frame.sensor_temperature_c = line.value("sensor_temperature_c", 0.0);
  frame.camera_timestamp_ns = line.value("camera_timestamp_ns", std::uint64_t{0});
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
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT16, frame.pixels.data()))
    ThrowUserError(path.string(), "", "cannot read the frame: " + in->geterror());
  frame.exposure_s = spec.get_float_attribute("ExposureTime", 0.0f);
  return frame;
}

}  // namespace phos
