#include "probeless/replay/sources.h"

#include <algorithm>
#include <map>
#include <optional>
#include <string_view>

#include "probeless/log/mcap.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/header.h"
#include "probeless/sim/simulator.h"

namespace probeless::replay {
namespace {

using dataset::DatasetError;

// The converter for a recorded channel: by its probeless.type metadata, else by its schema name.
const log::Ros2Converter* ConverterFor(const log::Channel& channel, const log::Schema* schema) {
  if (channel.message_encoding != log::kMessageEncodingCdr) return nullptr;
  const auto type = channel.metadata.find(std::string(log::kMetadataProbelessType));
  if (type != channel.metadata.end()) {
    if (const auto* c = log::FindRos2ConverterByProbelessType(type->second)) return c;
  }
  return schema != nullptr ? log::FindRos2ConverterByRos2Type(schema->name) : nullptr;
}

class McapSource final : public dataset::Source {
 public:
  explicit McapSource(const std::string& path) : path_(path) {
    try {
      reader_.emplace(path);
      // One pass: which channels decode, and the largest decoded message of each.
      log::MessageCursor cursor = reader_->Messages();
      log::MessageView view;
      while (cursor.Next(view)) {
        const uint16_t id = view.channel->id;
        auto known = by_channel_.find(id);
        if (known == by_channel_.end()) {
          const log::Ros2Converter* converter = ConverterFor(*view.channel, view.schema);
          if (converter == nullptr) {
            const std::string what =
                view.channel->topic + " (" + (view.schema ? view.schema->name : "no schema") + ")";
            if (std::find(skipped_.begin(), skipped_.end(), what) == skipped_.end()) {
              skipped_.push_back(what);
            }
            continue;
          }
          known = by_channel_.emplace(id, Route{topics_.size(), converter}).first;
          dataset::TopicInfo info;
          info.topic = view.channel->topic;
          info.type_name = std::string(converter->probeless_type());
          info.layout_hash = converter->layout_hash();
          topics_.push_back(std::move(info));
        }
        if (known->second.converter == nullptr) continue;
        dataset::TopicInfo& info = topics_[known->second.topic_index];
        info.max_message_bytes =
            std::max(info.max_message_bytes, known->second.converter->DecodedSize(view.data));
        info.message_count += 1;
        if (!first_time_) first_time_ = view.log_time_ns;
        last_time_ = view.log_time_ns;
      }
    } catch (const log::LogError& e) {
      throw DatasetError(std::string("cannot read MCAP log: ") + e.what());
    }
    if (topics_.empty()) {
      throw DatasetError(path +
                         ": no channel of this MCAP log can be decoded into probeless "
                         "messages (expected cdr channels of supported ROS 2 types)");
    }
    Rewind();
  }

  std::string_view kind() const override { return "mcap"; }
  const std::string& path() const override { return path_; }
  const std::vector<dataset::TopicInfo>& topics() const override { return topics_; }
  std::optional<std::pair<uint64_t, uint64_t>> time_range() const override {
    if (!first_time_) return std::nullopt;
    return std::make_pair(*first_time_, last_time_);
  }

  std::optional<dataset::StreamMessage> Next() override {
    try {
      log::MessageView view;
      while (cursor_->Next(view)) {
        const auto route = by_channel_.find(view.channel->id);
        if (route == by_channel_.end() || route->second.converter == nullptr) continue;
        const log::Ros2Converter& converter = *route->second.converter;
        dataset::StreamMessage message;
        message.topic_index = route->second.topic_index;
        message.log_time_ns = view.log_time_ns;
        message.message = log::MessageBuffer(converter.DecodedSize(view.data));
        const size_t used =
            converter.Decode(view.data, view.channel->metadata, message.message.bytes());
        message.message.Shrink(used);
        return message;
      }
    } catch (const log::LogError& e) {  // CdrError derives from LogError
      throw DatasetError(path_ + ": " + e.what());
    }
    return std::nullopt;
  }

  void Rewind() override { cursor_.emplace(reader_->Messages()); }

  const std::vector<std::string>& skipped() const { return skipped_; }

