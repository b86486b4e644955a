// Sessions that never lie (docs/capture.md, "The record format"): the typed
// records, torn lines, checksums, a resume that verifies, and crash
// consistency after the way SQLite and the ALICE study (Pillai et al., OSDI
// 2014) test storage: every file of a session cut at every record boundary
// and inside its last record, then resumed and verified.

#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>

#include <cstdio>
#include <cstring>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <gtest/gtest.h>

#include "phos/acquire/protocols.h"
#include "phos/acquire/session_records.h"
#include "phos/acquire/sim_lab.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "phos/util/random.h"
#include "test_util.h"

namespace phos {
namespace {
namespace fs = std::filesystem;

ExcitationProtocolOptions SmallExcitation() {
  ExcitationProtocolOptions options;
  options.lights = {"led405"};
  options.exposure_s = 0.2;
  options.reset_s = 100;
  options.max_charge_s = 8;
  options.tail_frames = 2;
  return options;
}

struct Lab {
  VirtualClock clock;
  Material orange = LoadMaterial(testing::Fixture("materials/orange.json"));
  CameraModel camera = [] {
    CameraModel c = DefaultCameraModel();
    c.width = 16;
    c.height = 12;
    return c;
  }();
  SimulatedLab lab{orange, std::vector<double>(8, 0.8), DefaultLights(), camera, clock};
};

void CaptureExcitation(const fs::path& dir) {
  Lab lab;
  SessionWriter session(dir, {{"protocol", "excitation"}});
  RunExcitationProtocol(lab.lab, lab.lab.lights(), lab.clock, session, SmallExcitation());
}

void ResumeExcitation(const fs::path& dir) {
  Lab lab;
  std::unique_ptr<SessionWriter> session = SessionWriter::Reopen(dir);
  RunExcitationProtocol(lab.lab, lab.lab.lights(), lab.clock, *session, SmallExcitation(), ReadExcitationDone(dir));
}

std::string Bytes(const fs::path& path) { return testing::ReadText(path); }
void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
}

// The measurements a complete excitation session holds, by (charge, tail).
std::set<std::pair<double, int>> Measured(const fs::path& dir) {
  std::set<std::pair<double, int>> measured;
  for (const FrameRecord& f : ReadFrameRecords(dir).frames)
    measured.insert({f.protocol["charge_s"].get<double>(), f.protocol["tail"].get<int>()});
  return measured;
}

TEST(SessionRecords, FrameRecordsRoundTripAndNameWhatIsWrong) {
  testing::TempDir dir;
  CaptureExcitation(dir / "s");
  const FrameRecords records = ReadFrameRecords(dir / "s");
  ASSERT_GT(records.frames.size(), 5u);
  for (const FrameRecord& f : records.frames) {
    EXPECT_TRUE(f.size_bytes.has_value());
    EXPECT_EQ(f.xxh3.size(), 16u);
    EXPECT_EQ(CheckFrameFile(dir / "s", f), "");
    const FrameRecord again = FrameRecord::FromJson(f.ToJson(), "x");
    EXPECT_EQ(again.ToJson(), f.ToJson());
  }
  // stop.json counts what frames.jsonl lists.
  EXPECT_EQ(ReadStopRecord(dir / "s")->frames, static_cast<int>(records.frames.size()));
  const nlohmann::json good = records.frames[0].ToJson();
  struct Case {
    const char* key;
    nlohmann::json value;  // null: the key removed
    const char* expected;
  } cases[] = {
      {"exposure_s", nullptr, "exposure_s: missing"},
      {"exposure_s", 5e-324, "exposure_s: expected a number in"},
      {"exposure_s", "1", "exposure_s: expected a finite number"},
      {"seq", 0, "seq: expected a frame number >= 1"},
      {"file", "../../etc/passwd", "file: expected frames/000001.tif"},
      {"xxh3", "zz", "xxh3: expected 16 hex digits"},
      {"size_bytes", -3, "size_bytes: expected a non-negative integer"},
      {"mean_signal_dn", "bright", "mean_signal_dn: expected an array of numbers"},
      {"tail", 1.5, "tail: expected an integer"},
      {"retakes", -1, "retakes: expected an integer from 0 to 1000"},
      {"retakes", 1.5, "retakes: expected an integer from 0 to 1000"},
      {"packets_resent", "3", "packets_resent: expected a non-negative integer"},
      {"packets_resent", -2, "packets_resent: expected a non-negative integer"},
      {"run", -1, "run: expected an integer from 0 to 100000"},
      {"run", 1.5, "run: expected an integer from 0 to 100000"},
  };
  for (const Case& c : cases) {
    nlohmann::json bad = good;
    if (c.value.is_null())
      bad.erase(c.key);
    else
      bad[c.key] = c.value;
    try {
      FrameRecord::FromJson(bad, "s/frames.jsonl:1");
      ADD_FAILURE() << c.key << " accepted";
    } catch (const UserError& e) {
      EXPECT_NE(std::string(e.what()).find(c.expected), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).rfind("s/frames.jsonl:1", 0), 0u) << e.what();
    }
  }
}

