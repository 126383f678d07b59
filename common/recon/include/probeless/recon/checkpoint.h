// Fusion's map across a restart (issue #22): files for FusionPipeline::Checkpoint() written so
// that a reader - the node respawned after a kill -9 - sees the previous complete file or the
// new complete one, never a part, and a writer thread so a frame does not wait for the disk.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

namespace probeless::recon {

// Writes `bytes` to `path` atomically: into `path` + ".tmp" (replaced), fsync'd, renamed over
// `path`, and the directory fsync'd. Throws ReconError "checkpoint '<path>': cannot <step>:
// <reason>" if any step fails (`path` is then unchanged).
void WriteFileAtomically(const std::string& path, std::span<const std::byte> bytes);

// The whole file at `path`; std::nullopt if there is none. Throws ReconError "checkpoint
// '<path>': cannot read: <reason>" if it exists but cannot be read.
std::optional<std::vector<std::byte>> ReadFileIfExists(const std::string& path);

// Writes checkpoints of one path on a thread of its own with WriteFileAtomically. Submit hands
// over the newest checkpoint; one still waiting (the disk slower than the checkpoints) is replaced
// by it, not queued, so at most one is pending and one in flight. A failed write is rethrown (its
// ReconError) by the next Submit, Flush or Discard.
class CheckpointWriter {
 public:
  explicit CheckpointWriter(std::string path);
  // Finishes the pending write (errors are dropped here: call Flush first to see them).
  ~CheckpointWriter();
  CheckpointWriter(const CheckpointWriter&) = delete;
  CheckpointWriter& operator=(const CheckpointWriter&) = delete;

  const std::string& path() const { return path_; }
  // Queues `bytes` for writing (an empty vector is ignored).
  void Submit(std::vector<std::byte> bytes);
  // Returns once everything submitted is on disk (or throws the write's error).
  void Flush();
  // Drops the pending checkpoint, waits for the one in flight and removes the file (a map that
  // was reset must not come back on a restart). Throws ReconError if the file cannot be removed.
  void Discard();
  // Checkpoints written so far.
  uint64_t written() const;

 private:
  void Run();
  void RethrowLocked();

  std::string path_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;  // to the thread: something pending or stop
  std::condition_variable idle_;  // from the thread: a write finished
  std::optional<std::vector<std::byte>> pending_;
  bool busy_ = false;
  bool stop_ = false;
  uint64_t written_ = 0;
  std::exception_ptr error_;
  std::thread thread_;  // last: starts after the members above exist
};

}  // namespace probeless::recon
