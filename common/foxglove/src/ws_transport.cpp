// Compiled as C++17 (see ws_transport.h).
#define ASIO_STANDALONE
#include "ws_transport.h"

#include <chrono>
#include <condition_variable>
#include <cstring>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <utility>
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include "probeless/error/error.h"

namespace probeless::foxglove::internal {
namespace {

using WsServer = websocketpp::server<websocketpp::config::asio>;
using Handle = websocketpp::connection_hdl;
constexpr auto kRepumpPeriod = std::chrono::milliseconds(5);
constexpr auto kCloseGrace = std::chrono::milliseconds(300);

}  // namespace

struct WsTransport::Impl {
  TransportOptions options;
  TransportCallbacks callbacks;
  WsServer server;
  std::unique_ptr<asio::steady_timer> timer;
  std::thread thread;
  bool started = false;
  bool stopping = false;  // caller's thread
  bool stopped = false;   // io thread
  uint16_t port = 0;

  // io thread only.
  std::map<Handle, uint64_t, std::owner_less<Handle>> ids;
  std::map<uint64_t, Handle> handles;
  std::set<uint64_t> blocked;  // socket full at the last pump

  // Any thread.
  std::mutex wake_mutex;
  std::set<uint64_t> pending;

  void Log(const std::string& line) {
    if (callbacks.log) callbacks.log(line);
  }

  void Pump(uint64_t id) {
    {
      std::lock_guard lock(wake_mutex);
      pending.erase(id);
    }
    const auto h = handles.find(id);
    if (h == handles.end()) return;
    websocketpp::lib::error_code ec;
    WsServer::connection_ptr con = server.get_con_from_hdl(h->second, ec);
    if (ec || con->get_state() != websocketpp::session::state::open) return;
    blocked.erase(id);
    while (true) {
      if (callbacks.overflowed(id)) {
        Log("warning: closing client " + std::to_string(id) + " (" + con->get_remote_endpoint() +
            "): it does not read its messages");
        con->close(websocketpp::close::status::policy_violation, "client does not read", ec);
        return;
      }
      if (con->get_buffered_amount() >= options.send_buffer_bytes) {
        blocked.insert(id);
        return;
      }
      std::optional<OutgoingFrame> frame = callbacks.pop(id);
      if (!frame) return;
      switch (frame->kind) {
        case OutgoingFrame::Kind::kText:
          ec = con->send(frame->bytes, websocketpp::frame::opcode::text);
          break;
        case OutgoingFrame::Kind::kBinary:
          ec = con->send(frame->bytes.data(), frame->bytes.size(),
                         websocketpp::frame::opcode::binary);
          break;
        case OutgoingFrame::Kind::kMessageData: {
          const std::vector<std::byte>& payload = frame->message->payload;
          WsServer::message_ptr m =
              con->get_message(websocketpp::frame::opcode::binary, 13 + payload.size());
          char head[13];
          head[0] = 0x01;
          const uint32_t sub = frame->subscription_id;
          const uint64_t ts = frame->message->receive_ns;
          std::memcpy(head + 1, &sub, 4);
          std::memcpy(head + 5, &ts, 8);
          m->append_payload(head, sizeof(head));
          m->append_payload(payload.data(), payload.size());
          ec = con->send(m);
          break;
        }
      }
      if (ec) return;  // closing: the close handler forgets the client
    }
  }

  void ArmTimer() {
    timer->expires_after(kRepumpPeriod);
    timer->async_wait([this](const asio::error_code& ec) {
      if (ec || stopped) return;
      const std::set<uint64_t> again = blocked;
      for (uint64_t id : again) Pump(id);
      ArmTimer();
    });
  }