// Keeps the first `keep` lines of frames.jsonl and their files, as a kill would.
void CutFrames(const fs::path& dir, std::size_t keep) {
  const std::vector<nlohmann::json> lines = ReadJsonLines(dir / "frames.jsonl");
  std::ofstream out(dir / "frames.jsonl", std::ios::trunc);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    if (i < keep)
      out << lines[i].dump() << "\n";
    else
      fs::remove(dir / lines[i]["file"].get<std::string>());
  }
  fs::remove(dir / "stop.json");
}

TEST(SessionRecords, EachResumeIsARunWhoseClockStartsAnew) {
  testing::TempDir dir;
  CaptureExcitation(dir / "s");
  CutFrames(dir / "s", 4);
  ResumeExcitation(dir / "s");
  const std::size_t after_first = ReadFrameRecords(dir / "s").frames.size();
  CutFrames(dir / "s", after_first - 2);
  ResumeExcitation(dir / "s");
  const FrameRecords records = ReadFrameRecords(dir / "s");
  for (std::size_t i = 0; i < records.frames.size(); ++i) {
    const int expected = i < 4 ? 0 : i < after_first - 2 ? 1 : 2;
    EXPECT_EQ(records.frames[i].run, expected) << i;
    // The first frame of each run is earlier on its clock than the last of the run before.
    if (i > 0 && records.frames[i].run != records.frames[i - 1].run) {
      EXPECT_LT(records.frames[i].t_start_s, records.frames[i - 1].t_start_s) << i;
    }
  }
  // Written as a session from before runs were counted, the clock tells them.
  std::vector<nlohmann::json> lines = ReadJsonLines(dir / "s" / "frames.jsonl");
  {
    std::ofstream out(dir / "s" / "frames.jsonl", std::ios::trunc);
    for (nlohmann::json line : lines) {
      line.erase("run");
      out << line.dump() << "\n";
    }
  }
  const FrameRecords inferred = ReadFrameRecords(dir / "s");
  ASSERT_EQ(inferred.frames.size(), records.frames.size());
  for (std::size_t i = 0; i < records.frames.size(); ++i) EXPECT_EQ(inferred.frames[i].run, records.frames[i].run) << i;
  // A run listed before an earlier one is refused, naming the line.
  lines[3]["run"] = 1;
  lines[4]["run"] = 0;
  {
    std::ofstream out(dir / "s" / "frames.jsonl", std::ios::trunc);
    for (const nlohmann::json& line : lines) out << line.dump() << "\n";
  }
  try {
    ReadFrameRecords(dir / "s");
    ADD_FAILURE() << "runs out of order accepted";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("frames.jsonl:5: run: run 0 comes after run 1"), std::string::npos)
        << e.what();
  }
}

