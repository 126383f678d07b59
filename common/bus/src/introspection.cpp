// ListTopics and CleanDeadSegments: read or tidy the registries without joining them.
#include <dirent.h>

#include <algorithm>
#include <cstring>

#include "probeless/bus/bus.h"
#include "shm.h"
#include "topic.h"

namespace probeless::bus {
namespace {

using internal::kActive;
using internal::kFree;

// Names in /dev/shm starting with this user's and domain's prefix, without the prefix.
std::vector<std::string> ListSegments(const std::string& domain) {
  const std::string prefix = internal::SegmentPrefix(domain);
  std::vector<std::string> names;
  DIR* dir = ::opendir("/dev/shm");
  if (dir == nullptr) return names;
  while (dirent* ent = ::readdir(dir)) {
    const std::string name = ent->d_name;
    if (name.rfind(prefix, 0) == 0) names.push_back(name.substr(prefix.size()));
  }
  ::closedir(dir);
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace

std::vector<TopicSnapshot> ListTopics(const std::string& domain) {
  std::vector<TopicSnapshot> topics;
  for (const auto& name : ListSegments(domain)) {
    if (name.rfind("t.", 0) != 0) continue;
    const std::string topic = internal::DecodeTopic(name.substr(2));
    std::shared_ptr<internal::TopicHandle> handle;
    try {
      handle = internal::TopicHandle::Open(domain, topic, /*create=*/false);
    } catch (const BusError&) {
      continue;  // invalid name or foreign layout: not ours to show
    }
    if (!handle) continue;
    auto* ctrl = handle->ctrl();
    internal::RobustLock lock(&ctrl->mutex);
    if (ctrl->dead) continue;
    TopicSnapshot snap;
    snap.topic = topic;
    snap.type.name = ctrl->type_name;
    snap.type.layout_hash = ctrl->layout_hash;
    for (const auto& p : ctrl->publishers) {
      if (p.state.load() != kActive) continue;
      PublisherSnapshot ps;
      ps.pid = p.owner.pid;
      ps.alive = internal::ProbablyAlive(p.owner);
      ps.node_name = p.node_name;
      ps.max_message_bytes = p.capacity;
      ps.slot_count = p.slot_count;
      ps.history = p.history;
      ps.published = p.published.load();
      ps.published_bytes = p.published_bytes.load();
      ps.last_publish_mono_ns = p.last_publish_mono_ns.load();
      snap.publishers.push_back(ps);
    }
    for (auto& s : ctrl->subscribers) {
      if (s.state.load() != kActive) continue;
      SubscriberSnapshot ss;
      ss.pid = s.owner.pid;
      ss.alive = internal::ProbablyAlive(s.owner);
      ss.node_name = s.node_name;
      {
        internal::RobustLock sub_lock(&s.mutex);
        ss.queue_depth = s.depth;
        ss.queued = internal::LiveCount(s);
      }
      ss.received = s.received.load();
      ss.dropped = s.dropped.load();
      snap.subscribers.push_back(ss);
    }
    topics.push_back(std::move(snap));
  }
  return topics;
}

std::vector<std::string> CleanDeadSegments(const std::string& domain) {
  const std::string prefix = internal::SegmentPrefix(domain);
  std::vector<std::string> removed;
  // Registries first: reclaiming their dead participants frees the segments of dead publishers.
  std::vector<std::string> referenced;
  for (const auto& name : ListSegments(domain)) {
    if (name.rfind("t.", 0) != 0) continue;
    const std::string topic = internal::DecodeTopic(name.substr(2));
    std::shared_ptr<internal::TopicHandle> handle;
    try {
      handle = internal::TopicHandle::Open(domain, topic, /*create=*/false);
    } catch (const BusError&) {
      continue;
    }
    if (!handle) {
      // Never finished initialising (its creator died): Open gave up on it.
      if (internal::OpenSegment(prefix + name, 0) != nullptr) {
        internal::UnlinkSegment(prefix + name);
        removed.push_back(prefix + name);
      }
      continue;
    }
    auto* ctrl = handle->ctrl();
    internal::RobustLock lock(&ctrl->mutex);
    if (ctrl->dead) continue;
    handle->MaintainLocked(/*full_check=*/true);
    handle->LeaveLocked();  // unlinks the registry if nobody is left
    for (auto& n : handle->TakeUnlinked()) removed.push_back(n);
    for (const auto& p : ctrl->publishers) {
      if (p.state.load() != kFree) referenced.push_back(p.segment);
    }
  }
  // Publisher segments no registry references and whose owner is dead.
  for (const auto& name : ListSegments(domain)) {
    if (name.rfind("p.", 0) != 0) continue;
    const std::string full = prefix + name;
    if (std::find(referenced.begin(), referenced.end(), full) != referenced.end()) continue;
    auto mapping = internal::OpenSegment(full, sizeof(internal::PublisherHeader));
    if (mapping) {
      const auto* header = internal::TopicHandle::Header(*mapping);
      if (header->magic == internal::kPublisherMagic && internal::DefinitelyAlive(header->owner)) {
        continue;  // a live publisher between creating its segment and registering it
      }
    }
    internal::UnlinkSegment(full);
    removed.push_back(full);
  }
  std::sort(removed.begin(), removed.end());
  removed.erase(std::unique(removed.begin(), removed.end()), removed.end());
  return removed;
}

}  // namespace probeless::bus
