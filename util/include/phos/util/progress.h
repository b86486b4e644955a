#pragma once
// A progress bar on stderr for long work (sequences, batches, studies).
// Drawn only when stderr is a terminal, so logs and CI output stay clean;
// thread-safe, and throttled to a few updates per second.

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdio>
#include <mutex>
#include <string>

namespace phos {

class ProgressBar {
 public:
  ProgressBar(std::string label, std::size_t total);
  ~ProgressBar();  // finishes the line
  void Advance(std::size_t count = 1);
  void Finish();
  // Prints a whole line (without its newline) to `stream` and flushes it,
  // above the bar when there is one (cleared, then drawn again), so that
  // results can be reported as they come while the bar runs, and a log
  // (stream not a terminal) has each as soon as it is known.
  void Print(std::FILE* stream, const std::string& line);

 private:
  void Draw(bool force);
  std::string label_;
  std::size_t total_;
  std::atomic<std::size_t> done_{0};
  bool enabled_;
  bool finished_ = false;
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_, last_draw_;
};

}  // namespace phos
