#include "probeless/dds_bridge/bridge.h"

#include <dds/dds.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <regex>
#include <set>
#include <thread>

#include "opaque_cdr.h"
#include "probeless/bus/bus.h"
#include "probeless/log/cdr.h"
#include "probeless/log/ros2.h"
#include "probeless/parse/number.h"

namespace probeless::dds_bridge {
namespace {

using Clock = std::chrono::steady_clock;

std::string Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return std::string(s);
}

std::string DdsErrorText(dds_return_t rc) { return dds_strretcode(rc); }

void CheckEntity(dds_entity_t e, const std::string& what) {
  if (e < 0) throw DdsBridgeError(what + ": " + DdsErrorText(e));
}

bool IsAddress(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) {
    return (c >= '0' && c <= '9') || c == '.' || c == ':' || (c >= 'a' && c <= 'f');
  }) && s.find_first_of(".:") != std::string::npos;
}

std::string XmlEscape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"') out += "&quot;";
    else if (c == '&') out += "&amp;";
    else if (c == '<') out += "&lt;";
    else if (c == '>') out += "&gt;";
    else out += c;
  }
  return out;
}

}  // namespace

Reliability ParseReliability(std::string_view text) {
  if (text == "reliable") return Reliability::kReliable;
  if (text == "best_effort") return Reliability::kBestEffort;
  throw DdsBridgeError("reliability '" + std::string(text) +
                       "' is not valid (expected reliable or best_effort)");
}

Durability ParseDurability(std::string_view text) {
  if (text == "volatile") return Durability::kVolatile;
  if (text == "transient_local") return Durability::kTransientLocal;
  throw DdsBridgeError("durability '" + std::string(text) +
                       "' is not valid (expected volatile or transient_local)");
}

QosRule ParseQosRule(std::string_view text) {
  const size_t eq = text.rfind('=');
  if (eq == std::string_view::npos || eq == 0) {
    throw DdsBridgeError("qos rule '" + std::string(text) +
                         "' is not valid (expected REGEX=reliability,depth,durability)");
  }
  QosRule rule;
  rule.regex = std::string(text.substr(0, eq));
  try {
    std::regex check(rule.regex);
  } catch (const std::regex_error& e) {
    throw DdsBridgeError("qos rule '" + std::string(text) + "': bad regex: " + e.what());
  }
  std::vector<std::string> parts;
  std::string_view rest = text.substr(eq + 1);
  while (true) {
    const size_t comma = rest.find(',');
    parts.push_back(Trim(rest.substr(0, comma)));
    if (comma == std::string_view::npos) break;
    rest.remove_prefix(comma + 1);
  }
  if (parts.size() > 3) {
    throw DdsBridgeError("qos rule '" + std::string(text) + "': more than three fields");
  }
  if (!parts.empty() && !parts[0].empty()) rule.reliability = ParseReliability(parts[0]);
  if (parts.size() > 1 && !parts[1].empty()) {
    const std::optional<long> parsed = parse::TryParseInteger<long>(parts[1], 1, 1000);
    const long depth = parsed.value_or(0);
    if (!parsed) {
      throw DdsBridgeError("qos rule '" + std::string(text) + "': depth '" + parts[1] +
                           "' is not an integer in 1..1000");
    }
    rule.depth = static_cast<uint32_t>(depth);
  }
  if (parts.size() > 2 && !parts[2].empty()) rule.durability = ParseDurability(parts[2]);
  return rule;
}

Route ParseRoute(std::string_view text) {
  Route route;
  const size_t sep = text.find(":=");
  route.from = Trim(text.substr(0, sep));
  route.to = sep == std::string_view::npos ? route.from : Trim(text.substr(sep + 2));
  for (const std::string* name : {&route.from, &route.to}) {
    try {
      bus::ValidateTopicName(*name);
    } catch (const bus::BusError& e) {
      throw DdsBridgeError("route '" + std::string(text) + "': " + e.what());
    }
  }
  return route;
}

std::string DdsTopicName(std::string_view ros_name) {
  if (ros_name.starts_with('/')) ros_name.remove_prefix(1);
  return "rt/" + std::string(ros_name);
}

std::string RosTopicName(std::string_view dds_name) {
  if (!dds_name.starts_with("rt/")) return {};
  return "/" + std::string(dds_name.substr(3));
}

