// Messages of record and replay: per-input acknowledgements for lock-step replay, and commands to
// the player.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// Capacity of a topic name field: bus::kMaxNameLength (100) characters plus NUL, padded.
inline constexpr size_t kTopicNameCapacity = 104;

// A node's acknowledgement that it has finished processing one input message. Every node that
// spins through node::Node::Spin publishes one on "<node fully qualified name>/ack" after each
// handler call; the player waits for them in lock-step mode (docs/replay.md).
struct Ack {
  Header header;  // stamp: when processing finished; frame_id: empty; sequence: acks so far
  char topic[kTopicNameCapacity] = {};  // resolved input topic, NUL-terminated
  int32_t publisher_pid = 0;            // bus::MessageInfo::publisher_pid of the input
  uint32_t reserved0 = 0;               // zero
  uint64_t publish_sequence = 0;        // bus::MessageInfo::sequence of the input (per publisher)

  static constexpr std::string_view kTypeName = "probeless_msgs/Ack";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, Ack, header);
    PROBELESS_MSGS_FIELD(b, Ack, topic);
    PROBELESS_MSGS_FIELD(b, Ack, publisher_pid);
    PROBELESS_MSGS_FIELD(b, Ack, reserved0);
    PROBELESS_MSGS_FIELD(b, Ack, publish_sequence);
    return b.Finish<Ack>();
  }

  std::string_view Topic() const { return FixedString(topic); }
  // Throws MessageError if `name` has more than kTopicNameCapacity - 1 characters.
  void SetTopic(std::string_view name) { SetFixedString(topic, name, "topic"); }
};
inline constexpr uint64_t Ack::kLayoutHash = layout::Fnv1a64(Ack::LayoutDescription());
static_assert(Message<Ack>);
static_assert(sizeof(Ack) == 176 && alignof(Ack) == 8);

// What a PlayerControl message asks the player to do.
enum class PlayerCommand : uint32_t {
  kInvalid = 0,
  kPause = 1,    // stop publishing until resumed (timing resumes where it stopped)
  kResume = 2,   // continue after a pause
  kToggle = 3,   // pause if playing, resume if paused
  kStep = 4,     // while paused: publish exactly the next message
  kSetRate = 5,  // change the rate factor to PlayerControl::rate (> 0)
};
constexpr std::string_view DescribeEnum(PlayerCommand) {
  return "PlayerCommand{invalid=0,pause=1,resume=2,toggle=3,step=4,set_rate=5}";
}

// A command to the player, on its control topic (default "/player/control").
struct PlayerControl {
  Header header;
  PlayerCommand command = PlayerCommand::kInvalid;
  uint32_t reserved0 = 0;  // zero
  double rate = 0;         // kSetRate: the new rate factor (1 = recorded speed); else unused

  static constexpr std::string_view kTypeName = "probeless_msgs/PlayerControl";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, PlayerControl, header);
    PROBELESS_MSGS_FIELD(b, PlayerControl, command);
    PROBELESS_MSGS_FIELD(b, PlayerControl, reserved0);
    PROBELESS_MSGS_FIELD(b, PlayerControl, rate);
    return b.Finish<PlayerControl>();
  }
};
inline constexpr uint64_t PlayerControl::kLayoutHash =
    layout::Fnv1a64(PlayerControl::LayoutDescription());
static_assert(Message<PlayerControl>);
static_assert(sizeof(PlayerControl) == 72 && alignof(PlayerControl) == 8);

}  // namespace probeless::msgs
