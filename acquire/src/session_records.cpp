#include "phos/acquire/session_records.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <set>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos {
namespace fs = std::filesystem;

namespace {

// Reads a whole file that must be a regular file of at most max_bytes.
std::string ReadBoundedFile(const fs::path& path, std::uint64_t max_bytes) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (ec || !fs::is_regular_file(status)) ThrowUserError(path.string(), "", "is not a regular file");
  const std::uint64_t size = fs::file_size(path, ec);
  if (ec) ThrowUserError(path.string(), "", "cannot read its size: " + ec.message());
  if (size > max_bytes)
    ThrowUserError(
        path.string(), "",
        "is " + std::to_string(size) + " bytes, over the limit of " + std::to_string(max_bytes) + " for a record file");
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowUserError(path.string(), "", "cannot open the file for reading");
  std::string text(size, '\0');
  in.read(text.data(), static_cast<std::streamsize>(size));
  text.resize(static_cast<std::size_t>(in.gcount()));
  return text;
}

std::string JsonError(const nlohmann::json::exception& e) {
  std::string what = e.what();
  if (auto close = what.find("] "); what.rfind("[json.exception", 0) == 0 && close != std::string::npos)
    what = what.substr(close + 2);
  return what;
}

void SyncOrThrow(int fd, const fs::path& path) {
  if (::fsync(fd) != 0) {
    const std::string reason = std::strerror(errno);
    ::close(fd);
    ThrowUserError(path.string(), "", "could not be flushed to disk: " + reason);
  }
}

// frames/NNNNNN.tif, the NNNNNN being seq: no other path is ever read, so
// a record cannot point outside its session.
std::string FrameFileName(int seq) {
  char name[48];
  std::snprintf(name, sizeof name, "frames/%06d.tif", seq);
  return name;
}

}  // namespace

// ---- JSON Lines ------------------------------------------------------------

JsonLinesFile ReadJsonLinesFile(const fs::path& path) {
  JsonLinesFile file;
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(path, ec))) return file;
  const std::string text = ReadBoundedFile(path, kMaxRecordFileBytes);
  std::size_t begin = 0;
  int line = 0;
  while (begin < text.size()) {
    ++line;
    const std::size_t end = text.find('\n', begin);
    if (end == std::string::npos) {  // no newline: the write of this line never finished
      file.torn = text.substr(begin);
      file.torn_line = line;
      break;
    }
    const std::string_view record(text.data() + begin, end - begin);
    nlohmann::json value;
    try {
      value = nlohmann::json::parse(record);
    } catch (const nlohmann::json::exception& e) {
      ThrowUserError(path.string() + ":" + std::to_string(line), "",
                     "not a JSON record (" + JsonError(e) + "); the file is corrupt past a torn line");
    }
    if (!value.is_object())
      ThrowUserError(path.string() + ":" + std::to_string(line), "",
                     "expected a JSON object, got " + DescribeJson(value));
    file.records.push_back({line, std::move(value)});
    begin = end + 1;
    file.whole_bytes = begin;
  }
  return file;
}

fs::path SetAsideTornLine(const fs::path& path, const JsonLinesFile& file) {
  fs::path torn_path = path;
  torn_path += ".torn";
  if (!file.torn) return torn_path;
  const int out = ::open(torn_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (out < 0) ThrowUserError(torn_path.string(), "", std::string("cannot open: ") + std::strerror(errno));
  const std::string text = *file.torn + "\n";
  if (::write(out, text.data(), text.size()) != static_cast<ssize_t>(text.size())) {
    ::close(out);
    ThrowUserError(torn_path.string(), "", "could not keep the torn line aside (disk full?)");
  }
  SyncOrThrow(out, torn_path);
  ::close(out);
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0 || ::ftruncate(fd, static_cast<off_t>(file.whole_bytes)) != 0) {
    if (fd >= 0) ::close(fd);
    ThrowUserError(path.string(), "", std::string("cannot cut off its torn last line: ") + std::strerror(errno));
  }
  SyncOrThrow(fd, path);
  ::close(fd);
  return torn_path;
}