std::string DdsTypeName(std::string_view ros2_type) {
  // "pkg/msg/Type" -> "pkg::msg::dds_::Type_"
  const size_t last = ros2_type.rfind('/');
  if (last == std::string_view::npos) return std::string(ros2_type);
  std::string ns(ros2_type.substr(0, last));
  std::string out;
  for (char c : ns) {
    if (c == '/') out += "::";
    else out += c;
  }
  return out + "::dds_::" + std::string(ros2_type.substr(last + 1)) + "_";
}

std::string Ros2TypeName(std::string_view dds_type) {
  constexpr std::string_view kMarker = "::dds_::";
  const size_t at = dds_type.rfind(kMarker);
  if (at == std::string_view::npos || !dds_type.ends_with('_')) return {};
  std::string ns;
  for (size_t i = 0; i < at; ++i) {
    if (dds_type.compare(i, 2, "::") == 0) {
      ns += '/';
      ++i;
    } else {
      ns += dds_type[i];
    }
  }
  const std::string_view name = dds_type.substr(at + kMarker.size());
  return ns + "/" + std::string(name.substr(0, name.size() - 1));
}

int ResolveDomainId(int domain_id) {
  if (domain_id >= 0) {
    if (domain_id > 232) {
      throw DdsBridgeError("domain id " + std::to_string(domain_id) + " out of range (0..232)");
    }
    return domain_id;
  }
  const char* env = std::getenv("ROS_DOMAIN_ID");
  if (env == nullptr || *env == '\0') return 0;
  const std::optional<int> parsed = parse::TryParseInteger<int>(env, 0, 232);
  const int value = parsed.value_or(0);
  if (!parsed) {
    throw DdsBridgeError(std::string("ROS_DOMAIN_ID '") + env +
                         "' is not a domain id (expected 0..232)");
  }
  return static_cast<int>(value);
}

std::string CycloneConfig(const BridgeOptions& o) {
  if (!o.cyclone_config.empty()) return o.cyclone_config;
  std::vector<std::string> interfaces = o.interfaces;
  if (interfaces.empty()) interfaces.push_back("127.0.0.1");
  std::vector<std::string> peers = o.peers;
  const bool loopback_only = std::all_of(interfaces.begin(), interfaces.end(), [](const auto& i) {
    return i == "127.0.0.1" || i == "lo";
  });
  if (peers.empty() && (loopback_only || !o.multicast)) peers.push_back("127.0.0.1");
  std::string xml = "<CycloneDDS><Domain Id=\"any\"><General><Interfaces>";
  for (const std::string& i : interfaces) {
    xml += IsAddress(i) ? "<NetworkInterface address=\"" + XmlEscape(i) + "\"/>"
                        : "<NetworkInterface name=\"" + XmlEscape(i) + "\"/>";
  }
  xml += "</Interfaces><AllowMulticast>";
  xml += o.multicast && !loopback_only ? "true" : "false";
  // Loopback carries 64 KB datagrams: fewer fragments per 1.5 MB frame.
  xml += "</AllowMulticast>";
  if (loopback_only) xml += "<MaxMessageSize>65500B</MaxMessageSize>";
  xml += "</General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
         "<MaxAutoParticipantIndex>64</MaxAutoParticipantIndex><Peers>";
  for (const std::string& p : peers) xml += "<Peer address=\"" + XmlEscape(p) + "\"/>";
  xml += "</Peers></Discovery>"
         "<Internal><Watermarks><WhcHigh>16MB</WhcHigh></Watermarks></Internal>"
         "</Domain></CycloneDDS>";
  return xml;
}

// ------------------------------------------------------------------------------------------------

struct Bridge::Impl {
  struct Outbound {
    std::string bus_topic, dds_topic, dds_type;
    const log::Ros2Converter* converter = nullptr;
    std::unique_ptr<bus::Subscriber> subscriber;
    dds_entity_t writer = 0;
    const ddsi_sertype* sertype = nullptr;
    std::atomic<uint64_t> forwarded{0}, write_drops{0}, errors{0}, bytes{0};
  };
  struct Inbound {
    std::string bus_topic, dds_topic, dds_type;
    const log::Ros2Converter* converter = nullptr;
    dds_entity_t reader = 0;
    std::unique_ptr<bus::Publisher> publisher;
    std::atomic<uint64_t> forwarded{0}, lost{0}, errors{0}, bytes{0};
  };

  BridgeOptions options;
  int domain_id = 0;
  dds_entity_t domain = 0;
  dds_entity_t participant = 0;
  dds_guid_t own_guid{};
  dds_entity_t publications = 0;  // DCPSPublication reader
  dds_entity_t waitset = 0;
  std::optional<std::regex> to_regex, from_regex;
  std::vector<std::pair<std::regex, QosRule>> qos_rules;