TEST(SessionRecords, TheLinksResendsAndRetakesAreRecordedAndOlderRecordsWithoutThemStillLoad) {
  testing::TempDir dir;
  CaptureExcitation(dir / "s");
  const std::vector<JsonLine> lines = ReadJsonLinesFile(dir / "s" / "frames.jsonl").records;
  ASSERT_FALSE(lines.empty());
  // The simulated lab has no packet link: every frame came whole at once.
  for (const JsonLine& line : lines) {
    EXPECT_EQ(line.value.at("packets_resent"), 0) << line.line;
    EXPECT_EQ(line.value.at("retakes"), 0) << line.line;
  }
  // As written by a camera that worked for it, through text, and back.
  FrameRecord record = FrameRecord::FromJson(lines[0].value, "x");
  record.packets_resent = 17;
  record.retakes = 2;
  const FrameRecord again = FrameRecord::FromJson(nlohmann::json::parse(record.ToJson().dump()), "x");
  EXPECT_EQ(again.packets_resent, 17u);
  EXPECT_EQ(again.retakes, 2);
  EXPECT_FALSE(again.protocol.contains("retakes"));  // a record field, not a protocol's
  // A session recorded before they were counted loads, with 0 for both.
  nlohmann::json older = lines[0].value;
  older.erase("packets_resent");
  older.erase("retakes");
  const FrameRecord old_record = FrameRecord::FromJson(older, "x");
  EXPECT_EQ(old_record.packets_resent, 0u);
  EXPECT_EQ(old_record.retakes, 0);
}

// A record's own checksum survives the trip through its file (written,
// read back as text, parsed) for any numbers it holds, and any change of one
// number, however small, is found.
TEST(SessionRecords, ARecordChecksumSurvivesItsFileAndFindsEveryChangedNumber) {
  SplitMix64 random(20261207);
  for (int trial = 0; trial < 2000; ++trial) {
    nlohmann::json record = {{"seq", static_cast<int>(random.Next() % 1000000) + 1},
                             {"run", static_cast<std::uint64_t>(random.Next() % 7)},
                             {"light", "led" + std::to_string(random.Next() % 1000)},
                             {"note", "\u00e9t\u00e9 \u2192 \"q\"\n"}};
    std::vector<double> numbers;
    for (int i = 0; i < 6; ++i) {
      // Any finite double: random bit patterns, subnormals and huge values included.
      double v = 0;
      do {
        const std::uint64_t bits = random.Next();
        std::memcpy(&v, &bits, sizeof v);
      } while (!std::isfinite(v));
      numbers.push_back(v);
    }
    record["exposure_s"] = numbers[0];
    record["mean_signal_dn"] = std::vector<double>(numbers.begin() + 1, numbers.end());
    const nlohmann::json signed_record = WithRecordChecksum(record);
    const nlohmann::json read_back = nlohmann::json::parse(signed_record.dump() + "\n");
    ASSERT_EQ(RecordChecksumProblem(read_back), "") << signed_record.dump();
    ASSERT_EQ(RecordChecksumProblem(nlohmann::json::parse(signed_record.dump(2))), "");
    // One number moved by one unit in the last place.
    nlohmann::json changed = read_back;
    const int which = static_cast<int>(random.Next() % 5);
    double& v = numbers[1 + which];
    changed["mean_signal_dn"][which] = std::nextafter(v, v > 0 ? 0.0 : 1.0);
    EXPECT_NE(RecordChecksumProblem(changed).find("does not match its record_xxh3"), std::string::npos);
    changed = read_back;
    changed["exposure_s"] = numbers[0] * 4;
    if (numbers[0] != 0 && std::isfinite(numbers[0] * 4)) {
      EXPECT_NE(RecordChecksumProblem(changed).find("changed after it was written"), std::string::npos);
    }
  }
  EXPECT_EQ(RecordChecksumProblem(nlohmann::json{{"event", "x"}}), "has no record_xxh3");
  nlohmann::json wrong_type = WithRecordChecksum({{"event", "x"}});
  wrong_type[kRecordChecksumKey] = 7;
  EXPECT_NE(RecordChecksumProblem(wrong_type), "");
}

