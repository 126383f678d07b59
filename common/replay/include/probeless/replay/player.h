// Player: publishes a recorded stream (dataset::Source) on the bus with its original timing
// scaled by a rate, or as fast as possible, or in lock-step with named downstream nodes.
//
// Timing: message k is published at  t0 + (log_time_k - log_time_0) / rate  on CLOCK_MONOTONIC
// (absolute sleeps, so errors do not accumulate); pausing, stepping and rate changes re-anchor the
// schedule at the current message. The next message is decoded while waiting for its time.
//
// Lock-step (options.lockstep_nodes non-empty): after each message the player waits until every
// named node is idle — everything the bus delivered to its subscribers has been acknowledged on
// "<node>/ack" (node::Node::Spin acknowledges each input after its handler) — in two consecutive
// registry snapshots that agree. A node publishes its outputs before acknowledging the input that
// caused them, so this covers chains: name the downstream nodes too (e.g. /face_tracker and
// /face_light) and the whole chain has finished with a frame before the next one is played. No
// message is dropped however slow the nodes, and a replay through them is deterministic. Before
// the first message the player waits until each named node is on the bus with a stable set of
// subscriptions. A node that leaves the bus (it died) is not waited for, with a warning, until it
// is back (respawned).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "probeless/dataset/source.h"

namespace probeless::replay {

struct PlayerOptions {
  double rate = 1.0;  // > 0; 2 = twice the recorded speed
  bool as_fast_as_possible = false;
  bool loop = false;      // start again at the end (timing continues seamlessly)
  double start_s = 0;     // skip the first start_s seconds of log time
  double duration_s = 0;  // play this many seconds of log time after start_s; 0 = all
  // Topics (source names, before remapping) to play: full-match ECMAScript regexes. An empty
  // include list means all; exclude wins over include.
  std::vector<std::string> include;
  std::vector<std::string> exclude;
  // Source topic -> published topic.
  std::vector<std::pair<std::string, std::string>> remaps;
  // A msgs::Header per published message (stamp_ns = the message's log time, stamp_mono_ns = the
  // publish time, sequence = messages so far); empty = none.
  std::string clock_topic = "/clock";
  // msgs::PlayerControl commands are taken from here; empty = none.
  std::string control_topic = "/player/control";
  // Fully qualified node names (e.g. "/fusion") to play in lock-step with; empty = free-running.
  std::vector<std::string> lockstep_nodes;
  // Warn (once per interval) while waiting longer than this for a lock-step acknowledgement.
  std::chrono::milliseconds lockstep_warn_after{5000};
  bool start_paused = false;
  uint32_t slot_count = 8;            // bus slots per published topic
  std::string node_name = "/player";  // shown by `probeless topic info`
  // Warnings and progress lines (one line each, no newline); default: stderr.
  std::function<void(const std::string&)> log;
};

struct PlayerStats {
  uint64_t published = 0;           // messages published (all topics)
  uint64_t passes = 0;              // completed passes over the source
  std::vector<uint64_t> per_topic;  // messages per Source::topics() index
  // |publish time - scheduled time| of timed messages, microseconds (empty when as fast as
  // possible or in lock-step).
  std::vector<double> lateness_us;
  double lockstep_wait_s = 0;  // total time spent waiting for acknowledgements
};

class Player {
 public:
  // Validates the options (throws InputError with one line: bad rate, bad regex,
  // remap to an invalid topic name) and creates one publisher per selected topic, the clock
  // publisher and the control subscriber. The source must outlive the player.
  Player(dataset::Source& source, PlayerOptions options);
  ~Player();
  Player(const Player&) = delete;
  Player& operator=(const Player&) = delete;

  // Plays until the end of the source (or, with loop, forever) or until keep_going() returns
  // false (checked at least every 20 ms, also while paused or waiting in lock-step). Throws
  // dataset::DatasetError if the source fails mid-way.
  PlayerStats Run(const std::function<bool()>& keep_going);

  // Thread-safe controls (the keyboard thread, tests); the control topic does the same.
  void Pause();
  void Resume();
  void TogglePause();
  void Step();                // while paused: publish the next message
  void SetRate(double rate);  // > 0, else ignored with a warning
  bool paused() const;
  double rate() const;

  // Published topic names, per Source::topics() index ("" for topics not selected).
  const std::vector<std::string>& published_topics() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The line the player node prints when it ends: "player: published N messages in S s, P
// pass(es)", then "; <topic> <count>" per published topic (`published_topics` as
// Player::published_topics(), "" = not published), "; lateness median M us, p99 Q us" when
// stats.lateness_us has entries, and "; lock-step wait W s" when `lockstep`. `seconds` is the
// playback's wall time. Numbers in the stream's default format (6 significant digits).
std::string PlaybackSummary(const PlayerStats& stats,
                            const std::vector<std::string>& published_topics, double seconds,
                            bool lockstep);

}  // namespace probeless::replay