void AppendJsonLine(const fs::path& path, const nlohmann::json& record) {
  const std::string text = record.dump() + "\n";
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (fd < 0) ThrowUserError(path.string(), "", std::string("cannot open for appending: ") + std::strerror(errno));
  struct stat before {};
  ::fstat(fd, &before);
  // One write of the whole line: O_APPEND puts it after the last record.
  const ssize_t written = ::write(fd, text.data(), text.size());
  const int write_errno = errno;
  if (written != static_cast<ssize_t>(text.size())) {
    // Half a line on a full disk: cut it off, so the file still ends with
    // its last whole record.
    const int ignored = ::ftruncate(fd, before.st_size);
    (void)ignored;
    ::fsync(fd);
    ::close(fd);
    ThrowUserError(path.string(), "",
                   std::string("could not record a line: ") +
                       (written < 0 ? std::strerror(write_errno) : "short write (disk full?)") +
                       "; every record before it is intact");
  }
  if (::fsync(fd) != 0) {
    const int ignored = ::ftruncate(fd, before.st_size);
    (void)ignored;
    ::close(fd);
    ThrowUserError(path.string(), "", "could not flush a record to disk; every record before it is intact");
  }
  ::close(fd);
}

// ---- typed keys ------------------------------------------------------------

namespace {
[[noreturn]] void KeyError(const std::string& where, const char* key, const std::string& what) {
  ThrowUserError(where, key, what);
}
const nlohmann::json& KeyOf(const nlohmann::json& j, const char* key, const std::string& where) {
  if (!j.is_object()) ThrowUserError(where, "", "expected a JSON object, got " + DescribeJson(j));
  auto it = j.find(key);
  if (it == j.end()) KeyError(where, key, "missing");
  return *it;
}
}  // namespace

template <>
double RequiredKey<double>(const nlohmann::json& j, const char* key, const std::string& where) {
  const nlohmann::json& v = KeyOf(j, key, where);
  if (!v.is_number() || !std::isfinite(v.get<double>()))
    KeyError(where, key, "expected a finite number, got " + DescribeJson(v));
  return v.get<double>();
}
template <>
int RequiredKey<int>(const nlohmann::json& j, const char* key, const std::string& where) {
  const nlohmann::json& v = KeyOf(j, key, where);
  if (!v.is_number_integer() || v.get<double>() < std::numeric_limits<int>::min() ||
      v.get<double>() > std::numeric_limits<int>::max())
    KeyError(where, key, "expected an integer, got " + DescribeJson(v));
  return v.get<int>();
}
template <>
std::string RequiredKey<std::string>(const nlohmann::json& j, const char* key, const std::string& where) {
  const nlohmann::json& v = KeyOf(j, key, where);
  if (!v.is_string()) KeyError(where, key, "expected a string, got " + DescribeJson(v));
  return v.get<std::string>();
}
template <>
nlohmann::json RequiredKey<nlohmann::json>(const nlohmann::json& j, const char* key, const std::string& where) {
  const nlohmann::json& v = KeyOf(j, key, where);
  if (!v.is_object()) KeyError(where, key, "expected an object, got " + DescribeJson(v));
  return v;
}

namespace {
double OptionalNumber(const nlohmann::json& j, const char* key, double fallback, const std::string& where) {
  return j.contains(key) ? RequiredKey<double>(j, key, where) : fallback;
}
// An optional count in [0, upper]: `fallback` when absent (older records).
int OptionalCount(const nlohmann::json& j, const char* key, int upper, int fallback, const std::string& where) {
  if (!j.contains(key)) return fallback;
  const nlohmann::json& v = j[key];
  if (!v.is_number_integer() || v.get<std::int64_t>() < 0 || v.get<std::int64_t>() > upper)
    KeyError(where, key, "expected an integer from 0 to " + std::to_string(upper) + ", got " + DescribeJson(v));
  return v.get<int>();
}
double NumberInRange(const nlohmann::json& j, const char* key, double lower, double upper, const std::string& where) {
  const double v = RequiredKey<double>(j, key, where);
  if (!(v >= lower && v <= upper))
    KeyError(where, key,
             "expected a number in [" + FormatDouble(lower) + ", " + FormatDouble(upper) + "], got " + FormatDouble(v));
  return v;
}
}  // namespace

// ---- frames.jsonl ----------------------------------------------------------

