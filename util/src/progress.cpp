#include "phos/util/progress.h"

#include <cstdio>
#include <unistd.h>

namespace phos {

ProgressBar::ProgressBar(std::string label, std::size_t total)
    : label_(std::move(label)),
      total_(total),
      enabled_(::isatty(STDERR_FILENO) == 1),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

ProgressBar::~ProgressBar() { Finish(); }

void ProgressBar::Advance(std::size_t count) {
  done_ += count;
  if (enabled_) Draw(false);
}

void ProgressBar::Finish() {
  if (!enabled_ || finished_) return;
  Draw(true);
  std::fputc('\n', stderr);
  finished_ = true;
}

void ProgressBar::Print(std::FILE* stream, const std::string& line) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (enabled_ && !finished_) {
      std::fputs("\r\033[K", stderr);  // the bar's line cleared
      std::fflush(stderr);
    }
    std::fprintf(stream, "%s\n", line.c_str());
    std::fflush(stream);
  }
  if (enabled_ && !finished_) Draw(true);
}

void ProgressBar::Draw(bool force) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto now = std::chrono::steady_clock::now();
  if (!force && now - last_draw_ < std::chrono::milliseconds(200)) return;
  last_draw_ = now;
  std::size_t done = std::min<std::size_t>(done_, total_);
  double fraction = total_ ? static_cast<double>(done) / static_cast<double>(total_) : 1.0;
  const int width = 30;
  int filled = static_cast<int>(fraction * width);
  double elapsed = std::chrono::duration<double>(now - start_).count();
  double eta = fraction > 0 ? elapsed * (1 - fraction) / fraction : 0;
  std::fprintf(stderr, "\r%s [%.*s%*s] %zu/%zu  %.0f s elapsed, ~%.0f s left ", label_.c_str(), filled,
               "##############################", width - filled, "", done, total_, elapsed, eta);
  std::fflush(stderr);
}

}  // namespace phos
