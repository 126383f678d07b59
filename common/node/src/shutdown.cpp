// Process-wide shutdown state: signal handlers, a futex-backed flag, Spin and Rate.
#include <linux/futex.h>
#include <signal.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <climits>
#include <cmath>
#include <ctime>
#include <mutex>
#include <sstream>

#include "probeless/node/node.h"

namespace probeless::node {
namespace {

// 0 while running, 1 once shutdown was requested. A futex word: waiters sleep on it.
std::atomic<uint32_t> g_shutdown{0};
// SIGINT/SIGTERM received so far.
std::atomic<int> g_signals{0};

static_assert(std::atomic<uint32_t>::is_always_lock_free && sizeof(g_shutdown) == 4);

uint32_t* FutexWord() { return reinterpret_cast<uint32_t*>(&g_shutdown); }

void OnSignal(int signal_number) {
  const int saved_errno = errno;
  if (g_signals.fetch_add(1) >= 1) _exit(128 + signal_number);  // second signal: leave now
  RequestShutdown();
  errno = saved_errno;
}

}  // namespace

void InstallSignalHandlers() {
  static std::once_flag once;
  std::call_once(once, [] {
    struct sigaction action {};
    action.sa_handler = OnSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
  });
}

bool ok() { return g_shutdown.load(std::memory_order_acquire) == 0; }

void RequestShutdown() {
  g_shutdown.store(1, std::memory_order_release);
  ::syscall(SYS_futex, FutexWord(), FUTEX_WAKE_PRIVATE, INT_MAX, nullptr, nullptr, 0);
}

bool WaitForShutdown(std::chrono::nanoseconds timeout) {
  using Clock = std::chrono::steady_clock;
  // Clamp absurd timeouts (e.g. nanoseconds::max()) to a year so the deadline cannot overflow.
  timeout = std::min<std::chrono::nanoseconds>(timeout, std::chrono::hours(24 * 365));
  const Clock::time_point deadline = Clock::now() + timeout;
  while (ok()) {
    const auto remaining = deadline - Clock::now();
    if (remaining <= std::chrono::nanoseconds::zero()) return false;
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(remaining).count();
    timespec relative{};
    relative.tv_sec = static_cast<time_t>(ns / 1'000'000'000);
    relative.tv_nsec = static_cast<long>(ns % 1'000'000'000);
    // Sleeps only while the word is still 0; EINTR, EAGAIN and timeouts all re-check above.
    ::syscall(SYS_futex, FutexWord(), FUTEX_WAIT_PRIVATE, 0u, &relative, nullptr, 0);
  }
  return true;
}

void Spin(bus::WaitSet& wait_set, const std::function<void(size_t)>& on_ready) {
  while (ok()) {
    for (size_t index : wait_set.Wait(kShutdownPollPeriod)) {
      if (!ok()) return;
      on_ready(index);
    }
  }
}

void Spin(const std::vector<Handler>& handlers) {
  bus::WaitSet wait_set;
  std::vector<const Handler*> by_index;
  for (const Handler& handler : handlers) {
    const size_t index = wait_set.Add(*handler.subscriber);
    if (by_index.size() <= index) by_index.resize(index + 1, nullptr);
    by_index[index] = &handler;
  }
  Spin(wait_set, [&](size_t index) {
    const Handler& handler = *by_index.at(index);
    // Drain at most one queue's worth so a fast topic cannot starve the others.
    for (uint32_t n = 0; n < bus::kMaxQueueDepth && ok(); ++n) {
      std::optional<bus::Sample> sample = handler.subscriber->TryTake();
      if (!sample) break;
      handler.on_sample(std::move(*sample));
    }
  });
}

Rate::Rate(double hz) {
  if (!std::isfinite(hz) || hz <= 0) {
    std::ostringstream text;
    text << "invalid rate " << hz << " Hz (expected a finite value > 0)";
    throw NodeError(text.str());
  }
  period_ = std::chrono::nanoseconds(static_cast<int64_t>(std::llround(1e9 / hz)));
  if (period_.count() < 1) period_ = std::chrono::nanoseconds(1);
  next_ = std::chrono::steady_clock::now() + period_;
}

bool Rate::Sleep() {
  const auto now = std::chrono::steady_clock::now();
  if (now < next_) {
    if (WaitForShutdown(next_ - now)) return false;
  } else if (now - next_ > period_) {
    next_ = now;  // more than a period behind: restart the schedule instead of bursting
  }
  next_ += period_;
  return ok();
}

}  // namespace probeless::node
