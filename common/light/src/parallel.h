// Row-parallel loops on a few std::threads (dynamic chunks; results must not depend on which
// thread runs a chunk, so they stay deterministic).
#pragma once

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

namespace probeless::light::internal {

template <class Fn>
void ParallelRows(int threads, int rows, int chunk, const Fn& fn) {
  std::atomic<int> next{0};
  auto work = [&] {
    for (int begin = next.fetch_add(chunk); begin < rows; begin = next.fetch_add(chunk)) {
      fn(begin, std::min(rows, begin + chunk));
    }
  };
  const int extra = std::max(0, std::min(threads, (rows + chunk - 1) / chunk) - 1);
  std::vector<std::thread> pool;
  pool.reserve(extra);
  for (int t = 0; t < extra; ++t) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
}

}  // namespace probeless::light::internal