TEST(SessionRecords, ATornLastLineIsSkippedAndSetAsideNeverGluedOnto) {
  testing::TempDir dir;
  const fs::path path = dir / "a.jsonl";
  WriteBytes(path, "{\"event\":\"one\"}\n{\"event\":\"tw");
  JsonLinesFile file = ReadJsonLinesFile(path);
  ASSERT_EQ(file.records.size(), 1u);
  ASSERT_TRUE(file.torn);
  EXPECT_EQ(*file.torn, "{\"event\":\"tw");
  SetAsideTornLine(path, file);
  AppendJsonLine(path, {{"event", "three"}});
  EXPECT_EQ(Bytes(path), "{\"event\":\"one\"}\n{\"event\":\"three\"}\n");
  EXPECT_EQ(Bytes(dir / "a.jsonl.torn"), "{\"event\":\"tw\n");
  // A bad line that is not the last is corruption: one line naming it.
  WriteBytes(path, "{\"event\":\"one\"}\nnot json\n{\"event\":\"three\"}\n");
  try {
    ReadJsonLinesFile(path);
    ADD_FAILURE();
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("a.jsonl:2"), std::string::npos) << e.what();
  }
}

// Cut each record file at every record boundary and at points inside its
// last record; resume must finish every measurement, verify must find the
// result whole, and no check may call a cut session complete.
TEST(SessionRecords, EveryCutOfEveryRecordFileResumesToAWholeSession) {
  testing::TempDir dir;
  CaptureExcitation(dir / "whole");
  const std::set<std::pair<double, int>> expected = Measured(dir / "whole");
  int cases = 0, refused_complete = 0;
  for (const char* name : {"frames.jsonl", "events.jsonl"}) {
    const std::string bytes = Bytes(dir / "whole" / name);
    std::vector<std::size_t> cuts;
    for (std::size_t i = 0; i < bytes.size(); ++i)
      if (bytes[i] == '\n') cuts.push_back(i + 1);  // at a boundary
    const std::size_t last_start = bytes.rfind('\n', bytes.size() - 2) + 1;
    for (std::size_t inside : {last_start + 1, (last_start + bytes.size()) / 2, bytes.size() - 1})
      cuts.push_back(inside);  // inside the last record
    // Every boundary of frames.jsonl, every fourth of events.jsonl (it has
    // several lines per frame): the boundaries differ only in what is lost.
    const std::size_t stride = std::string(name) == "events.jsonl" ? 4 : 1;
    for (std::size_t k = 0; k < cuts.size(); ++k) {
      if (k % stride != 0 && k + 3 < cuts.size()) continue;
      const fs::path s = dir / ("cut-" + std::to_string(cases));
      fs::copy(dir / "whole", s, fs::copy_options::recursive);
      WriteBytes(s / name, bytes.substr(0, cuts[k]));
      fs::remove(s / "stop.json");  // the crash left none
      const SessionCheck before = CheckSession(s);
      EXPECT_FALSE(before.complete()) << name << " cut at " << cuts[k];
      refused_complete += !before.complete();
      ResumeExcitation(s);
      const SessionCheck after = CheckSession(s);
      EXPECT_TRUE(after.complete() && after.clean())
          << name << " cut at " << cuts[k] << ": " << (after.problems.empty() ? "" : after.problems.front());
      EXPECT_EQ(Measured(s), expected) << name << " cut at " << cuts[k];
      fs::remove_all(s);
      ++cases;
    }
  }
  std::printf("crash consistency: %d cuts of frames.jsonl and events.jsonl resumed to whole sessions\n", cases);
  EXPECT_GT(cases, 20);
  EXPECT_EQ(refused_complete, cases);
}

