// A tiny fixed-size thread pool for data-parallel loops of the reconstruction. Work is split into
// tasks whose results the caller stores per task index, so reductions are deterministic whatever
// the thread count.
#pragma once

#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace probeless::recon {

class ThreadPool {
 public:
  // `threads` >= 1 threads in all (the calling thread is one of them). Throws ReconError for 0.
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int threads() const { return static_cast<int>(workers_.size()) + 1; }
  // Calls fn(task) once for every task in [0, tasks), spread over the threads; returns when all
  // are done. Not re-entrant (fn must not call Run on the same pool). Exceptions thrown by fn are
  // rethrown here (the first one).
  void Run(int tasks, const std::function<void(int)>& fn);

 private:
  void Work(uint64_t generation);
  void Loop();
  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  const std::function<void(int)>* fn_ = nullptr;
  int tasks_ = 0;
  int next_ = 0;
  int finished_ = 0;
  int busy_workers_ = 0;
  uint64_t generation_ = 0;
  bool stop_ = false;
  std::exception_ptr error_;
};

// Runs fn(task) for every task on `pool`, or serially when pool is null.
inline void ParallelFor(ThreadPool* pool, int tasks, const std::function<void(int)>& fn) {
  if (pool == nullptr || pool->threads() == 1 || tasks <= 1) {
    for (int i = 0; i < tasks; ++i) fn(i);
  } else {
    pool->Run(tasks, fn);
  }
}

}  // namespace probeless::recon
