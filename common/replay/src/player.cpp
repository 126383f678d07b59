#include "probeless/replay/player.h"

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <optional>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "probeless/bus/bus.h"
#include "probeless/error/error.h"
#include "probeless/msgs/header.h"
#include "probeless/msgs/replay.h"

namespace probeless::replay {
namespace {

using namespace std::chrono_literals;

constexpr int64_t kPollNs = 20'000'000;  // longest sleep between checks of controls and stop

int64_t MonoNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

void SleepUntilMono(int64_t deadline_ns) {
  timespec ts{};
  ts.tv_sec = deadline_ns / 1'000'000'000;
  ts.tv_nsec = deadline_ns % 1'000'000'000;
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

std::regex CompileTopicRegex(const std::string& pattern) {
  try {
    return std::regex(pattern, std::regex::ECMAScript);
  } catch (const std::regex_error& e) {
    throw InputError("player: invalid topic regex '" + pattern + "': " + e.what());
  }
}

}  // namespace

struct Player::Impl {
  dataset::Source& source;
  PlayerOptions options;
  std::vector<std::string> published_topics;
  std::vector<std::optional<bus::Publisher>> publishers;
  std::optional<bus::Publisher> clock;
  std::optional<bus::Subscriber> control;

  struct LockstepNode {
    std::string name;
    std::string ack_topic;
    bus::Subscriber acks;  // only to wake up when the node acknowledges something
    bool gone = false;     // left the bus: not waited for until it is back
  };
  std::vector<LockstepNode> lock_nodes;
  std::optional<bus::WaitSet> ack_wait_set;

  mutable std::mutex mutex;  // guards the control state below
  bool paused = false;
  uint64_t steps = 0;
  double rate = 1.0;
  bool reanchor = true;

  // Schedule: a message with (loop-adjusted) log time L is due at anchor_mono + (L - anchor_log)
  // / rate.
  int64_t anchor_mono = 0;
  uint64_t anchor_log = 0;

  Impl(dataset::Source& s, PlayerOptions o) : source(s), options(std::move(o)) {}

  void Log(const std::string& line) const {
    if (options.log) {
      options.log(line);
    } else {
      std::fprintf(stderr, "%s\n", line.c_str());
    }
  }

  void ApplyControl(const msgs::PlayerControl& c) {
    switch (c.command) {
      case msgs::PlayerCommand::kPause:
        SetPaused(true);
        break;
      case msgs::PlayerCommand::kResume:
        SetPaused(false);
        break;
      case msgs::PlayerCommand::kToggle: {
        std::lock_guard<std::mutex> lock(mutex);
        paused = !paused;
        reanchor = true;
        break;
      }
      case msgs::PlayerCommand::kStep: {
        std::lock_guard<std::mutex> lock(mutex);
        if (paused) steps += 1;
        break;
      }
      case msgs::PlayerCommand::kSetRate:
        SetRate(c.rate);
        break;
      default:
        Log("[warn] player: ignoring a PlayerControl with unknown command " +
            std::to_string(static_cast<uint32_t>(c.command)));
    }
  }

  void SetPaused(bool value) {
    std::lock_guard<std::mutex> lock(mutex);
    if (paused != value) reanchor = true;
    paused = value;
  }

  void SetRate(double value) {
    if (!(std::isfinite(value) && value > 0)) {
      Log("[warn] player: ignoring rate " + std::to_string(value) + " (expected > 0)");
      return;
    }
    std::lock_guard<std::mutex> lock(mutex);
    rate = value;
    reanchor = true;
  }

  void PollControl() {
    if (!control) return;
    while (auto sample = control->TryTake()) {
      if (sample->data().size() < sizeof(msgs::PlayerControl)) continue;
      ApplyControl(*msgs::ReadMessage<msgs::PlayerControl>(sample->data()));
    }
  }

  // Waits until the message with loop-adjusted log time `log_time` is due (honouring pause, step
  // and rate changes). Returns false if keep_going() turned false.
  bool WaitUntilDue(uint64_t log_time, const std::function<bool()>& keep_going,
                    std::vector<double>* lateness_us) {
    for (;;) {
      PollControl();
      if (!keep_going()) return false;
      int64_t due = 0;
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (paused) {
          if (steps == 0) {
            due = -1;
          } else {
            steps -= 1;
            reanchor = true;
          }
        }
        if (due == 0) {
          if (reanchor) {
            anchor_mono = MonoNs();
            anchor_log = log_time;
            reanchor = false;
          }
          if (options.as_fast_as_possible) return true;
          const double offset_ns =
              static_cast<double>(static_cast<int64_t>(log_time - anchor_log)) / rate;
          due = anchor_mono + static_cast<int64_t>(std::llround(offset_ns));
        }
      }
      const int64_t now = MonoNs();
      if (due < 0) {  // paused
        SleepUntilMono(now + kPollNs);
        continue;
      }
      if (now >= due) {
        if (lateness_us != nullptr && lock_nodes.empty()) {
          lateness_us->push_back(static_cast<double>(now - due) / 1000.0);
        }
        return true;
      }
      SleepUntilMono(std::min(due, now + kPollNs));
    }
  }