TEST(SessionRecords, ABadFrameIsFoundSetAsideAndMeasuredAgain) {
  testing::TempDir dir;
  CaptureExcitation(dir / "whole");
  const std::set<std::pair<double, int>> expected = Measured(dir / "whole");
  const FrameRecords records = ReadFrameRecords(dir / "whole");
  int cases = 0;
  for (std::size_t i = 0; i < records.frames.size(); i += 3) {
    for (int damage = 0; damage < 3; ++damage) {
      const fs::path s = dir / ("bad-" + std::to_string(cases++));
      fs::copy(dir / "whole", s, fs::copy_options::recursive);
      const fs::path frame = s / records.frames[i].file;
      const std::string bytes = Bytes(frame);
      if (damage == 0) WriteBytes(frame, bytes.substr(0, bytes.size() / 2));  // truncated
      if (damage == 1) fs::remove(frame);                                     // missing
      if (damage == 2) {                                                      // same size, one byte flipped
        std::string flipped = bytes;
        flipped[flipped.size() / 2] ^= 0x40;
        WriteBytes(frame, flipped);
      }
      const SessionCheck check = CheckSession(s);
      ASSERT_EQ(check.bad_frames.size(), 1u) << damage;
      EXPECT_EQ(check.bad_frames[0].frame.seq, records.frames[i].seq);
      EXPECT_TRUE(check.complete() && !check.clean());  // stop says complete; verify says not whole
      // The fits refuse it, naming the frame.
      try {
        RequireGoodFrames(s, ReadFrameRecords(s));
        ADD_FAILURE() << "a bad frame passed";
      } catch (const UserError& e) {
        EXPECT_NE(std::string(e.what()).find(records.frames[i].file), std::string::npos) << e.what();
      }
      ResumeExcitation(s);
      const SessionCheck after = CheckSession(s);
      EXPECT_TRUE(after.complete() && after.clean()) << (after.problems.empty() ? "" : after.problems.front());
      EXPECT_EQ(Measured(s), expected);
      if (damage != 1) {
        EXPECT_TRUE(fs::exists(frame.string() + ".bad-1"));  // kept aside, not overwritten
      }
      fs::remove_all(s);
    }
  }
  // Where a frame cannot be measured again (a decay), resume refuses in one
  // line naming it, and the session stays as it was.
  fs::copy(dir / "whole", dir / "kept", fs::copy_options::recursive);
  WriteBytes(dir / "kept" / records.frames[0].file, "");
  try {
    SessionWriter::Reopen(dir / "kept", false);
    ADD_FAILURE() << "resumed over a bad frame";
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find(records.frames[0].file), std::string::npos) << e.what();
  }
  EXPECT_TRUE(ReadStopRecord(dir / "kept").has_value());
  std::printf("bad frames: %d damaged frames found, set aside and measured again\n", cases);
}

// A real full disk: a 16 KiB tmpfs (CI runs as root). The capture fails in
// one line naming the file it could not write; what is listed stays valid,
// and resume on a roomy disk finishes the session.
TEST(SessionRecords, AFullDiskLosesNothingListedAndResumeFinishesOnARoomyOne) {
  testing::TempDir dir;
  const fs::path mount_point = dir / "small";
  fs::create_directories(mount_point);
  if (::mount("tmpfs", mount_point.c_str(), "tmpfs", 0, "size=16k") != 0)
    GTEST_SKIP() << "cannot mount a tmpfs here (not root?): the full-disk test needs one";
  struct Unmount {
    fs::path path;
    ~Unmount() { ::umount2(path.c_str(), MNT_DETACH); }
  } unmount{mount_point};
  const fs::path s = mount_point / "s";
  std::string error;
  try {
    CaptureExcitation(s);
  } catch (const UserError& e) {
    error = e.what();
  }
  ASSERT_FALSE(error.empty()) << "the capture fitted in 16 KiB";
  EXPECT_EQ(error.find('\n'), std::string::npos);
  EXPECT_NE(error.find(s.string()), std::string::npos) << error;  // names the file, inside the session
  EXPECT_EQ(error.find("stop.json"), std::string::npos) << error;
  std::printf("full disk: %s\n", error.c_str());
  const SessionCheck check = CheckSession(s);
  EXPECT_FALSE(check.complete());
  EXPECT_TRUE(check.bad_frames.empty()) << check.bad_frames.front().problem;
  for (const std::string& problem : check.problems) EXPECT_NE(problem.find("stop.json: counts"), 0u) << problem;
  // On a roomy disk.
  fs::copy(s, dir / "roomy", fs::copy_options::recursive);
  ResumeExcitation(dir / "roomy");
  const SessionCheck after = CheckSession(dir / "roomy");
  EXPECT_TRUE(after.complete() && after.clean()) << (after.problems.empty() ? "" : after.problems.front());
  testing::TempDir reference;
  CaptureExcitation(reference / "s");
  EXPECT_EQ(Measured(dir / "roomy"), Measured(reference / "s"));
}