  void Forget(Handle hdl) {
    const auto it = ids.find(hdl);
    if (it == ids.end()) return;
    const uint64_t id = it->second;
    ids.erase(it);
    handles.erase(id);
    blocked.erase(id);
    callbacks.close(id);
  }
};

WsTransport::WsTransport(const TransportOptions& options, TransportCallbacks callbacks)
    : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.options = options;
  s.callbacks = std::move(callbacks);
  s.server.clear_access_channels(websocketpp::log::alevel::all);
  s.server.clear_error_channels(websocketpp::log::elevel::all);
  s.server.init_asio();
  s.server.set_reuse_addr(true);
  s.server.set_max_message_size(options.max_client_message_bytes);
  s.server.set_validate_handler([&s](Handle hdl) {
    websocketpp::lib::error_code ec;
    WsServer::connection_ptr con = s.server.get_con_from_hdl(hdl, ec);
    if (ec) return false;
    const std::string chosen = s.callbacks.choose_subprotocol(con->get_requested_subprotocols());
    if (chosen.empty()) {
      s.Log("warning: refused a connection from " + con->get_remote_endpoint() +
            ": it offers neither foxglove.sdk.v1 nor foxglove.websocket.v1");
      return false;
    }
    con->select_subprotocol(chosen, ec);
    return !ec;
  });
  s.server.set_open_handler([&s](Handle hdl) {
    websocketpp::lib::error_code ec;
    WsServer::connection_ptr con = s.server.get_con_from_hdl(hdl, ec);
    if (ec) return;
    const uint64_t id = s.callbacks.open(con->get_remote_endpoint());
    s.ids.emplace(hdl, id);
    s.handles.emplace(id, hdl);
    s.Log("client " + std::to_string(id) + " connected from " + con->get_remote_endpoint() + " (" +
          con->get_subprotocol() + ")");
    s.Pump(id);
  });
  s.server.set_close_handler([&s](Handle hdl) {
    const auto it = s.ids.find(hdl);
    if (it != s.ids.end()) s.Log("client " + std::to_string(it->second) + " disconnected");
    s.Forget(hdl);
  });
  s.server.set_fail_handler([&s](Handle hdl) { s.Forget(hdl); });
  s.server.set_message_handler([&s](Handle hdl, WsServer::message_ptr message) {
    const auto it = s.ids.find(hdl);
    if (it == s.ids.end()) return;
    const uint64_t id = it->second;
    s.callbacks.message(id, message->get_payload(),
                        message->get_opcode() == websocketpp::frame::opcode::binary);
    s.Pump(id);
  });

  websocketpp::lib::error_code ec;
  const asio::ip::address address = asio::ip::make_address(options.address, ec);
  if (ec) throw InputError("invalid address '" + options.address + "'");
  s.server.listen(asio::ip::tcp::endpoint(address, options.port), ec);
  if (ec) {
    throw InputError("cannot listen on " + options.address + ":" + std::to_string(options.port) +
                     ": " + ec.message());
  }
  s.port = s.server.get_local_endpoint(ec).port();
  s.server.start_accept(ec);
  if (ec) throw InputError("cannot accept connections: " + ec.message());
  s.timer = std::make_unique<asio::steady_timer>(s.server.get_io_service());
}

WsTransport::~WsTransport() { Stop(); }

uint16_t WsTransport::port() const { return impl_->port; }

void WsTransport::Start() {
  Impl& s = *impl_;
  if (s.started) return;
  s.started = true;
  s.ArmTimer();
  s.thread = std::thread([&s] { s.server.run(); });
}

void WsTransport::Stop() {
  Impl& s = *impl_;
  if (!s.started || s.stopping) return;
  s.stopping = true;
  asio::post(s.server.get_io_service(), [&s] {
    websocketpp::lib::error_code ec;
    s.server.stop_listening(ec);
    for (const auto& [id, hdl] : s.handles) {
      s.server.close(hdl, websocketpp::close::status::going_away, "server shutting down", ec);
    }
  });
  // Wait (bounded) for the close handshakes, asking the io thread whether any are left.
  struct Probe {
    std::mutex mutex;
    std::condition_variable cv;
    bool answered = false;
    bool empty = false;
  };
  const auto deadline = std::chrono::steady_clock::now() + kCloseGrace;
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    auto probe = std::make_shared<Probe>();
    asio::post(s.server.get_io_service(), [&s, probe] {
      std::lock_guard lock(probe->mutex);
      probe->empty = s.handles.empty();
      probe->answered = true;
      probe->cv.notify_one();
    });
    std::unique_lock lock(probe->mutex);
    if (!probe->cv.wait_for(lock, std::chrono::milliseconds(100),
                            [&] { return probe->answered; })) {
      break;
    }
    if (probe->empty) break;
  }
  asio::post(s.server.get_io_service(), [&s] {
    s.stopped = true;
    s.timer->cancel();
  });
  s.server.stop();
  s.thread.join();
}

void WsTransport::Wake(uint64_t client) {
  Impl& s = *impl_;
  {
    std::lock_guard lock(s.wake_mutex);
    if (!s.pending.insert(client).second) return;
  }
  asio::post(s.server.get_io_service(), [&s, client] { s.Pump(client); });
}

}  // namespace probeless::foxglove::internal