  // The work state of every lock-step node, from one bus registry snapshot.
  struct NodeState {
    bool present = false;  // has at least one live subscriber
    uint64_t inputs = 0;   // samples delivered to its subscribers (received - dropped)
    uint64_t queued = 0;   // of those, still queued
    uint64_t acks = 0;     // acknowledgements published on <node>/ack
    bool Idle() const { return present && queued == 0 && acks >= inputs; }
    bool operator==(const NodeState&) const = default;
  };

  std::vector<NodeState> Snapshot() const {
    std::vector<NodeState> states(lock_nodes.size());
    for (const auto& topic : bus::ListTopics()) {
      for (size_t n = 0; n < lock_nodes.size(); ++n) {
        NodeState& state = states[n];
        for (const auto& sub : topic.subscribers) {
          if (!sub.alive || sub.node_name != lock_nodes[n].name) continue;
          state.present = true;
          state.inputs += sub.received - sub.dropped;
          state.queued += sub.queued;
        }
        if (topic.topic == lock_nodes[n].ack_topic) {
          for (const auto& pub : topic.publishers) {
            if (pub.alive) state.acks += pub.published;
          }
        }
      }
    }
    return states;
  }

  void DrainAcks() {
    for (auto& n : lock_nodes) {
      while (n.acks.TryTake()) {
      }
    }
  }