namespace {
// The fields the protocols add to a frame's record and the fits read: each
// of its type when present, so a fit never meets a mistyped one.
enum class Field { kNumber, kNonNegative, kInteger, kString, kBool, kNumberArray };
struct ProtocolField {
  const char* key;
  Field type;
};
constexpr ProtocolField kProtocolFields[] = {
    {"light", Field::kString},
    {"kind", Field::kString},
    {"charge_s", Field::kNonNegative},
    {"light_off_s", Field::kNumber},
    {"delay_after_light_off_s", Field::kNumber},
    {"delay_s", Field::kNumber},
    {"tail", Field::kInteger},
    {"tail_frames", Field::kInteger},
    {"mean_signal_dn", Field::kNumberArray},
    {"column_mean_dn", Field::kNumberArray},
    {"saturated_fraction", Field::kNonNegative},
    {"peak_column_fraction", Field::kNonNegative},
    {"wavelength_nm", Field::kNonNegative},
    {"temperature_k", Field::kNonNegative},
    {"irradiance", Field::kNonNegative},
    {"lvf", Field::kBool},
};

void CheckProtocolFields(const nlohmann::json& fields, const std::string& where) {
  for (const ProtocolField& f : kProtocolFields) {
    auto it = fields.find(f.key);
    if (it == fields.end()) continue;
    const nlohmann::json& v = *it;
    switch (f.type) {
      case Field::kNumber: RequiredKey<double>(fields, f.key, where); break;
      case Field::kNonNegative: NumberInRange(fields, f.key, 0, std::numeric_limits<double>::max(), where); break;
      case Field::kInteger: {
        const int n = RequiredKey<int>(fields, f.key, where);
        if (n < 0 || n > 1000) KeyError(where, f.key, "expected 0 to 1000, got " + std::to_string(n));
        break;
      }
      case Field::kString: RequiredKey<std::string>(fields, f.key, where); break;
      case Field::kBool:
        if (!v.is_boolean()) KeyError(where, f.key, "expected true or false, got " + DescribeJson(v));
        break;
      case Field::kNumberArray:
        if (!v.is_array() || v.empty() || v.size() > 65536)
          KeyError(where, f.key, "expected an array of numbers, got " + DescribeJson(v));
        for (const nlohmann::json& x : v)
          if (!x.is_number() || !std::isfinite(x.get<double>()))
            KeyError(where, f.key, "expected finite numbers, got " + DescribeJson(x));
        break;
    }
  }
}
}  // namespace

nlohmann::json FrameRecord::ToJson() const {
  nlohmann::json j = protocol.is_object() ? protocol : nlohmann::json::object();
  j["file"] = file;
  j["seq"] = seq;
  j["t_start_s"] = t_start_s;
  j["exposure_s"] = exposure_s;
  j["gain"] = gain;
  j["black_level_dn"] = black_level_dn;
  j["adc_bits"] = adc_bits;
  j["sensor_temperature_c"] = sensor_temperature_c;
  if (camera_timestamp_ns != 0) j["camera_timestamp_ns"] = camera_timestamp_ns;
  j["packets_resent"] = packets_resent;
  j["retakes"] = retakes;
  if (size_bytes) j["size_bytes"] = *size_bytes;
  if (!xxh3.empty()) j["xxh3"] = xxh3;
  if (run != 0) j["run"] = run;
  return j;
}

FrameRecord FrameRecord::FromJson(const nlohmann::json& j, const std::string& where) {
  FrameRecord r;
  r.seq = RequiredKey<int>(j, "seq", where);
  if (r.seq < 1) KeyError(where, "seq", "expected a frame number >= 1, got " + std::to_string(r.seq));
  r.file = RequiredKey<std::string>(j, "file", where);
  if (r.file != FrameFileName(r.seq))
    KeyError(where, "file", "expected " + FrameFileName(r.seq) + " (the frame's seq), got " + DescribeJson(j["file"]));
  r.t_start_s = RequiredKey<double>(j, "t_start_s", where);
  r.exposure_s = NumberInRange(j, "exposure_s", kMinExposureS, kMaxExposureS, where);
  r.gain = j.contains("gain") ? NumberInRange(j, "gain", 1e-6, 1e6, where) : 1.0;
  r.black_level_dn = j.contains("black_level_dn") ? NumberInRange(j, "black_level_dn", 0, 4294967295.0, where) : 0.0;
  r.adc_bits = j.contains("adc_bits") ? RequiredKey<int>(j, "adc_bits", where) : 16;
  if (r.adc_bits < 1 || r.adc_bits > 32)
    KeyError(where, "adc_bits", "expected 1 to 32, got " + std::to_string(r.adc_bits));
  if (r.black_level_dn >= std::ldexp(1.0, r.adc_bits) - 1)
    KeyError(where, "black_level_dn", "is at or above the ADC's range (" + std::to_string(r.adc_bits) + " bits)");
  r.sensor_temperature_c = OptionalNumber(j, "sensor_temperature_c", 0.0, where);
  if (j.contains("camera_timestamp_ns")) {
    if (!j["camera_timestamp_ns"].is_number_unsigned())
      KeyError(where, "camera_timestamp_ns",
               "expected a non-negative integer, got " + DescribeJson(j["camera_timestamp_ns"]));
    r.camera_timestamp_ns = j["camera_timestamp_ns"].get<std::uint64_t>();
  }
  if (j.contains("packets_resent")) {
    if (!j["packets_resent"].is_number_unsigned())
      KeyError(where, "packets_resent", "expected a non-negative integer, got " + DescribeJson(j["packets_resent"]));
    r.packets_resent = j["packets_resent"].get<std::uint64_t>();
  }
  r.retakes = OptionalCount(j, "retakes", 1000, 0, where);
  if (j.contains("size_bytes")) {
    if (!j["size_bytes"].is_number_unsigned())
      KeyError(where, "size_bytes", "expected a non-negative integer, got " + DescribeJson(j["size_bytes"]));
    r.size_bytes = j["size_bytes"].get<std::uint64_t>();
  }
  if (j.contains("xxh3")) {
    r.xxh3 = RequiredKey<std::string>(j, "xxh3", where);
    if (r.xxh3.size() != 16 || r.xxh3.find_first_not_of("0123456789abcdef") != std::string::npos)
      KeyError(where, "xxh3", "expected 16 hex digits, got " + DescribeJson(j["xxh3"]));
  }
  r.run = OptionalCount(j, "run", 100000, 0, where);
  r.protocol = j;
  for (const char* key : kFrameRecordKeys) r.protocol.erase(key);
  CheckProtocolFields(r.protocol, where);
  return r;
}

