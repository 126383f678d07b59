// The player's keyboard on a terminal: space pause/resume, s step, + / - rate x1.25 / /1.25, q
// quit.
#pragma once

#include <termios.h>

#include <atomic>
#include <thread>

#include "probeless/replay/player.h"

namespace probeless::player {

// Puts stdin in raw mode and reads keys on a thread of its own until destroyed, then restores the
// terminal. Does nothing when stdin is not a terminal (a launch file, a pipe, a test). `q` asks
// the process to shut down (node::RequestShutdown). `player` must outlive this object.
class Keyboard {
 public:
  explicit Keyboard(replay::Player& player);
  ~Keyboard();
  Keyboard(const Keyboard&) = delete;
  Keyboard& operator=(const Keyboard&) = delete;

 private:
  void Loop();
  void Handle(char key);

  replay::Player& player_;
  termios saved_{};
  bool active_ = false;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace probeless::player
