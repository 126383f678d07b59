#include "keyboard.h"

#include <poll.h>
#include <unistd.h>

#include <cstdio>

#include "probeless/node/node.h"

namespace probeless::player {

Keyboard::Keyboard(replay::Player& player) : player_(player) {
  if (!isatty(STDIN_FILENO) || tcgetattr(STDIN_FILENO, &saved_) != 0) return;
  termios raw = saved_;
  raw.c_lflag &= ~static_cast<tcflag_t>(ICANON | ECHO);
  raw.c_cc[VMIN] = 0;
  raw.c_cc[VTIME] = 0;
  if (tcsetattr(STDIN_FILENO, TCSANOW, &raw) != 0) return;
  active_ = true;
  std::fprintf(stderr, "[info] player: keys: space pause/resume, s step, +/- rate, q quit\n");
  thread_ = std::thread([this] { Loop(); });
}

Keyboard::~Keyboard() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (active_) tcsetattr(STDIN_FILENO, TCSANOW, &saved_);
}

void Keyboard::Loop() {
  while (!stop_ && node::ok()) {
    pollfd fd{STDIN_FILENO, POLLIN, 0};
    if (poll(&fd, 1, 100) <= 0) continue;
    char key = 0;
    if (read(STDIN_FILENO, &key, 1) == 1) Handle(key);
  }
}

void Keyboard::Handle(char key) {
  switch (key) {
    case ' ':
      player_.TogglePause();
      std::fprintf(stderr, "[info] player: %s\n", player_.paused() ? "paused" : "playing");
      break;
    case 's':
      player_.Step();
      break;
    case '+':
    case '-':
      player_.SetRate(key == '+' ? player_.rate() * 1.25 : player_.rate() / 1.25);
      std::fprintf(stderr, "[info] player: rate %.3g\n", player_.rate());
      break;
    case 'q':
      node::RequestShutdown();
      break;
    default:
      break;
  }
}

}  // namespace probeless::player