FrameRecords ReadFrameRecords(const fs::path& session_dir) {
  const fs::path path = session_dir / "frames.jsonl";
  const JsonLinesFile file = ReadJsonLinesFile(path);
  FrameRecords records;
  records.torn = file.torn;
  std::set<int> seen;
  int last = 0, last_run = 0;
  double last_t_s = -std::numeric_limits<double>::infinity();
  for (const JsonLine& line : file.records) {
    const std::string where = path.string() + ":" + std::to_string(line.line);
    FrameRecord frame = FrameRecord::FromJson(line.value, where);
    if (!seen.insert(frame.seq).second)
      ThrowUserError(where, "seq", "frame " + std::to_string(frame.seq) + " is listed twice");
    if (frame.seq < last)
      ThrowUserError(where, "seq", "frame " + std::to_string(frame.seq) + " comes after frame " + std::to_string(last));
    // A record from before runs were counted has none: its run is told by
    // its clock, which started anew at each resume (a frame earlier than the
    // one before it began the next run).
    if (!line.value.contains("run")) frame.run = last_run + (frame.t_start_s < last_t_s);
    if (frame.run < last_run)
      ThrowUserError(where, "run", "run " + std::to_string(frame.run) + " comes after run " + std::to_string(last_run));
    last = frame.seq;
    last_run = frame.run;
    last_t_s = frame.t_start_s;
    records.frames.push_back(std::move(frame));
    records.lines.push_back(line.line);
  }
  return records;
}

std::string CheckFrameFile(const fs::path& session_dir, const FrameRecord& frame) {
  const fs::path path = session_dir / frame.file;
  std::error_code ec;
  const fs::file_status status = fs::symlink_status(path, ec);
  if (!fs::exists(status)) return "is missing";
  if (!fs::is_regular_file(status)) return "is not a regular file";
  const std::uint64_t size = fs::file_size(path, ec);
  if (ec) return "cannot be read (" + ec.message() + ")";
  if (frame.size_bytes && size != *frame.size_bytes)
    return "is " + std::to_string(size) + " bytes where its record says " + std::to_string(*frame.size_bytes) +
           " (truncated or replaced)";
  if (!frame.xxh3.empty()) {
    try {
      const FileDigest digest = DigestFile(path);
      if (digest.xxh3 != frame.xxh3) return "has checksum " + digest.xxh3 + " where its record says " + frame.xxh3;
    } catch (const UserError& e) {
      return std::string("cannot be read (") + e.what() + ")";
    }
  }
  if (size == 0) return "is empty";
  return "";
}

void RequireGoodFrames(const fs::path& session_dir, const FrameRecords& records) {
  for (std::size_t i = 0; i < records.frames.size(); ++i) {
    const std::string problem = CheckFrameFile(session_dir, records.frames[i]);
    if (!problem.empty())
      ThrowUserError(
          (session_dir / records.frames[i].file).string(), "",
          problem + " (frames.jsonl:" + std::to_string(records.lines[i]) +
              "); 'phos capture verify' lists every problem, 'phos capture resume' measures again what can be");
  }
}

