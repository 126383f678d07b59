#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <system_error>

#include "internal.h"
#include "probeless/msgs/layout.h"

namespace probeless::dataset::internal {

namespace fs = std::filesystem;

FrameSource::FrameSource(std::string kind, std::string path, uint64_t frame_limit)
    : kind_(std::move(kind)), path_(std::move(path)), frame_limit_(frame_limit) {}

std::optional<StreamMessage> FrameSource::Next() {
  while (pending_.empty()) {
    if (ended_ || (frame_limit_ != 0 && next_frame_ >= frame_limit_)) return std::nullopt;
    const uint64_t index = next_frame_++;
    std::vector<StreamMessage> frame;
    if (!ReadFrame(index, frame)) {
      ended_ = true;
      return std::nullopt;
    }
    for (auto& message : frame) pending_.push_back(std::move(message));
  }
  StreamMessage message = std::move(pending_.front());
  pending_.pop_front();
  return message;
}

void FrameSource::Rewind() {
  pending_.clear();
  next_frame_ = 0;
  ended_ = false;
  OnRewind();
}

StreamMessage NewMessage(size_t topic_index, uint64_t log_time_ns, size_t bytes) {
  StreamMessage message;
  message.topic_index = topic_index;
  message.log_time_ns = log_time_ns;
  message.message = log::MessageBuffer(bytes);
  return message;
}

void FillHeader(msgs::Header& header, int64_t stamp_ns, uint64_t sequence,
                std::string_view frame_id) {
  header.stamp_ns = stamp_ns;
  header.stamp_mono_ns = 0;
  header.sequence = sequence;
  header.SetFrameId(frame_id);
}

uint64_t FrameTimeNs(uint64_t index, double fps) {
  return static_cast<uint64_t>(std::llround(static_cast<double>(index) * 1e9 / fps));
}

uint64_t LimitFrames(uint64_t available, const DatasetOptions& options) {
  return options.max_frames == 0 ? available : std::min(available, options.max_frames);
}

namespace {
void CheckPrefix(const std::string& prefix, std::string_view option) {
  bool ok = prefix.size() >= 2 && prefix.front() == '/' && prefix.back() != '/' &&
            prefix.find("//") == std::string::npos;
  for (char c : prefix) {
    const bool allowed = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                         (c >= '0' && c <= '9') || c == '_' || c == '/';
    ok = ok && allowed;
  }
  if (!ok) {
    throw DatasetError("dataset option " + std::string(option) + " '" + prefix +
                       "' is not an absolute topic prefix (expected e.g. /camera: letters, "
                       "digits, '_' and single '/', no trailing '/')");
  }
}
void CheckFrameId(const std::string& id, std::string_view option) {
  if (id.empty() || id.size() >= msgs::kFrameIdCapacity) {
    throw DatasetError("dataset option " + std::string(option) + " '" + id +
                       "' must have 1 to 31 characters");
  }
}
}  // namespace

void CheckOptions(const DatasetOptions& options, std::string_view kind) {
  if (!(options.fps > 0) || !std::isfinite(options.fps)) {
    throw DatasetError("dataset option fps " + std::to_string(options.fps) +
                       " must be a positive number of frames per second");
  }
  CheckPrefix(options.topic_prefix, "topic_prefix");
  CheckPrefix(options.ground_truth_prefix, "ground_truth_prefix");
  CheckFrameId(options.camera_frame_id, "camera_frame_id");
  CheckFrameId(options.world_frame_id, "world_frame_id");
  if (!options.yaleb_subjects.empty() && kind != "yaleb") {
    throw DatasetError("dataset option yaleb_subjects applies to yaleb datasets only, not " +
                       std::string(kind));
  }
  for (int subject : options.yaleb_subjects) {
    if (subject < 1 || subject > 99) {
      throw DatasetError("dataset option yaleb_subjects: subject " + std::to_string(subject) +
                         " out of range 1..99");
    }
  }
}

std::string TopicName(const std::string& prefix, std::string_view name) {
  return prefix + "/" + std::string(name);
}

namespace {
std::vector<std::string> ListEntries(const std::string& dir, bool folders) {
  std::error_code error;
  fs::directory_iterator it(dir, error);
  if (error) {
    throw DatasetError("cannot list folder '" + dir + "': " + error.message());
  }
  std::vector<std::string> names;
  for (const fs::directory_entry& entry : it) {
    std::error_code type_error;
    const bool match = folders ? entry.is_directory(type_error) : entry.is_regular_file(type_error);
    if (match && !type_error) names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}
}  // namespace

std::vector<std::string> ListFiles(const std::string& dir) { return ListEntries(dir, false); }
std::vector<std::string> ListFolders(const std::string& dir) { return ListEntries(dir, true); }

std::string JoinPath(const std::string& dir, const std::string& name) {
  if (dir.empty()) return name;
  if (dir.back() == '/') return dir + name;
  return dir + "/" + name;
}

std::string LowerExtension(const std::string& name) {
  const size_t dot = name.rfind('.');
  if (dot == std::string::npos || dot == 0 || name.find('/', dot) != std::string::npos) return "";
  std::string ext = name.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

}  // namespace probeless::dataset::internal
