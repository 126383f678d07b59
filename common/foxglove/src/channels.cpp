#include "probeless/foxglove/channels.h"

#include <algorithm>
#include <regex>
#include <set>

#include "probeless/bus/bus.h"
#include "probeless/log/mcap.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/image.h"

namespace probeless::foxglove {
namespace {

std::regex Compile(const std::string& pattern, std::string_view what) {
  try {
    return std::regex(pattern, std::regex::ECMAScript);
  } catch (const std::regex_error& e) {
    throw FoxgloveError("invalid " + std::string(what) + " regex '" + pattern + "': " + e.what());
  }
}

void CheckTopicName(const std::string& topic, std::string_view what) {
  try {
    bus::ValidateTopicName(topic);
  } catch (const bus::BusError& e) {
    throw FoxgloveError(std::string(what) + ": " + e.what());
  }
}

std::string Key(ChannelKind kind, const BusTopic& t) {
  return std::string(kind == ChannelKind::kJpeg ? "jpeg|" : "cdr|") + t.topic + "|" + t.type + "|" +
         std::to_string(t.layout_hash);
}

}  // namespace

struct TopicFilter::Impl {
  bool all = false;
  std::set<std::string, std::less<>> topics;
  std::optional<std::regex> include;
  std::optional<std::regex> exclude;
};

TopicFilter::TopicFilter(const TopicSelection& selection) : impl_(std::make_unique<Impl>()) {
  if (!selection.all && selection.topics.empty() && selection.regex.empty()) {
    throw FoxgloveError("no topics selected (expected all, a topic list or a regex)");
  }
  impl_->all = selection.all;
  for (const std::string& t : selection.topics) {
    CheckTopicName(t, "topics");
    impl_->topics.insert(t);
  }
  if (!selection.regex.empty()) impl_->include = Compile(selection.regex, "topic");
  if (!selection.exclude.empty()) impl_->exclude = Compile(selection.exclude, "exclude");
}

TopicFilter::~TopicFilter() = default;
TopicFilter::TopicFilter(TopicFilter&&) noexcept = default;
TopicFilter& TopicFilter::operator=(TopicFilter&&) noexcept = default;

bool TopicFilter::Selected(std::string_view topic) const {
  const std::string name(topic);
  const bool in = impl_->all || impl_->topics.contains(topic) ||
                  (impl_->include && std::regex_search(name, *impl_->include));
  return in && !(impl_->exclude && std::regex_search(name, *impl_->exclude));
}

ChannelTable::ChannelTable(const ChannelTableOptions& options)
    : filter_(options.selection), jpeg_topics_(options.jpeg_topics) {
  for (const std::string& t : jpeg_topics_) CheckTopicName(t, "jpeg_topics");
}

ChannelTable::~ChannelTable() = default;

ChannelChanges ChannelTable::Update(std::span<const BusTopic> topics) {
  ChannelChanges changes;
  std::set<std::string> bus_names;
  for (const BusTopic& t : topics) bus_names.insert(t.topic);
  // The channels that should exist now, by key.
  std::map<std::string, ChannelEntry> wanted;
  auto warn = [&](const BusTopic& t, const std::string& line, bool notice = false) {
    auto [it, inserted] = warned_.try_emplace(t.topic + "|" + line, t.type);
    if (inserted) (notice ? changes.notices : changes.warnings).push_back(line);
  };
  for (const BusTopic& t : topics) {
    if (t.type.empty()) continue;  // a topic being created
    const bool selected = filter_.Selected(t.topic);
    const bool jpeg =
        std::find(jpeg_topics_.begin(), jpeg_topics_.end(), t.topic) != jpeg_topics_.end();
    if (!selected && !jpeg) continue;
    const log::Ros2Converter* converter = log::FindRos2ConverterByProbelessType(t.type);
    if (converter == nullptr) {
      warn(t, t.topic + ": type " + t.type + " has no ROS 2 conversion; not advertised", true);
      continue;
    }
    if (converter->layout_hash() != t.layout_hash) {
      warn(t, t.topic + ": type " + t.type +
                  " has a layout hash this build does not convert; "
                  "not advertised");
      continue;
    }
    ChannelEntry e;
    e.bus_topic = t.topic;
    e.type = t.type;
    e.layout_hash = t.layout_hash;
    e.converter = converter;
    if (selected) {
      e.kind = ChannelKind::kCdr;
      e.channel = {0,
                   t.topic,
                   std::string(log::kMessageEncodingCdr),
                   std::string(converter->ros2_type()),
                   std::string(converter->schema_text()),
                   std::string(log::kSchemaEncodingRos2Msg)};
      wanted.emplace(Key(ChannelKind::kCdr, t), e);
    }
    if (jpeg) {
      const std::string name = t.topic + std::string(kJpegSuffix);
      if (t.type != msgs::Image::kTypeName) {
        warn(t, t.topic + ": type " + t.type + " is not an image; no JPEG channel");
      } else if (bus_names.contains(name)) {
        warn(t, name + ": a bus topic of that name exists; no JPEG channel for " + t.topic);
      } else {
        e.kind = ChannelKind::kJpeg;
        e.channel = {0,
                     name,
                     std::string(log::kMessageEncodingCdr),
                     std::string(log::kRos2CompressedImageType),
                     log::CompressedImageSchemaText(),
                     std::string(log::kSchemaEncodingRos2Msg)};
        wanted.emplace(Key(ChannelKind::kJpeg, t), e);
      }
    }
  }
  // Removed: current channels no longer wanted.
  for (auto it = channels_.begin(); it != channels_.end();) {
    const BusTopic t{it->second.bus_topic, it->second.type, it->second.layout_hash};
    if (!wanted.contains(Key(it->second.kind, t))) {
      changes.removed.push_back(it->first);
      it = channels_.erase(it);
    } else {
      ++it;
    }
  }
  // Added: wanted channels not current, with their old id if they had one.
  std::set<uint32_t> current;
  for (const auto& [id, e] : channels_) current.insert(id);
  for (auto& [key, e] : wanted) {
    auto [id_it, fresh] = ids_.try_emplace(key, next_id_);
    if (fresh) ++next_id_;
    if (current.contains(id_it->second)) continue;
    e.channel.id = id_it->second;
    changes.added.push_back(e.channel);
    channels_.emplace(id_it->second, std::move(e));
  }
  std::sort(changes.added.begin(), changes.added.end(),
            [](const Channel& a, const Channel& b) { return a.id < b.id; });
  return changes;
}

const ChannelEntry* ChannelTable::Find(uint32_t id) const {
  const auto it = channels_.find(id);
  return it == channels_.end() ? nullptr : &it->second;
}

std::vector<Channel> ChannelTable::Channels() const {
  std::vector<Channel> out;
  for (const auto& [id, e] : channels_) out.push_back(e.channel);
  return out;
}

std::vector<const ChannelEntry*> ChannelTable::Entries() const {
  std::vector<const ChannelEntry*> out;
  for (const auto& [id, e] : channels_) out.push_back(&e);
  return out;
}

}  // namespace probeless::foxglove