// ---- record checksums -------------------------------------------------------

std::string RecordChecksum(const nlohmann::json& record) {
  nlohmann::json without = record;
  if (without.is_object()) without.erase(kRecordChecksumKey);
  // Invalid UTF-8 cannot reach a record (the parser refuses it), and a
  // record phos builds holds only its own strings; replace rather than throw.
  const std::string text = without.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  return Xxh3Hex(text.data(), text.size());
}

nlohmann::json WithRecordChecksum(nlohmann::json record) {
  record[kRecordChecksumKey] = RecordChecksum(record);
  return record;
}

std::string RecordChecksumProblem(const nlohmann::json& record) {
  if (!record.is_object() || !record.contains(kRecordChecksumKey)) return std::string("has no ") + kRecordChecksumKey;
  const nlohmann::json& written = record[kRecordChecksumKey];
  const std::string now = RecordChecksum(record);
  if (!written.is_string() || written.get<std::string>() != now)
    return "does not match its " + std::string(kRecordChecksumKey) + " (" + DescribeJson(written) +
           "; its numbers give " + now + "): changed after it was written";
  return "";
}

namespace {

// A whole-file record (session.json, stop.json) against its checksum.
void CheckRecordFile(const fs::path& path, bool required, std::vector<std::string>* problems) {
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(path, ec))) return;
  nlohmann::json record;
  try {
    record = ReadJsonFile(path);
  } catch (const UserError&) {
    return;  // a record that does not read is its reader's problem, said there
  }
  const std::string problem = RecordChecksumProblem(record);
  if (!problem.empty() && (required || record.contains(kRecordChecksumKey)))
    problems->push_back(path.string() + ": " + problem);
}

void CheckRecordLines(const fs::path& path, bool required, std::vector<std::string>* problems) {
  JsonLinesFile file;
  try {
    file = ReadJsonLinesFile(path);
  } catch (const UserError&) {
    return;
  }
  for (const JsonLine& line : file.records) {
    const std::string problem = RecordChecksumProblem(line.value);
    if (!problem.empty() && (required || line.value.contains(kRecordChecksumKey)))
      problems->push_back(path.string() + ":" + std::to_string(line.line) + ": " + problem);
  }
}

// Frame records that give their file no size and checksum: nothing tells a
// frame replaced by another image (even one of the right size) from the one
// taken.
void CheckFrameFileChecksums(const fs::path& path, std::vector<std::string>* problems) {
  JsonLinesFile file;
  try {
    file = ReadJsonLinesFile(path);
  } catch (const UserError&) {
    return;
  }
  for (const JsonLine& line : file.records)
    if (!line.value.contains("xxh3") || !line.value.contains("size_bytes"))
      problems->push_back(path.string() + ":" + std::to_string(line.line) +
                          ": gives no xxh3 and size_bytes for its frame file, so nothing can check the file");
}

}  // namespace

std::vector<std::string> RecordChecksumProblems(const fs::path& session_dir) {
  std::vector<std::string> problems;
  bool required = true;
  try {
    required = ReadJsonFile(session_dir / "session.json").value("schema", "") != kSessionSchemaWithoutChecksums;
  } catch (const UserError&) {
    // No readable start record: its reader says so; check what can be.
  } catch (const nlohmann::json::exception&) {}
  CheckRecordFile(session_dir / "session.json", required, &problems);
  CheckRecordLines(session_dir / "frames.jsonl", required, &problems);
  CheckFrameFileChecksums(session_dir / "frames.jsonl", &problems);
  CheckRecordLines(session_dir / "events.jsonl", required, &problems);
  CheckRecordFile(session_dir / "stop.json", required, &problems);
  return problems;
}

void RequireRecordChecksums(const fs::path& session_dir) {
  const std::vector<std::string> problems = RecordChecksumProblems(session_dir);
  if (!problems.empty())
    ThrowUserError("", "",
                   problems.front() +
                       " ('phos capture verify' lists every problem; a record whose numbers changed "
                       "cannot be trusted)");
}

// ---- session.json ----------------------------------------------------------

nlohmann::json SessionRecord::ToJson() const {
  nlohmann::json j = {
      {"schema", schema}, {"protocol", protocol}, {"uid", uid},           {"started_utc", started_utc},
      {"sample", sample}, {"devices", devices},   {"settings", settings}, {"versions", {{"phos", phos_version}}}};
  if (!part_of.empty()) j["part_of"] = part_of;
  if (resume > 0) j["resume"] = resume;
  return j;
}

