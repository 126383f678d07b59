// A minimal WebSocket client over a raw socket, for the bridge's tests and benchmark: an
// independent peer (the RFC 6455 handshake and frames written here, client frames masked, no
// fragmentation or extensions), so a bug shared with websocketpp cannot hide. Blocking, with a
// 5 s read timeout; loopback only.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>

namespace probeless::foxglove::test_client {

using nlohmann::json;

class RawClient {
 public:
  explicit RawClient(uint16_t port) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
  }
  ~RawClient() { close(fd_); }

  // Sends the upgrade request; returns the HTTP response head.
  std::string Handshake(const std::string& protocols) {
    std::string request =
        "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
    if (!protocols.empty()) request += "Sec-WebSocket-Protocol: " + protocols + "\r\n";
    request += "\r\n";
    Write(request);
    std::string head;
    while (head.find("\r\n\r\n") == std::string::npos) {
      const std::optional<std::string> b = Read(1);
      if (!b) break;
      head += *b;
    }
    return head;
  }

  // A masked client frame (opcode 1 text, 2 binary).
  void Send(const std::string& payload, int opcode) {
    std::string frame(1, static_cast<char>(0x80 | opcode));
    const unsigned char mask[4] = {0x12, 0x34, 0x56, 0x78};
    if (payload.size() < 126) {
      frame += static_cast<char>(0x80 | payload.size());
    } else {
      frame += static_cast<char>(0x80 | 126);
      frame += static_cast<char>(payload.size() >> 8);
      frame += static_cast<char>(payload.size() & 0xff);
    }
    frame.append(reinterpret_cast<const char*>(mask), 4);
    for (size_t i = 0; i < payload.size(); ++i)
      frame += static_cast<char>(payload[i] ^ mask[i % 4]);
    Write(frame);
  }

  // The next server frame: {opcode, payload}; nullopt on timeout or close.
  std::optional<std::pair<int, std::string>> Next(
      std::chrono::milliseconds timeout = std::chrono::milliseconds(5000)) {
    const auto head = Read(2, timeout);
    if (!head) return std::nullopt;
    const int opcode = (*head)[0] & 0x0f;
    uint64_t length = (*head)[1] & 0x7f;
    if (length == 126 || length == 127) {
      const auto ext = Read(length == 126 ? 2 : 8);
      if (!ext) return std::nullopt;
      length = 0;
      for (unsigned char c : *ext) length = (length << 8) | c;
    }
    const auto payload = Read(length);
    if (!payload) return std::nullopt;
    return std::make_pair(opcode, *payload);
  }

  // The next text frame's JSON (skipping binary time frames).
  json NextJson() {
    for (int i = 0; i < 1000; ++i) {
      const auto f = Next();
      if (!f) return json();
      if (f->first == 1) return json::parse(f->second);
    }
    return json();
  }

  bool connected() const { return connected_; }

 private:
  void Write(const std::string& bytes) {
    size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
      if (n <= 0) return;
      done += static_cast<size_t>(n);
    }
  }
  std::optional<std::string> Read(
      size_t n, std::chrono::milliseconds timeout = std::chrono::milliseconds(5000)) {
    std::string out(n, '\0');
    size_t done = 0;
    while (done < n) {
      pollfd p{fd_, POLLIN, 0};
      if (poll(&p, 1, static_cast<int>(timeout.count())) <= 0) return std::nullopt;
      const ssize_t r = ::recv(fd_, out.data() + done, n - done, 0);
      if (r <= 0) return std::nullopt;
      done += static_cast<size_t>(r);
    }
    return out;
  }
  int fd_ = -1;
  bool connected_ = false;
};

}  // namespace probeless::foxglove::test_client
