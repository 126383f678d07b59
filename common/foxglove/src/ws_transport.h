// The WebSocket side of the bridge on websocketpp 0.8 with standalone asio (Debian
// libwebsocketpp-dev, libasio-dev). Private to the library, and compiled as C++17 (websocketpp
// 0.8 does not compile as C++20), so this header uses only C++17 and client_queue.h.
//
// One io thread runs everything websocketpp does. Sending is pulled: Wake(client) (any thread)
// schedules a pump on the io thread, which pops frames from the client's queue (Callbacks::pop)
// while the connection has fewer than send_buffer_bytes handed to asio and not yet written. A
// client that does not read keeps its socket full, so the pump stops and its ClientQueue drops
// its oldest data — nothing upstream waits. A timer re-pumps blocked connections every 5 ms.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "probeless/foxglove/client_queue.h"

namespace probeless::foxglove::internal {

struct TransportOptions {
  std::string address = "127.0.0.1";
  uint16_t port = 8765;  // 0: any free port
  size_t send_buffer_bytes = 4u << 20;
  size_t max_client_message_bytes = 1u << 20;
};

struct TransportCallbacks {
  // The subprotocol to accept among those offered; empty refuses the handshake.
  std::function<std::string(const std::vector<std::string>& offered)> choose_subprotocol;
  // A connection opened (remote "ip:port"); returns its client id.
  std::function<uint64_t(const std::string& remote)> open;
  std::function<void(uint64_t client)> close;
  std::function<void(uint64_t client, const std::string& payload, bool binary)> message;
  std::function<std::optional<OutgoingFrame>(uint64_t client)> pop;
  // True when the client is to be disconnected for not reading.
  std::function<bool(uint64_t client)> overflowed;
  // Notices and warnings ("warning: ..."), one line each.
  std::function<void(const std::string& line)> log;
};

class WsTransport {
 public:
  // Binds and listens; throws std::runtime_error (one line) if the address cannot be used.
  WsTransport(const TransportOptions& options, TransportCallbacks callbacks);
  ~WsTransport();  // Stop()
  WsTransport(const WsTransport&) = delete;
  WsTransport& operator=(const WsTransport&) = delete;

  // The bound port.
  uint16_t port() const;
  // Starts the io thread.
  void Start();
  // Closes every connection (going away), stops the io thread and joins it. Idempotent.
  void Stop();
  // Schedules sending to `client` (thread-safe, coalesced).
  void Wake(uint64_t client);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::foxglove::internal
