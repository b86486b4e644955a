#include "phos/acquire/clock.h"

#include <thread>

namespace phos {

double SystemClock::now_s() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void SystemClock::SleepUntil(double t_s) {
  const double wait = t_s - now_s();
  if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
}

}  // namespace phos