 private:
  struct Route {
    size_t topic_index;
    const log::Ros2Converter* converter;
  };
  std::string path_;
  std::optional<log::McapReader> reader_;
  std::optional<log::MessageCursor> cursor_;
  std::map<uint16_t, Route> by_channel_;
  std::vector<dataset::TopicInfo> topics_;
  std::vector<std::string> skipped_;
  std::optional<uint64_t> first_time_;
  uint64_t last_time_ = 0;
};

bool EndsWith(std::string_view text, std::string_view suffix) {
  return text.size() >= suffix.size() && text.substr(text.size() - suffix.size()) == suffix;
}

}  // namespace

std::unique_ptr<dataset::Source> OpenMcapSource(const std::string& path) {
  return std::make_unique<McapSource>(path);
}

std::vector<std::string> SkippedMcapChannels(const dataset::Source& source) {
  if (const auto* mcap = dynamic_cast<const McapSource*>(&source)) return mcap->skipped();
  return {};
}

std::unique_ptr<dataset::Source> OpenSource(const std::string& spec,
                                            const dataset::DatasetOptions& options) {
  if (spec.starts_with("mcap:")) return OpenMcapSource(spec.substr(5));
  if (EndsWith(spec, ".mcap")) return OpenMcapSource(spec);
  if (spec.starts_with("sim:") || EndsWith(spec, ".yaml") || EndsWith(spec, ".yml")) {
    sim::SimOptions sim_options;
    sim_options.max_frames = options.max_frames;
    sim_options.topic_prefix = options.topic_prefix;
    sim_options.ground_truth_prefix = options.ground_truth_prefix;
    return sim::OpenSimSource(spec.starts_with("sim:") ? spec.substr(4) : spec, sim_options);
  }
  return dataset::OpenDataset(spec, options);
}

ConvertStats ConvertToMcap(dataset::Source& source, const std::string& path,
                           const log::WriterOptions& options,
                           const std::function<void(uint64_t, uint64_t)>& progress) {
  const auto& topics = source.topics();
  std::vector<const log::Ros2Converter*> converters(topics.size());
  for (size_t i = 0; i < topics.size(); ++i) {
    converters[i] = log::FindRos2ConverterByProbelessType(topics[i].type_name);
    if (converters[i] == nullptr) {
      throw DatasetError(source.path() + ": topic " + topics[i].topic + " has type " +
                         topics[i].type_name + ", which has no ROS 2 conversion");
    }
  }
  log::McapWriter writer(path, options);
  writer.AddMetadata("probeless.source",
                     {{"kind", std::string(source.kind())}, {"path", source.path()}});
  std::vector<std::optional<uint16_t>> channels(topics.size());
  ConvertStats stats;
  stats.per_topic.assign(topics.size(), 0);
  const uint64_t total = source.message_count();
  source.Rewind();
  log::CdrWriter cdr;
  while (auto message = source.Next()) {
    const size_t t = message->topic_index;
    const auto bytes = std::span<const std::byte>(message->message.bytes());
    const log::Ros2Converter& converter = *converters[t];
    if (!channels[t]) {
      const uint16_t schema = writer.AddSchema(converter.ros2_type(), log::kSchemaEncodingRos2Msg,
                                               converter.schema_text());
      channels[t] = writer.AddChannel(topics[t].topic, log::kMessageEncodingCdr, schema,
                                      converter.ChannelMetadata(bytes));
    }
    const auto* header = reinterpret_cast<const msgs::Header*>(bytes.data());
    cdr.Reset();
    converter.Encode(bytes, cdr);
    const uint64_t sequence = header->sequence != 0 ? header->sequence : stats.per_topic[t] + 1;
    writer.Write(*channels[t], static_cast<uint32_t>(sequence), message->log_time_ns,
                 static_cast<uint64_t>(std::max<int64_t>(header->stamp_ns, 0)), cdr.data());
    stats.per_topic[t] += 1;
    stats.messages += 1;
    if (progress && stats.messages % 100 == 0) progress(stats.messages, total);
  }
  writer.Close();
  stats.file_bytes = writer.stats().file_bytes;
  if (progress) progress(stats.messages, total);
  return stats;
}

}  // namespace probeless::replay
