// Chaos test of the bus: processes killed with SIGKILL at random moments (fixed seed), also inside
// the bus's critical sections. Afterwards every slot must be reclaimable, the survivors must still
// talk, and nothing may be left in /dev/shm.
#include <dirent.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <map>
#include <random>
#include <thread>

#include "probeless/bus/bus.h"

namespace probeless::bus {
namespace {

using namespace std::chrono_literals;

const TopicType kFrame{"test_msgs/Frame", 42};

std::vector<std::string> Segments() {
  const std::string prefix = "probeless." + std::to_string(getuid()) + "." + CurrentDomain() + ".";
  std::vector<std::string> names;
  DIR* dir = opendir("/dev/shm");
  while (dirent* ent = readdir(dir)) {
    if (std::string(ent->d_name).rfind(prefix, 0) == 0) names.push_back(ent->d_name);
  }
  closedir(dir);
  return names;
}

template <typename F>
pid_t Spawn(F body) {
  const pid_t pid = fork();
  if (pid == 0) {
    try {
      body();
    } catch (const std::exception& e) {
      fprintf(stderr, "child %d: %s\n", getpid(), e.what());
      _exit(3);
    }
    _exit(0);
  }
  return pid;
}

void Reap(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
}

// Subscribers that take, hold a few samples, and are killed at random.
void ChurningSubscriber(uint32_t depth) {
  Subscriber sub("/chaos/frames", kFrame, {.queue_depth = depth});
  std::vector<Sample> held;
  for (;;) {
    if (auto s = sub.Take(50ms)) {
      held.push_back(std::move(*s));
      if (held.size() > 3) held.erase(held.begin());
    }
  }
}

TEST(BusChaosTest, RandomKillsOfSubscribersAndPublishersLeaveTheBusHealthy) {
  CleanDeadSegments();
  std::mt19937 rng(20261123);
  constexpr uint32_t kSlots = 48;
  PublisherOptions options;
  options.max_message_bytes = 64 * 1024;
  options.slot_count = kSlots;
  options.history = 2;
  Publisher pub("/chaos/frames", kFrame, options);

  // A steady subscriber in this process must see a strictly increasing stream throughout.
  Subscriber steady("/chaos/frames", kFrame, {.queue_depth = 64});
  // Sequence numbers rise per publisher process (each restart starts again at 1).
  std::map<int32_t, uint64_t> last_sequence;
  uint64_t steady_received = 0;
  auto drain = [&] {
    while (auto s = steady.TryTake()) {
      uint64_t& last = last_sequence[s->info().publisher_pid];
      ASSERT_GT(s->info().sequence, last);
      last = s->info().sequence;
      ++steady_received;
    }
  };

  // A second publisher process that is killed and restarted.
  auto start_publisher = [] {
    return Spawn([] {
      PublisherOptions o;
      o.max_message_bytes = 64 * 1024;
      o.slot_count = 32;  // > 6 churning subscribers x 3 held samples + queues
      Publisher p("/chaos/frames", kFrame, o);
      for (;;) {
        Loan loan = p.Borrow(4096);
        std::memset(loan.data().data(), 0x5A, 4096);
        p.Publish(std::move(loan));
      }
    });
  };

  std::vector<pid_t> subscribers;
  pid_t other_publisher = start_publisher();
  // However the test ends, no child outlives it.
  struct Reaper {
    std::vector<pid_t>* subs;
    pid_t* pub;
    ~Reaper() { KillAll(); }
    void KillAll() {
      for (pid_t pid : *subs) {
        kill(pid, SIGKILL);
        Reap(pid);
      }
      subs->clear();
      if (*pub > 0) {
        kill(*pub, SIGKILL);
        Reap(*pub);
        *pub = 0;
      }
    }
  } reaper{&subscribers, &other_publisher};
  const auto end = std::chrono::steady_clock::now() + 3s;
  int kills = 0;
  while (std::chrono::steady_clock::now() < end) {
    // Publish a burst (never blocks, never throws: slots of dead subscribers come back).
    for (int i = 0; i < 20; ++i) {
      Loan loan = pub.Borrow(1 + rng() % options.max_message_bytes);
      loan.data()[0] = std::byte{1};
      pub.Publish(std::move(loan));
    }
    drain();
    if (subscribers.size() < 6)
      subscribers.push_back(Spawn([&] { ChurningSubscriber(1 + rng() % 4); }));
    std::this_thread::sleep_for(std::chrono::microseconds(rng() % 3000));
    if (rng() % 3 == 0 && !subscribers.empty()) {
      const size_t victim = rng() % subscribers.size();
      kill(subscribers[victim], SIGKILL);
      Reap(subscribers[victim]);
      subscribers.erase(subscribers.begin() + victim);
      ++kills;
    }
    if (rng() % 10 == 0) {
      kill(other_publisher, SIGKILL);
      Reap(other_publisher);
      other_publisher = start_publisher();
      ++kills;
    }
  }
  reaper.KillAll();
  drain();
  EXPECT_GT(kills, 10);
  EXPECT_GT(steady_received, 100u);

  // Only the steady subscriber (queue up to 64) and the history (2) may still hold slots: after
  // draining it, all kSlots slots must be borrowable at once.
  std::vector<Loan> loans;
  for (uint32_t i = 0; i < kSlots - options.history; ++i) {
    ASSERT_NO_THROW(loans.push_back(pub.Borrow(16))) << "slot " << i << " was never reclaimed";
  }
  loans.clear();
  EXPECT_EQ(pub.SubscriberCount(), 1u);
  // The survivors still talk.
  const std::string text = "after the storm";
  pub.PublishCopy(std::as_bytes(std::span(text.data(), text.size())));
  auto after = steady.Take(1s);
  ASSERT_TRUE(after);
  EXPECT_EQ(after->data().size(), text.size());
  after.reset();

  // Everything gone once the survivors leave and dead leftovers are cleaned.
  {
    Subscriber tmp = std::move(steady);
    Publisher tmp_pub = std::move(pub);
  }
  CleanDeadSegments();
  EXPECT_TRUE(Segments().empty()) << Segments().front();
}

}  // namespace
}  // namespace probeless::bus