  // Before the first message: every lock-step node is on the bus (has subscribers) and its set of
  // subscriptions has been stable for 100 ms (it finished creating them).
  bool WaitForLockstepNodes(const std::function<bool()>& keep_going) {
    const int64_t start = MonoNs();
    int64_t next_warning = start + options.lockstep_warn_after.count() * 1'000'000;
    int64_t stable_since = 0;
    std::vector<size_t> previous_counts;
    for (;;) {
      std::vector<size_t> counts(lock_nodes.size(), 0);
      for (const auto& topic : bus::ListTopics()) {
        for (size_t n = 0; n < lock_nodes.size(); ++n) {
          for (const auto& sub : topic.subscribers) {
            counts[n] += sub.alive && sub.node_name == lock_nodes[n].name;
          }
        }
      }
      const int64_t now = MonoNs();
      const bool all_present =
          std::all_of(counts.begin(), counts.end(), [](size_t c) { return c > 0; });
      if (!all_present || counts != previous_counts) stable_since = now;
      previous_counts = counts;
      if (all_present && now - stable_since >= 100'000'000) return true;
      if (!keep_going()) return false;
      if (now >= next_warning) {
        std::string names;
        for (size_t n = 0; n < lock_nodes.size(); ++n) {
          if (counts[n] == 0) names += (names.empty() ? "" : ", ") + lock_nodes[n].name;
        }
        Log("[warn] player: lock-step: still waiting for " + names + " to appear on the bus (" +
            std::to_string((now - start) / 1'000'000'000) + " s)");
        next_warning = now + options.lockstep_warn_after.count() * 1'000'000;
      }
      SleepUntilMono(now + 10'000'000);
    }
  }

  // After a message: waits until every lock-step node is idle — everything delivered to it has
  // been acknowledged — in two consecutive snapshots that agree. A node's outputs are published
  // before it acknowledges the input that caused them, so once an upstream node is idle its
  // outputs are counted as inputs of the downstream nodes; the second, equal snapshot proves that
  // nothing arrived between the reads of one snapshot. So the whole chain has finished with the
  // message, whether or not a node subscribes to the played topic itself.
  bool WaitForQuiescence(const std::function<bool()>& keep_going, double* waited_s) {
    const int64_t start = MonoNs();
    int64_t next_warning = start + options.lockstep_warn_after.count() * 1'000'000;
    std::optional<std::vector<NodeState>> previous;
    for (;;) {
      std::vector<NodeState> states = Snapshot();
      bool all_idle = true;
      for (size_t n = 0; n < states.size(); ++n) {
        if (!states[n].present) {  // died or left: not waited for until it is back
          if (!lock_nodes[n].gone) {
            Log("[warn] player: lock-step: " + lock_nodes[n].name +
                " has left the bus; not waiting for it");
            lock_nodes[n].gone = true;
          }
          continue;
        }
        if (lock_nodes[n].gone) {
          Log("[info] player: lock-step: " + lock_nodes[n].name +
              " is back on the bus; waiting for it again");
          lock_nodes[n].gone = false;
        }
        all_idle &= states[n].Idle();
      }
      if (all_idle && previous && *previous == states) break;
      previous = all_idle ? std::optional(std::move(states)) : std::nullopt;
      if (previous) continue;  // confirm at once
      if (!keep_going()) return false;
      PollControl();
      ack_wait_set->Wait(std::chrono::milliseconds(2));
      DrainAcks();
      const int64_t now = MonoNs();
      if (now >= next_warning) {
        std::string names;
        const auto current = Snapshot();
        for (size_t n = 0; n < current.size(); ++n) {
          if (current[n].present && !current[n].Idle()) {
            names +=
                (names.empty() ? "" : ", ") + lock_nodes[n].name + " (" +
                std::to_string(current[n].inputs - std::min(current[n].inputs, current[n].acks)) +
                " unacknowledged)";
          }
        }
        Log("[warn] player: lock-step: waiting " + std::to_string((now - start) / 1'000'000) +
            " ms for " + names);
        next_warning = now + options.lockstep_warn_after.count() * 1'000'000;
      }
    }
    DrainAcks();
    *waited_s += static_cast<double>(MonoNs() - start) / 1e9;
    return true;
  }
};

Player::Player(dataset::Source& source, PlayerOptions options)
    : impl_(std::make_unique<Impl>(source, std::move(options))) {
  Impl& impl = *impl_;
  const PlayerOptions& o = impl.options;
  if (!o.as_fast_as_possible && !(std::isfinite(o.rate) && o.rate > 0)) {
    throw InputError("player: rate must be > 0, got " + std::to_string(o.rate));
  }
  if (!(o.start_s >= 0) || !(o.duration_s >= 0)) {
    throw InputError("player: start and duration must be >= 0 seconds");
  }
  impl.rate = o.as_fast_as_possible ? 1.0 : o.rate;
  impl.paused = o.start_paused;
  std::vector<std::regex> include;
  std::vector<std::regex> exclude;
  for (const auto& p : o.include) include.push_back(CompileTopicRegex(p));
  for (const auto& p : o.exclude) exclude.push_back(CompileTopicRegex(p));
  const auto& topics = source.topics();
  impl.published_topics.assign(topics.size(), "");
  impl.publishers.resize(topics.size());
  for (size_t t = 0; t < topics.size(); ++t) {
    const std::string& name = topics[t].topic;
    auto matches = [&](const std::regex& r) { return std::regex_match(name, r); };
    if (!include.empty() && std::none_of(include.begin(), include.end(), matches)) continue;
    if (std::any_of(exclude.begin(), exclude.end(), matches)) continue;
    std::string target = name;
    for (const auto& [from, to] : o.remaps) {
      if (from == name) target = to;
    }
    try {
      bus::ValidateTopicName(target);
    } catch (const bus::BusError& e) {
      throw InputError(std::string("player: ") + e.what());
    }
    bus::PublisherOptions po;
    po.max_message_bytes = std::max<size_t>(topics[t].max_message_bytes, 64);
    po.slot_count = std::max<uint32_t>(o.slot_count, 2);
    po.node_name = o.node_name;
    impl.publishers[t].emplace(target, bus::TopicType{topics[t].type_name, topics[t].layout_hash},
                               po);
    impl.published_topics[t] = target;
  }
  if (!o.clock_topic.empty()) {
    bus::PublisherOptions po;
    po.max_message_bytes = sizeof(msgs::Header);
    po.slot_count = 8;
    po.node_name = o.node_name;
    impl.clock.emplace(o.clock_topic, msgs::TopicTypeOf<msgs::Header>(), po);
  }
  if (!o.control_topic.empty()) {
    bus::SubscriberOptions so;
    so.queue_depth = 16;
    so.node_name = o.node_name;
    impl.control.emplace(o.control_topic, msgs::TopicTypeOf<msgs::PlayerControl>(), so);
  }
  if (!o.lockstep_nodes.empty()) {
    impl.ack_wait_set.emplace();
    impl.lock_nodes.reserve(o.lockstep_nodes.size());
    for (const auto& name : o.lockstep_nodes) {
      if (!name.starts_with('/')) {
        throw InputError("player: lock-step node '" + name +
                         "' must be a fully qualified node name such as /" + name);
      }
      bus::SubscriberOptions so;
      so.queue_depth = 64;
      so.node_name = o.node_name;
      impl.lock_nodes.push_back(
          {name, name + "/ack",
           bus::Subscriber(name + "/ack", msgs::TopicTypeOf<msgs::Ack>(), so)});
    }
    for (auto& n : impl.lock_nodes) impl.ack_wait_set->Add(n.acks);
  }
}

Player::~Player() = default;

PlayerStats Player::Run(const std::function<bool()>& keep_going) {
  Impl& impl = *impl_;
  const PlayerOptions& o = impl.options;
  PlayerStats stats;
  stats.per_topic.assign(impl.source.topics().size(), 0);
  if (!impl.lock_nodes.empty() && !impl.WaitForLockstepNodes(keep_going)) return stats;
  const auto start_ns = static_cast<uint64_t>(std::llround(o.start_s * 1e9));
  const auto duration_ns = static_cast<uint64_t>(std::llround(o.duration_s * 1e9));
  uint64_t loop_offset = 0;  // added to log times so that timing continues across passes
  uint64_t clock_sequence = 0;
  for (;;) {
    impl.source.Rewind();
    std::optional<uint64_t> origin;
    uint64_t first_played = 0;
    uint64_t last_played = 0;
    uint64_t played = 0;
    while (auto message = impl.source.Next()) {
      if (!origin) origin = message->log_time_ns;
      const uint64_t relative = message->log_time_ns - *origin;
      if (relative < start_ns) continue;
      if (duration_ns > 0 && relative >= start_ns + duration_ns) break;
      const size_t t = message->topic_index;
      if (t >= impl.publishers.size() || !impl.publishers[t]) continue;
      const uint64_t log_time = message->log_time_ns + loop_offset;
      if (!impl.WaitUntilDue(log_time, keep_going, &stats.lateness_us)) return stats;
      const auto bytes = std::span<const std::byte>(message->message.bytes());
      bus::Loan loan = impl.publishers[t]->Borrow(bytes.size());
      std::memcpy(loan.data().data(), bytes.data(), bytes.size());
      impl.publishers[t]->Publish(std::move(loan));
      if (impl.clock) {
        bus::Loan c = impl.clock->Borrow(sizeof(msgs::Header));
        auto header = msgs::WriteMessage<msgs::Header>(c.data());
        header->stamp_ns = static_cast<int64_t>(log_time);
        header->stamp_mono_ns = MonoNs();
        header->sequence = ++clock_sequence;
        impl.clock->Publish(std::move(c));
      }
      stats.published += 1;
      stats.per_topic[t] += 1;
      if (played == 0) first_played = log_time;
      last_played = log_time;
      played += 1;
      if (!impl.lock_nodes.empty()) {
        const int64_t published_mono = MonoNs();
        if (!impl.WaitForQuiescence(keep_going, &stats.lockstep_wait_s)) return stats;
        // Re-anchor at the message just published: the next one keeps its recorded interval after
        // it, or goes at once if the wait took longer (time spent waiting makes no burst later).
        std::lock_guard<std::mutex> lock(impl.mutex);
        if (!impl.reanchor) {
          impl.anchor_mono = published_mono;
          impl.anchor_log = log_time;
        }
      }
    }
    stats.passes += 1;
    if (!o.loop || played == 0 || !keep_going()) break;
    // The next pass starts one mean message interval after this one ended.
    const uint64_t gap = played > 1 ? (last_played - first_played) / (played - 1) : 33'333'333;
    loop_offset = last_played + gap - (first_played - loop_offset);
  }
  return stats;
}

void Player::Pause() { impl_->SetPaused(true); }
void Player::Resume() { impl_->SetPaused(false); }
void Player::TogglePause() {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->paused = !impl_->paused;
  impl_->reanchor = true;
}
void Player::Step() {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  if (impl_->paused) impl_->steps += 1;
}
void Player::SetRate(double rate) { impl_->SetRate(rate); }
bool Player::paused() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->paused;
}
double Player::rate() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->rate;
}
const std::vector<std::string>& Player::published_topics() const { return impl_->published_topics; }

std::string PlaybackSummary(const PlayerStats& stats,
                            const std::vector<std::string>& published_topics, double seconds,
                            bool lockstep) {
  std::ostringstream summary;
  summary << "player: published " << stats.published << " messages in " << seconds << " s, "
          << stats.passes << " pass(es)";
  for (size_t t = 0; t < stats.per_topic.size() && t < published_topics.size(); ++t) {
    if (!published_topics[t].empty())
      summary << "; " << published_topics[t] << " " << stats.per_topic[t];
  }
  if (!stats.lateness_us.empty()) {
    std::vector<double> lateness = stats.lateness_us;
    std::sort(lateness.begin(), lateness.end());
    summary << "; lateness median " << lateness[lateness.size() / 2] << " us, p99 "
            << lateness[std::min(lateness.size() - 1, lateness.size() * 99 / 100)] << " us";
  }
  if (lockstep) summary << "; lock-step wait " << stats.lockstep_wait_s << " s";
  return summary.str();
}

}  // namespace probeless::replay
