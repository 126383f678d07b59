// The reconstruction's data-parallel loops run on the project's one thread pool
// (probeless/parallel/thread_pool.h); this header keeps recon's int-indexed spelling of the loop.
#pragma once

#include <functional>

#include "probeless/parallel/thread_pool.h"

namespace probeless::recon {

using parallel::ThreadPool;

// Runs fn(task) for every task in [0, tasks) on `pool`, or serially in order when pool is null
// (parallel::ParallelFor). Results that callers store per task index are deterministic.
inline void ParallelFor(ThreadPool* pool, int tasks, const std::function<void(int)>& fn) {
  if (tasks <= 0) return;
  parallel::ParallelFor(pool, static_cast<size_t>(tasks),
                        [&fn](size_t task) { fn(static_cast<int>(task)); });
}

}  // namespace probeless::recon
