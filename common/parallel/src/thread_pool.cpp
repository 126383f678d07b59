#include "probeless/parallel/thread_pool.h"

#include <atomic>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace probeless::parallel {

struct ThreadPool::Impl {
  std::vector<std::thread> workers;
  std::mutex run_mutex;  // serialises ParallelFor callers
  std::mutex mutex;
  std::condition_variable wake;
  std::condition_variable done;
  const std::function<void(size_t)>* fn = nullptr;
  size_t count = 0;
  std::atomic<size_t> next{0};
  size_t active = 0;  // workers inside the current job
  uint64_t generation = 0;
  bool stop = false;
  std::exception_ptr error;

  // Takes indices until none are left; on an exception records it and skips the rest.
  void Work() {
    for (;;) {
      const size_t i = next.fetch_add(1);
      if (i >= count) return;
      try {
        (*fn)(i);
      } catch (...) {
        std::lock_guard lock(mutex);
        if (!error) error = std::current_exception();
        next = count;
      }
    }
  }

  void Loop() {
    uint64_t seen = 0;
    std::unique_lock lock(mutex);
    for (;;) {
      wake.wait(lock, [&] { return stop || generation != seen; });
      if (stop) return;
      seen = generation;
      ++active;
      lock.unlock();
      Work();
      lock.lock();
      if (--active == 0) done.notify_all();
    }
  }
};

ThreadPool::ThreadPool(int threads) : impl_(std::make_unique<Impl>()) {
  if (threads < 1) {
    throw InputError("ThreadPool: threads must be >= 1, got " + std::to_string(threads));
  }
  for (int i = 1; i < threads; ++i) impl_->workers.emplace_back([this] { impl_->Loop(); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->stop = true;
  }
  impl_->wake.notify_all();
  for (auto& t : impl_->workers) t.join();
}

int ThreadPool::thread_count() const { return static_cast<int>(impl_->workers.size()) + 1; }

void ThreadPool::ParallelFor(size_t count, const std::function<void(size_t)>& fn) {
  if (count == 0) return;
  Impl& p = *impl_;
  std::lock_guard run(p.run_mutex);
  {
    std::unique_lock lock(p.mutex);
    // Workers still leaving the previous job (they saw no index left) must be out of Work().
    p.done.wait(lock, [&] { return p.active == 0; });
    p.fn = &fn;
    p.count = count;
    p.next = 0;
    p.error = nullptr;
    ++p.generation;
  }
  p.wake.notify_all();
  p.Work();
  std::exception_ptr error;
  {
    std::unique_lock lock(p.mutex);
    p.done.wait(lock, [&] { return p.active == 0; });
    error = p.error;
    p.fn = nullptr;
    p.count = 0;
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace probeless::parallel
