#include "phos/acquire/lights.h"

#include <algorithm>
#include <atomic>
#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cerrno>
#include <cstdlib>
#include <mutex>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

void Lights::AllOff() {
  for (const std::string& channel : channels())
    if (IsOn(channel)) Set(channel, false);
}

RecordingLights::RecordingLights(std::vector<std::string> channels, const Clock& clock)
    : channels_(std::move(channels)), state_(channels_.size(), false), clock_(clock) {}

void RecordingLights::Set(const std::string& channel, bool on) {
  auto it = std::find(channels_.begin(), channels_.end(), channel);
  if (it == channels_.end()) {
    ThrowUserError("", "light", "unknown channel '" + channel + "' (this lab has: " + JoinComma(channels_) + ")");
  }
  if (before_change) before_change(channel, on);
  state_[static_cast<std::size_t>(it - channels_.begin())] = on;
  events_.push_back({clock_.now_s(), channel, on});
}

bool RecordingLights::IsOn(const std::string& channel) const {
  auto it = std::find(channels_.begin(), channels_.end(), channel);
  return it != channels_.end() && state_[static_cast<std::size_t>(it - channels_.begin())];
}

namespace {
// The lights a signal must switch off. One guard at a time is enough for a
// protocol; nested guards keep the outermost.
Lights* g_guarded = nullptr;
struct sigaction g_previous_int, g_previous_term;

std::atomic<SignalCleanup> g_cleanup{nullptr};

extern "C" void SwitchOffAndExit(int signal_number) {
  // Not async-signal-safe in general, but the process ends right after, and
  // a lab would rather the lights go off than the process end cleanly.
  // The channels that were on, by name, for the session's events.jsonl.
  static char names[32][128];
  static const char* switched_off[32];
  int count = 0;
  if (g_guarded != nullptr) {
    for (const std::string& channel : g_guarded->channels()) {
      if (!g_guarded->IsOn(channel)) continue;
      try {
        g_guarded->Set(channel, false);
      } catch (...) {
        continue;  // the hardware refused: nothing to log as off
      }
      if (count < 32) {
        std::snprintf(names[count], sizeof names[count], "%s", channel.c_str());
        switched_off[count] = names[count];
        ++count;
      }
    }
  }
  if (SignalCleanup cleanup = g_cleanup.load()) cleanup(signal_number, switched_off, count);
  std::_Exit(128 + signal_number);
}
}  // namespace

void SetSignalCleanup(SignalCleanup cleanup) { g_cleanup.store(cleanup); }

LightsGuardian::LightsGuardian(Lights& lights) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) ThrowUserError("", "lights", "cannot start the lights guardian (pipe)");
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    ThrowUserError("", "lights", "cannot start the lights guardian (fork)");
  }
  if (pid == 0) {
    // The guardian. Only the read end stays open here, so EOF means
    // capture has gone.
    ::close(fds[1]);
    std::signal(SIGINT, SIG_IGN);
    std::signal(SIGTERM, SIG_IGN);
    std::signal(SIGPIPE, SIG_IGN);
    ::prctl(PR_SET_NAME, "phos-guardian");
    char byte = 0;
    ssize_t n;
    do {
      n = ::read(fds[0], &byte, 1);
    } while (n < 0 && errno == EINTR);
    if (n == 1 && byte == 'd') ::_exit(0);  // stood down: capture ended normally
    // Capture died (or its parent changed: it was killed before we read).
    (void)parent;
    try {
      lights.AllOff();
    } catch (...) {}
    ::_exit(0);
  }
  ::close(fds[0]);
  pid_ = pid;
  pipe_fd_ = fds[1];
}

LightsGuardian::~LightsGuardian() {
  if (pipe_fd_ >= 0) {
    const char stand_down = 'd';
    const ssize_t ignored = ::write(pipe_fd_, &stand_down, 1);
    (void)ignored;
    ::close(pipe_fd_);
  }
  if (pid_ > 0) ::waitpid(pid_, nullptr, 0);
}

LightsOffGuard::LightsOffGuard(Lights& lights) : lights_(lights) {
  if (g_guarded == nullptr) {
    g_guarded = &lights;
    struct sigaction action {};
    action.sa_handler = SwitchOffAndExit;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, &g_previous_int);
    sigaction(SIGTERM, &action, &g_previous_term);
  }
}

LightsOffGuard::~LightsOffGuard() {
  try {
    lights_.AllOff();
  } catch (...) {
    // Nothing more can be done from a destructor; the signal handler and the
    // hardware's own watchdog are the next lines of defence.
  }
  if (g_guarded == &lights_) {
    sigaction(SIGINT, &g_previous_int, nullptr);
    sigaction(SIGTERM, &g_previous_term, nullptr);
    g_guarded = nullptr;
  }
}

}  // namespace phos
