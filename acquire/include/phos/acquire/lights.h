#pragma once
// Lights: named channels (LED 365 nm, LED 405 nm, white LED, lamp, shutter)
// that a protocol switches. Every switch is recorded with its time on the
// protocol's clock, and lights are left off on every way out: LightsOffGuard
// switches them off when it goes out of scope (normal end, error, exception),
// and the signal handler (InstallLightsOffOnSignal) does it on SIGINT and
// SIGTERM before the process ends.

#include <functional>
#include <string>
#include <vector>

#include "phos/acquire/clock.h"

namespace phos {

struct LightEvent {
  double t_s;  // on the protocol's clock
  std::string channel;
  bool on;
};

class Lights {
 public:
  virtual ~Lights() = default;
  virtual std::vector<std::string> channels() const = 0;
  // Throws UserError for an unknown channel.
  virtual void Set(const std::string& channel, bool on) = 0;
  virtual bool IsOn(const std::string& channel) const = 0;
  void AllOff();
};

// Lights that only record (the simulated lab reads their state; tests assert
// the timing). `before_change(channel, on)` runs just before every switch,
// while the old state still holds (the simulated sample advances to that
// moment); it may refuse a switch on by throwing, never a switch off.
class RecordingLights final : public Lights {
 public:
  RecordingLights(std::vector<std::string> channels, const Clock& clock);
  std::vector<std::string> channels() const override { return channels_; }
  void Set(const std::string& channel, bool on) override;
  bool IsOn(const std::string& channel) const override;
  const std::vector<LightEvent>& events() const { return events_; }
  std::function<void(const std::string& channel, bool on)> before_change;

 private:
  std::vector<std::string> channels_;
  std::vector<bool> state_;
  const Clock& clock_;
  std::vector<LightEvent> events_;
};

// Switches every light off when destroyed, and while it lives, on SIGINT or
// SIGTERM too (then the process exits with 128 + signal, as a shell expects).
// After the lights, the signal handler runs the cleanup registered with
// SetSignalCleanup (the open session records that it was aborted).
class LightsOffGuard {
 public:
  explicit LightsOffGuard(Lights& lights);
  ~LightsOffGuard();
  LightsOffGuard(const LightsOffGuard&) = delete;
  LightsOffGuard& operator=(const LightsOffGuard&) = delete;

 private:
  Lights& lights_;
};

// Lights off even when capture dies by kill -9, a crash or the OOM killer,
// which no handler sees. The guardian is a child process forked when the
// lights are opened: it inherits their handles (GPIO line requests are file
// descriptors, shared across fork), ignores SIGINT and SIGTERM (a Ctrl-C to
// the terminal reaches the whole process group, and the guardian must
// outlive capture), and blocks reading a pipe whose only writer is capture.
// When capture ends in any way, the pipe closes: the guardian switches every
// light off through its own copy and exits. A normal end tells it to stand
// down first (the lights are off then). Its pid is for tests and logs.
class LightsGuardian {
 public:
  explicit LightsGuardian(Lights& lights);
  ~LightsGuardian();  // stands down
  LightsGuardian(const LightsGuardian&) = delete;
  LightsGuardian& operator=(const LightsGuardian&) = delete;
  int pid() const { return pid_; }

 private:
  int pid_ = -1;
  int pipe_fd_ = -1;  // the write end
};

// A function the SIGINT/SIGTERM handler calls after switching the lights off
// and before the process ends, with the channels it switched off (so the
// session can log them); it must be async-signal-safe (nullptr: none).
using SignalCleanup = void (*)(int signal_number, const char* const* switched_off, int switched_off_count);
void SetSignalCleanup(SignalCleanup cleanup);

}  // namespace phos
