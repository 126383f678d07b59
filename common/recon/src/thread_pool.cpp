#include "probeless/recon/thread_pool.h"

#include "probeless/recon/math.h"

namespace probeless::recon {

ThreadPool::ThreadPool(int threads) {
  if (threads < 1)
    throw ReconError("ThreadPool: threads must be >= 1, got " + std::to_string(threads));
  for (int i = 1; i < threads; ++i) workers_.emplace_back([this] { Loop(); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (auto& w : workers_) w.join();
}

void ThreadPool::Work(uint64_t generation) {
  for (;;) {
    int task;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (generation != generation_ || next_ >= tasks_) return;
      task = next_++;
    }
    try {
      (*fn_)(task);
    } catch (...) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++finished_;
      if (finished_ == tasks_) done_.notify_all();
    }
  }
}

void ThreadPool::Loop() {
  uint64_t seen = 0;
  for (;;) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
      ++busy_workers_;
    }
    Work(seen);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      --busy_workers_;
      if (busy_workers_ == 0) done_.notify_all();
    }
  }
}

void ThreadPool::Run(int tasks, const std::function<void(int)>& fn) {
  uint64_t generation;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    fn_ = &fn;
    tasks_ = tasks;
    next_ = 0;
    finished_ = 0;
    error_ = nullptr;
    generation = ++generation_;
  }
  wake_.notify_all();
  Work(generation);
  std::exception_ptr error;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, [&] { return finished_ == tasks_ && busy_workers_ == 0; });
    fn_ = nullptr;
    error = error_;
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace probeless::recon
