// The project's one thread pool for data-parallel loops: a fixed set of std::threads that run the
// indices of a loop, the calling thread working too. Every index runs exactly once; which thread
// runs it is unspecified, so callers that need deterministic results store them per index (or per
// fixed chunk) and reduce afterwards in index order.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>

#include "probeless/error/error.h"

namespace probeless::parallel {

class ThreadPool {
 public:
  // `threads` >= 1 threads in all, the caller of ParallelFor included (threads - 1 are started).
  // Throws InputError (probeless/error/error.h) for threads < 1.
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  // Threads in all (>= 1).
  int thread_count() const;
  // Calls fn(i) once for every i in [0, count), spread over the threads, and returns when all
  // calls have returned. The first exception thrown by fn is rethrown here (indices not started
  // yet are then skipped). Not re-entrant: fn must not call ParallelFor on the same pool; calls
  // from different threads are serialised.
  void ParallelFor(size_t count, const std::function<void(size_t)>& fn);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// fn(i) for every i in [0, count) on `pool`, or in order on the calling thread when pool is null,
// has one thread, or count <= 1.
inline void ParallelFor(ThreadPool* pool, size_t count, const std::function<void(size_t)>& fn) {
  if (pool == nullptr || pool->thread_count() == 1 || count <= 1) {
    for (size_t i = 0; i < count; ++i) fn(i);
  } else {
    pool->ParallelFor(count, fn);
  }
}

}  // namespace probeless::parallel
