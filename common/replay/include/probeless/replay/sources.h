// Opening recorded streams (MCAP logs and dataset folders) as one kind of dataset::Source, and
// writing any source to an MCAP log (`probeless bag convert`).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "probeless/dataset/datasets.h"
#include "probeless/dataset/source.h"
#include "probeless/log/mcap_writer.h"

namespace probeless::replay {

// An MCAP log as a Source (kind "mcap"): every channel whose messages have a probeless ROS 2
// conversion (log::Ros2Converter, found by the channel's probeless.type metadata or its schema
// name) becomes a topic, decoded back into probeless messages; log times are the MCAP log times.
// Other channels are skipped and listed by SkippedMcapChannels. Opening reads the summary (or
// scans a truncated file) and makes one pass over the messages to find each topic's largest
// decoded message. Throws dataset::DatasetError naming the file on unreadable input or when no
// channel can be decoded.
std::unique_ptr<dataset::Source> OpenMcapSource(const std::string& path);

// "topic (schema name)" of the channels an MCAP Source skipped; empty for other sources.
std::vector<std::string> SkippedMcapChannels(const dataset::Source& source);

// Opens `spec`: "mcap:PATH" or a PATH ending in ".mcap" as an MCAP log; "sim:PATH" or a PATH
// ending in ".yaml"/".yml" as a simulator scenario (sim::OpenSimSource; max_frames and the topic
// prefixes of `options` apply); anything else through dataset::OpenDataset ("kind:PATH" or a
// folder/file whose kind is detected). Throws dataset::DatasetError (sim::ScenarioError is one).
std::unique_ptr<dataset::Source> OpenSource(const std::string& spec,
                                            const dataset::DatasetOptions& options = {});

struct ConvertStats {
  uint64_t messages = 0;
  uint64_t file_bytes = 0;
  std::vector<uint64_t> per_topic;  // messages per Source::topics() index
};

// Writes one pass of `source` to the MCAP log `path` with ROS 2 schemas and CDR messages (the
// same encoding the recorder writes): channel per topic, sequence = the message's
// header.sequence (truncated to 32 bits) or its index, publish time = header.stamp_ns. Calls
// `progress(done, total)` (total 0 if unknown) at most every 100 messages and at the end. Throws
// dataset::DatasetError (bad input) or log::LogError (cannot write).
ConvertStats ConvertToMcap(dataset::Source& source, const std::string& path,
                           const log::WriterOptions& options = {},
                           const std::function<void(uint64_t, uint64_t)>& progress = {});

}  // namespace probeless::replay