SessionRecord SessionRecord::FromJson(const nlohmann::json& j, const std::string& where) {
  SessionRecord r;
  r.schema = RequiredKey<std::string>(j, "schema", where);
  if (r.schema != kSessionSchema && r.schema != kSessionSchemaWithoutChecksums)
    KeyError(where, "schema",
             std::string("expected \"") + kSessionSchema + "\" (or \"" + kSessionSchemaWithoutChecksums + "\"), got " +
                 DescribeJson(j["schema"]));
  r.protocol = RequiredKey<std::string>(j, "protocol", where);
  static const std::set<std::string> kProtocols = {"lvf-calibration", "spectrum", "decay", "excitation", "all"};
  if (!kProtocols.count(r.protocol))
    KeyError(where, "protocol",
             "expected lvf-calibration, spectrum, decay, excitation or all, got " + DescribeJson(j["protocol"]));
  r.uid = RequiredKey<std::string>(j, "uid", where);
  r.started_utc = RequiredKey<std::string>(j, "started_utc", where);
  r.sample = j.contains("sample") ? RequiredKey<nlohmann::json>(j, "sample", where) : nlohmann::json::object();
  // Optional objects: a protocol run through the library may record none;
  // the readers that need a value inside them name it when it is missing.
  if (j.contains("devices")) r.devices = RequiredKey<nlohmann::json>(j, "devices", where);
  if (j.contains("settings")) r.settings = RequiredKey<nlohmann::json>(j, "settings", where);
  if (j.contains("versions")) {
    const nlohmann::json versions = RequiredKey<nlohmann::json>(j, "versions", where);
    if (versions.contains("phos")) r.phos_version = RequiredKey<std::string>(versions, "phos", where + ": versions");
  }
  if (j.contains("part_of")) r.part_of = RequiredKey<std::string>(j, "part_of", where);
  if (j.contains("resume")) r.resume = RequiredKey<int>(j, "resume", where);
  return r;
}

SessionRecord ReadSessionRecord(const fs::path& session_dir) {
  const fs::path path = session_dir / "session.json";
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))
    ThrowUserError(session_dir.string(), "", "is not a capture session (no session.json)");
  return SessionRecord::FromJson(ReadJsonFile(path), path.string());
}

// ---- stop.json -------------------------------------------------------------

nlohmann::json StopRecord::ToJson() const {
  nlohmann::json j = {{"how", how}};
  if (frames >= 0) j["frames"] = frames;  // the signal handler's record cannot count
  if (!stopped_utc.empty()) j["stopped_utc"] = stopped_utc;
  if (!why.empty()) j["why"] = why;
  return j;
}

StopRecord StopRecord::FromJson(const nlohmann::json& j, const std::string& where) {
  StopRecord r;
  r.how = RequiredKey<std::string>(j, "how", where);
  if (r.how != "complete" && r.how != "aborted" && r.how != "failed")
    KeyError(where, "how", "expected complete, aborted or failed, got " + DescribeJson(j["how"]));
  // The signal handler's record has no count (it may not allocate): the
  // frame list is then the only count.
  r.frames = j.contains("frames") ? RequiredKey<int>(j, "frames", where) : -1;
  if (j.contains("why")) r.why = RequiredKey<std::string>(j, "why", where);
  if (j.contains("stopped_utc")) r.stopped_utc = RequiredKey<std::string>(j, "stopped_utc", where);
  return r;
}

std::optional<StopRecord> ReadStopRecord(const fs::path& session_dir) {
  const fs::path path = session_dir / "stop.json";
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(path, ec))) return std::nullopt;
  return StopRecord::FromJson(ReadJsonFile(path), path.string());
}

// ---- events.jsonl ----------------------------------------------------------

std::vector<nlohmann::json> ReadEventRecords(const fs::path& session_dir) {
  const fs::path path = session_dir / "events.jsonl";
  const JsonLinesFile file = ReadJsonLinesFile(path);
  std::vector<nlohmann::json> events;
  for (const JsonLine& line : file.records) {
    const std::string where = path.string() + ":" + std::to_string(line.line);
    RequiredKey<std::string>(line.value, "event", where);
    if (line.value.contains("t_s")) RequiredKey<double>(line.value, "t_s", where);
    events.push_back(line.value);
  }
  return events;
}

}  // namespace phos