  mutable std::mutex mutex;  // guards the two lists (entries are never removed while running)
  std::vector<std::unique_ptr<Outbound>> outbound;
  std::vector<std::unique_ptr<Inbound>> inbound;
  std::map<std::string, dds_entity_t> topics;  // DDS topic name -> topic entity (dds thread-safe)
  std::mutex topics_mutex;
  std::set<std::string> inbound_bus_topics;  // never forwarded back to DDS (guarded by mutex)
  std::set<std::string> unsupported_logged;

  std::atomic<bool> running{false};
  std::thread out_thread, in_thread;

  void Log(const std::string& line) const {
    if (options.log) options.log(line);
  }

  Qos QosFor(const std::string& ros_name, const std::string& ros2_type) const {
    Qos q = ros2_type == "sensor_msgs/msg/Image" ? options.image_qos : options.default_qos;
    for (const auto& [re, rule] : qos_rules) {
      if (!std::regex_search(ros_name, re)) continue;
      if (rule.reliability) q.reliability = *rule.reliability;
      if (rule.depth) q.depth = *rule.depth;
      if (rule.durability) q.durability = *rule.durability;
    }
    return q;
  }

  static dds_qos_t* MakeQos(const Qos& q, bool writer) {
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos,
                         q.reliability == Reliability::kReliable ? DDS_RELIABILITY_RELIABLE
                                                                 : DDS_RELIABILITY_BEST_EFFORT,
                         DDS_MSECS(writer ? 100 : 0));
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, static_cast<int32_t>(q.depth));
    dds_qset_durability(qos, q.durability == Durability::kVolatile
                                 ? DDS_DURABILITY_VOLATILE
                                 : DDS_DURABILITY_TRANSIENT_LOCAL);
    const dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
    dds_qset_data_representation(qos, 1, &xcdr1);
    if (!writer) dds_qset_ignorelocal(qos, DDS_IGNORELOCAL_PARTICIPANT);
    return qos;
  }

  // The DDS topic entity for `name` with type `dds_type` (created once).
  std::pair<dds_entity_t, const ddsi_sertype*> Topic(const std::string& name,
                                                     const std::string& dds_type) {
    std::lock_guard lock(topics_mutex);
    ddsi_sertype* st = internal::CreateOpaqueSertype(dds_type);
    const dds_entity_t topic =
        dds_create_topic_sertype(participant, name.c_str(), &st, nullptr, nullptr, nullptr);
    if (topic < 0) {
      ddsi_sertype_unref(st);
      throw DdsBridgeError("DDS topic '" + name + "' (" + dds_type + "): " + DdsErrorText(topic));
    }
    return {topic, st};
  }

  void Init() {
    domain_id = ResolveDomainId(options.domain_id);
    if (!options.to_dds_regex.empty()) {
      try {
        to_regex.emplace(options.to_dds_regex);
      } catch (const std::regex_error& e) {
        throw DdsBridgeError("to_dds_regex '" + options.to_dds_regex + "': " + e.what());
      }
    }
    if (!options.from_dds_regex.empty()) {
      try {
        from_regex.emplace(options.from_dds_regex);
      } catch (const std::regex_error& e) {
        throw DdsBridgeError("from_dds_regex '" + options.from_dds_regex + "': " + e.what());
      }
    }
    for (const QosRule& r : options.qos_rules) qos_rules.emplace_back(std::regex(r.regex), r);
    if (options.bus_queue_depth < 1 || options.bus_queue_depth > bus::kMaxQueueDepth) {
      throw DdsBridgeError("bus_queue_depth " + std::to_string(options.bus_queue_depth) +
                           " out of range (1.." + std::to_string(bus::kMaxQueueDepth) + ")");
    }
    if (options.bus_slot_count < 2 || options.bus_slot_count > 1024) {  // the bus's pool limits
      throw DdsBridgeError("bus_slot_count " + std::to_string(options.bus_slot_count) +
                           " out of range (2..1024)");
    }
    for (const Route& r : options.from_dds) inbound_bus_topics.insert(r.to);

    const std::string config = CycloneConfig(options);
    domain = dds_create_domain(static_cast<dds_domainid_t>(domain_id), config.c_str());
    CheckEntity(domain, "DDS domain " + std::to_string(domain_id));
    participant = dds_create_participant(static_cast<dds_domainid_t>(domain_id), nullptr, nullptr);
    CheckEntity(participant, "DDS participant in domain " + std::to_string(domain_id));
    dds_get_guid(participant, &own_guid);
    publications = dds_create_reader(participant, DDS_BUILTIN_TOPIC_DCPSPUBLICATION, nullptr,
                                     nullptr);
    CheckEntity(publications, "DCPSPublication reader");
    waitset = dds_create_waitset(participant);
    CheckEntity(waitset, "DDS waitset");
  }

  void Fini() {
    if (domain > 0) dds_delete(domain);
    domain = 0;
  }

  // --- bus -> DDS -------------------------------------------------------------------------------

  std::optional<std::string> OutboundTarget(const std::string& bus_topic) const {
    {
      std::lock_guard lock(mutex);
      if (inbound_bus_topics.count(bus_topic) != 0) return std::nullopt;
    }
    for (const Route& r : options.to_dds) {
      if (r.from == bus_topic) return r.to;
    }
    if (to_regex && std::regex_search(bus_topic, *to_regex)) return bus_topic;
    return std::nullopt;
  }

  bool ScanBus() {
    bool changed = false;
    std::set<std::string> known;
    {
      std::lock_guard lock(mutex);
      for (const auto& o : outbound) known.insert(o->bus_topic);
    }
    for (const bus::TopicSnapshot& t : bus::ListTopics()) {
      if (known.count(t.topic) != 0) continue;
      const auto target = OutboundTarget(t.topic);
      if (!target) continue;
      const log::Ros2Converter* converter =
          log::FindRos2ConverterByProbelessType(t.type.name);
      if (converter == nullptr || converter->layout_hash() != t.type.layout_hash) {
        if (unsupported_logged.insert(t.topic).second) {
          Log("warning: bus topic " + t.topic + " (" + t.type.name +
              ") has no ROS 2 conversion; not bridged");
        }
        continue;
      }
      auto o = std::make_unique<Outbound>();
      o->bus_topic = t.topic;
      o->dds_topic = DdsTopicName(*target);
      o->dds_type = DdsTypeName(converter->ros2_type());
      o->converter = converter;
      bus::SubscriberOptions so;
      so.queue_depth = options.bus_queue_depth;
      so.receive_history = true;
      so.node_name = options.node_name;
      o->subscriber = std::make_unique<bus::Subscriber>(
          t.topic, bus::TopicType{std::string(converter->probeless_type()), converter->layout_hash()},
          so);
      auto [topic, sertype] = Topic(o->dds_topic, o->dds_type);
      const Qos q = QosFor(*target, std::string(converter->ros2_type()));
      dds_qos_t* qos = MakeQos(q, true);
      o->writer = dds_create_writer(participant, topic, qos, nullptr);
      dds_delete_qos(qos);
      CheckEntity(o->writer, "DDS writer on " + o->dds_topic);
      o->sertype = sertype;
      Log("bus " + o->bus_topic + " -> DDS " + o->dds_topic + " [" + o->dds_type + "] " +
          (q.reliability == Reliability::kReliable ? "reliable" : "best_effort") + " depth " +
          std::to_string(q.depth) +
          (q.durability == Durability::kVolatile ? " volatile" : " transient_local"));
      std::lock_guard lock(mutex);
      outbound.push_back(std::move(o));
      changed = true;
    }
    return changed;
  }

  void Forward(Outbound& o, const bus::Sample& sample) {
    log::CdrWriter writer;
    try {
      o.converter->Encode(sample.data(), writer);
    } catch (const std::exception& e) {
      if (o.errors.fetch_add(1) == 0) Log("warning: " + o.bus_topic + ": " + e.what());
      return;
    }
    const size_t size = writer.size();
    ddsi_serdata* sd = internal::MakeOpaqueSerdata(o.sertype, writer.Take());
    sd->statusinfo = 0;
    sd->timestamp.v = dds_time();
    const dds_return_t rc = dds_writecdr(o.writer, sd);
    if (rc == DDS_RETCODE_TIMEOUT) {
      o.write_drops.fetch_add(1);
    } else if (rc != DDS_RETCODE_OK) {
      if (o.errors.fetch_add(1) == 0) Log("warning: " + o.dds_topic + ": write: " + DdsErrorText(rc));
    } else {
      o.forwarded.fetch_add(1);
      o.bytes.fetch_add(size);
    }
  }

  void OutLoop() {
    auto next_scan = Clock::now();
    std::unique_ptr<bus::WaitSet> wait_set;
    std::vector<Outbound*> list;
    while (running.load()) {
      if (Clock::now() >= next_scan) {
        try {
          if (ScanBus() || !wait_set) {
            wait_set = std::make_unique<bus::WaitSet>();
            list.clear();
            std::lock_guard lock(mutex);
            for (const auto& o : outbound) {
              wait_set->Add(*o->subscriber);
              list.push_back(o.get());
            }
          }
        } catch (const std::exception& e) {
          Log(std::string("warning: bus scan: ") + e.what());
        }
        next_scan = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(options.rescan_period_s));
      }
      if (list.empty()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        continue;
      }
      for (size_t index : wait_set->Wait(std::chrono::milliseconds(20))) {
        Outbound& o = *list[index];
        while (auto sample = o.subscriber->TryTake()) Forward(o, *sample);
      }
    }
  }

  // --- DDS -> bus -------------------------------------------------------------------------------

  std::optional<std::string> InboundTarget(const std::string& ros_name) const {
    for (const Route& r : options.from_dds) {
      if (r.from == ros_name) return r.to;
    }
    if (from_regex && std::regex_search(ros_name, *from_regex)) {
      try {
        bus::ValidateTopicName(ros_name);
      } catch (const bus::BusError&) {
        return std::nullopt;
      }
      return ros_name;
    }
    return std::nullopt;
  }

  bool ScanPublications() {
    bool changed = false;
    void* samples[16] = {};
    dds_sample_info_t infos[16];
    while (true) {
      std::fill(std::begin(samples), std::end(samples), nullptr);
      const int n = dds_take(publications, samples, infos, 16, 16);
      if (n <= 0) break;
      for (int i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;
        const auto* ep = static_cast<const dds_builtintopic_endpoint_t*>(samples[i]);
        if (std::memcmp(ep->participant_key.v, own_guid.v, sizeof(own_guid.v)) == 0) continue;
        const std::string ros_name = RosTopicName(ep->topic_name ? ep->topic_name : "");
        if (ros_name.empty()) continue;
        const std::string dds_type = ep->type_name ? ep->type_name : "";
        {
          std::lock_guard lock(mutex);
          const bool known = std::any_of(inbound.begin(), inbound.end(), [&](const auto& in) {
            return in->dds_topic == ep->topic_name && in->dds_type == dds_type;
          });
          if (known) continue;
        }
        const auto target = InboundTarget(ros_name);
        if (!target) continue;
        const log::Ros2Converter* converter =
            log::FindRos2ConverterByRos2Type(Ros2TypeName(dds_type));
        if (converter == nullptr) {
          if (unsupported_logged.insert(ep->topic_name + std::string(" ") + dds_type).second) {
            Log("warning: DDS topic " + std::string(ep->topic_name) + " (" + dds_type +
                ") has no probeless conversion; not bridged");
          }
          continue;
        }
        auto in = std::make_unique<Inbound>();
        in->dds_topic = ep->topic_name;
        in->dds_type = dds_type;
        in->bus_topic = *target;
        in->converter = converter;
        auto [topic, sertype] = Topic(in->dds_topic, dds_type);
        const Qos q = QosFor(ros_name, std::string(converter->ros2_type()));
        dds_qos_t* qos = MakeQos(q, false);
        in->reader = dds_create_reader(participant, topic, qos, nullptr);
        dds_delete_qos(qos);
        CheckEntity(in->reader, "DDS reader on " + in->dds_topic);
        const dds_entity_t cond = dds_create_readcondition(in->reader, DDS_ANY_STATE);
        CheckEntity(cond, "DDS read condition on " + in->dds_topic);
        {
          std::lock_guard lock(mutex);
          const dds_return_t rc =
              dds_waitset_attach(waitset, cond, static_cast<dds_attach_t>(inbound.size()));
          if (rc != DDS_RETCODE_OK) throw DdsBridgeError("waitset attach: " + DdsErrorText(rc));
          Log("DDS " + in->dds_topic + " [" + dds_type + "] -> bus " + in->bus_topic + " " +
              (q.reliability == Reliability::kReliable ? "reliable" : "best_effort") +
              " depth " + std::to_string(q.depth));
          inbound_bus_topics.insert(in->bus_topic);
          inbound.push_back(std::move(in));
        }
        changed = true;
      }
      dds_return_loan(publications, samples, n);
    }
    return changed;
  }

  void Deliver(Inbound& in, std::span<const std::byte> cdr) {
    try {
      const size_t needed = in.converter->DecodedSize(cdr);
      if (!in.publisher || in.publisher->max_message_bytes() < needed) {
        in.publisher.reset();
        bus::PublisherOptions po;
        po.max_message_bytes = std::max<size_t>(needed + needed / 4, 4096);
        po.slot_count = options.bus_slot_count;
        po.node_name = options.node_name;
        in.publisher = std::make_unique<bus::Publisher>(
            in.bus_topic,
            bus::TopicType{std::string(in.converter->probeless_type()), in.converter->layout_hash()},
            po);
      }
      bus::Loan loan = in.publisher->Borrow(needed);
      const size_t used = in.converter->Decode(cdr, {}, loan.data());
      loan.Resize(used);
      in.publisher->Publish(std::move(loan));
      in.forwarded.fetch_add(1);
      in.bytes.fetch_add(cdr.size());
    } catch (const std::exception& e) {
      if (in.errors.fetch_add(1) == 0) Log("warning: " + in.dds_topic + ": " + e.what());
    }
  }

  void InLoop() {
    auto next_scan = Clock::now();
    std::vector<dds_attach_t> triggered(64);
    while (running.load()) {
      if (Clock::now() >= next_scan) {
        try {
          ScanPublications();
        } catch (const std::exception& e) {
          Log(std::string("warning: DDS discovery: ") + e.what());
        }
        next_scan = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(options.rescan_period_s));
      }
      {
        std::lock_guard lock(mutex);
        if (triggered.size() < inbound.size() + 1) triggered.resize(inbound.size() + 1);
      }
      const dds_return_t n = dds_waitset_wait(waitset, triggered.data(), triggered.size(),
                                              DDS_MSECS(20));
      if (n <= 0) continue;
      for (dds_return_t i = 0; i < n && static_cast<size_t>(i) < triggered.size(); ++i) {
        Inbound* in = nullptr;
        {
          std::lock_guard lock(mutex);
          if (static_cast<size_t>(triggered[i]) < inbound.size()) in = inbound[static_cast<size_t>(triggered[i])].get();
        }
        if (in == nullptr) continue;
        while (true) {
          ddsi_serdata* sd = nullptr;
          dds_sample_info_t info;
          const dds_return_t got = dds_takecdr(in->reader, &sd, 1, &info, DDS_ANY_STATE);
          if (got <= 0) break;
          if (info.valid_data) Deliver(*in, internal::OpaqueBytes(sd));
          ddsi_serdata_unref(sd);
        }
      }
    }
  }
};