// A write cut short at every byte of a frame's file (RLIMIT_FSIZE: every
// write past N bytes of any file fails, EFBIG, as a disk that fills up at
// that point). OpenImageIO's TIFF writer reported success for a frame the
// full disk had cut short, and the cut frame was listed with its checksum: a
// decay then could never complete. Whatever byte the write stops at, what
// the session lists is whole, and the capture says so in one line.
TEST(SessionRecords, AWriteCutAtAnyByteOfAFrameListsNothingBroken) {
  testing::TempDir dir;
  // A decay of tiny frames (8x8, about 700 bytes each) under a start record
  // smaller than one, so the limit first cuts a frame's file.
  // One lab, made before the children fork (each capture runs on its copy).
  VirtualClock clock;
  CameraModel camera = DefaultCameraModel();
  camera.width = camera.height = 8;
  SimulatedLab lab(LoadMaterial(testing::Fixture("materials/orange.json")), std::vector<double>(8, 0.8),
                   DefaultLights(), camera, clock);
  auto capture = [&](const fs::path& out) {
    DecayProtocolOptions options;
    options.charge_light = "led405";
    options.charge_s = 60;
    options.duration_s = 20;
    SessionWriter session(out, {{"protocol", "decay"}});
    RunDecayProtocol(lab, lab.lights(), clock, session, options);
  };
  // The cut sessions on a tmpfs where one can be mounted (as root, as CI
  // is): hundreds of captures, each fsync'ing its records.
  const fs::path cuts = dir / "cuts";
  fs::create_directories(cuts);
  struct Unmount {
    fs::path path;
    bool mounted;
    ~Unmount() {
      if (mounted) ::umount2(path.c_str(), MNT_DETACH);
    }
  } unmount{cuts, ::mount("tmpfs", cuts.c_str(), "tmpfs", 0, "size=64m") == 0};
  capture(dir / "whole");
  const std::uint64_t frame_bytes = fs::file_size(dir / "whole" / "frames" / "000001.tif");
  const std::uint64_t start_bytes = fs::file_size(dir / "whole" / "session.json");
  ASSERT_LT(start_bytes + 16, frame_bytes);
  int cut = 0;
  for (std::uint64_t limit = start_bytes + 1; limit <= frame_bytes + 1; ++limit) {
    const fs::path s = cuts / ("cut-" + std::to_string(limit));
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      std::signal(SIGXFSZ, SIG_IGN);
      const rlimit r{limit, limit};
      ::setrlimit(RLIMIT_FSIZE, &r);
      try {
        capture(s);
      } catch (const UserError&) {
        std::_Exit(3);
      } catch (...) {
        std::_Exit(4);
      }
      std::_Exit(0);
    }
    int status = 0;
    ::waitpid(child, &status, 0);
    ASSERT_TRUE(WIFEXITED(status)) << limit;
    ASSERT_NE(WEXITSTATUS(status), 4) << "not a UserError at " << limit;
    cut += WEXITSTATUS(status) == 3;
    // Everything listed reads back whole.
    const SessionCheck check = CheckSession(s);
    EXPECT_TRUE(check.bad_frames.empty())
        << "limit " << limit << ": " << check.bad_frames.front().frame.file << " " << check.bad_frames.front().problem;
    fs::remove_all(s);
  }
  EXPECT_GT(cut, 0);
  std::printf("writes cut at each of %d bytes of a frame: nothing listed is broken\n", cut);
}

}  // namespace
}  // namespace phos
