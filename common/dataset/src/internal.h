// Private building blocks of the dataset sources: the per-frame Source base class, message
// construction, option checks and the factory of each kind.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "probeless/dataset/datasets.h"
#include "probeless/dataset/source.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::dataset::internal {

// A Source whose pass is a sequence of frames, each frame a fixed group of messages sharing one
// log time (e.g. camera info, image, depth, pose). Subclasses fill topics_ and implement
// ReadFrame; this class queues a frame's messages, applies max_frames and rewinds.
class FrameSource : public Source {
 public:
  // `frame_limit`: frames per pass at most (0 = until ReadFrame reports the end).
  FrameSource(std::string kind, std::string path, uint64_t frame_limit);

  std::string_view kind() const override { return kind_; }
  const std::string& path() const override { return path_; }
  const std::vector<TopicInfo>& topics() const override { return topics_; }
  std::optional<StreamMessage> Next() override;
  void Rewind() override;
  std::optional<std::pair<uint64_t, uint64_t>> time_range() const override { return time_range_; }

 protected:
  // Appends the messages of frame `index` (0-based, frames read in order 0, 1, 2, ... within a
  // pass) to `out` in their output order; returns false at the end of the pass (nothing
  // appended). Throws DatasetError on a bad file; the pass then continues with the next frame.
  virtual bool ReadFrame(uint64_t index, std::vector<StreamMessage>& out) = 0;
  // Called by Rewind() before the next pass.
  virtual void OnRewind() {}

  // Adds a topic of message type M and returns its index.
  template <msgs::Message M>
  size_t AddTopic(const std::string& topic, size_t max_message_bytes, uint64_t message_count) {
    topics_.push_back(TopicInfo{topic, std::string(M::kTypeName), M::kLayoutHash, max_message_bytes,
                                message_count});
    return topics_.size() - 1;
  }

  std::vector<TopicInfo> topics_;
  std::optional<std::pair<uint64_t, uint64_t>> time_range_;

 private:
  std::string kind_;
  std::string path_;
  uint64_t frame_limit_ = 0;
  uint64_t next_frame_ = 0;
  bool ended_ = false;
  std::deque<StreamMessage> pending_;
};

// A zeroed message of `bytes` bytes on topic `topic_index` at `log_time_ns`.
StreamMessage NewMessage(size_t topic_index, uint64_t log_time_ns, size_t bytes);

// Sets a header: stamp_ns = `stamp_ns`, stamp_mono_ns = 0 (a recording has no monotonic clock),
// sequence, frame_id.
void FillHeader(msgs::Header& header, int64_t stamp_ns, uint64_t sequence,
                std::string_view frame_id);

// Log time of frame `index` at `fps` frames per second: round(index * 1e9 / fps) ns.
uint64_t FrameTimeNs(uint64_t index, double fps);

// Frames to play out of `available`, honouring options.max_frames.
uint64_t LimitFrames(uint64_t available, const DatasetOptions& options);

// Throws DatasetError unless the options are usable (fps > 0, absolute topic prefixes, frame ids
// of at most 31 characters, Yale B subjects only for "yaleb").
void CheckOptions(const DatasetOptions& options, std::string_view kind);

// "<prefix>/<name>".
std::string TopicName(const std::string& prefix, std::string_view name);

// The sorted regular-file names (not paths) in folder `dir`. Throws DatasetError if `dir` is not a
// readable folder.
std::vector<std::string> ListFiles(const std::string& dir);
// The sorted sub-folder names in folder `dir`.
std::vector<std::string> ListFolders(const std::string& dir);
// `dir` + "/" + `name` (no doubled '/').
std::string JoinPath(const std::string& dir, const std::string& name);
// Lower-case extension without the dot ("png"); "" if none.
std::string LowerExtension(const std::string& name);
// Whether `name` ends in .png, .jpg, .jpeg, .pgm, .ppm or .bmp (any case).
bool IsImageFileName(const std::string& name);

// The factories of each kind; `path` exists. Same contract as OpenDataset.
std::unique_ptr<Source> OpenSevenScenes(const std::string& path, const DatasetOptions& options);
std::unique_ptr<Source> OpenTum(const std::string& path, const DatasetOptions& options);
std::unique_ptr<Source> OpenYaleB(const std::string& path, const DatasetOptions& options);
std::unique_ptr<Source> OpenImages(const std::string& path, const DatasetOptions& options);
std::unique_ptr<Source> OpenVideo(const std::string& path, const DatasetOptions& options);

}  // namespace probeless::dataset::internal
