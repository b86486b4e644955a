#pragma once
// Time for protocols: a monotonic clock and sleeps. The same protocol code
// runs on the system clock with real hardware and on a virtual clock in the
// simulated lab, where a 90-minute charge takes no time at all.

#include <chrono>

namespace phos {

class Clock {
 public:
  virtual ~Clock() = default;
  // Seconds on a monotonic clock (its zero is arbitrary).
  virtual double now_s() const = 0;
  virtual void SleepUntil(double t_s) = 0;
  void SleepFor(double seconds) { SleepUntil(now_s() + seconds); }
};

class SystemClock final : public Clock {
 public:
  double now_s() const override;
  void SleepUntil(double t_s) override;
};

// Time moves only when someone sleeps (or advances it): deterministic, instant.
class VirtualClock final : public Clock {
 public:
  explicit VirtualClock(double start_s = 0) : now_(start_s) {}
  double now_s() const override { return now_; }
  void SleepUntil(double t_s) override {
    if (t_s > now_) now_ = t_s;
  }
  void Advance(double seconds) { SleepUntil(now_ + seconds); }

 private:
  double now_;
};

}  // namespace phos