Bridge::Bridge(BridgeOptions options) : impl_(std::make_unique<Impl>()) {
  impl_->options = std::move(options);
  try {
    impl_->Init();
  } catch (...) {
    impl_->Fini();
    throw;
  }
}

Bridge::~Bridge() {
  Stop();
  impl_->Fini();
}

void Bridge::Start() {
  if (impl_->running.exchange(true)) return;
  impl_->out_thread = std::thread([this] { impl_->OutLoop(); });
  impl_->in_thread = std::thread([this] { impl_->InLoop(); });
}

void Bridge::Stop() {
  impl_->running.store(false);
  if (impl_->out_thread.joinable()) impl_->out_thread.join();
  if (impl_->in_thread.joinable()) impl_->in_thread.join();
}

int Bridge::domain_id() const { return impl_->domain_id; }

std::vector<TopicStats> Bridge::Stats() const {
  std::vector<TopicStats> out;
  std::lock_guard lock(impl_->mutex);
  for (const auto& o : impl_->outbound) {
    TopicStats s;
    s.bus_topic = o->bus_topic;
    s.dds_topic = o->dds_topic;
    s.dds_type = o->dds_type;
    s.to_dds = true;
    s.forwarded = o->forwarded.load();
    s.dropped = o->subscriber->dropped() + o->write_drops.load();
    s.errors = o->errors.load();
    s.bytes = o->bytes.load();
    out.push_back(std::move(s));
  }
  for (const auto& in : impl_->inbound) {
    TopicStats s;
    s.bus_topic = in->bus_topic;
    s.dds_topic = in->dds_topic;
    s.dds_type = in->dds_type;
    s.to_dds = false;
    dds_sample_lost_status_t lost{};
    if (dds_get_sample_lost_status(in->reader, &lost) == DDS_RETCODE_OK) {
      in->lost.fetch_add(lost.total_count_change);
    }
    s.forwarded = in->forwarded.load();
    s.dropped = in->lost.load();
    s.errors = in->errors.load();
    s.bytes = in->bytes.load();
    out.push_back(std::move(s));
  }
  return out;
}

}  // namespace probeless::dds_bridge
