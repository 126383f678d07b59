#include "probeless/launch/proc_stat.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>

namespace probeless::launch {
namespace {

// A real line (kernel 6.1) with a command name that holds spaces and ')'.
constexpr const char* kLine =
    "4242 (my node) (x)) S 17 4240 17 34816 4240 4194560 1571 0 3 0 250 37 0 0 20 0 5 0 "
    "987654 12345678 2048 18446744073709551615 1 1 0 0 0 0 0 4096 0 0 0 0 17 1 0 0 0 0 0\n";

TEST(ProcStat, ParsesTheFieldsAfterTheLastParenthesis) {
  const std::optional<ProcStat> s = ParseProcStat(kLine);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->pid, 4242);
  EXPECT_EQ(s->state, 'S');
  EXPECT_EQ(s->ppid, 17);
  EXPECT_EQ(s->pgid, 4240);
  EXPECT_EQ(s->utime_ticks, 250u);
  EXPECT_EQ(s->stime_ticks, 37u);
  EXPECT_EQ(s->start_ticks, 987654u);
  EXPECT_TRUE(s->Alive());
  EXPECT_DOUBLE_EQ(s->CpuSeconds(), 287.0 / static_cast<double>(sysconf(_SC_CLK_TCK)));
}

TEST(ProcStat, ZombieIsNotAlive) {
  std::string line = kLine;
  line[line.find(") S") + 2] = 'Z';
  const std::optional<ProcStat> s = ParseProcStat(line);
  ASSERT_TRUE(s.has_value());
  EXPECT_FALSE(s->Alive());
}

TEST(ProcStat, RejectsMalformedLines) {
  EXPECT_FALSE(ParseProcStat("").has_value());
  EXPECT_FALSE(ParseProcStat("4242 (node) S 17 4240").has_value());  // too few fields
  EXPECT_FALSE(ParseProcStat("42x (node) S 17 4240 17 34816 4240 4194560 1571 0 3 0 250 37 0 0 "
                             "20 0 5 0 987654")
                   .has_value());  // pid not a number
  EXPECT_FALSE(ParseProcStat("4242 (node) S 17 4240 17 34816 4240 4194560 1571 0 3 0 2x0 37 0 0 "
                             "20 0 5 0 987654")
                   .has_value());  // utime not a number
  EXPECT_FALSE(ParseProcStat("4242 node S 17 4240 17 34816 4240 4194560 1571 0 3 0 250 37 0 0 "
                             "20 0 5 0 987654")
                   .has_value());  // no command name
}

TEST(ProcStat, ReadsThisProcessAndNotAReapedOne) {
  const std::optional<ProcStat> self = ReadProcStat(getpid());
  ASSERT_TRUE(self.has_value());
  EXPECT_EQ(self->pid, getpid());
  EXPECT_EQ(self->ppid, getppid());
  EXPECT_EQ(self->pgid, getpgrp());
  EXPECT_TRUE(self->Alive());
  // Burn some CPU: the counter must grow (a tick is 10 ms).
  const double before = self->CpuSeconds();
  const auto start = std::chrono::steady_clock::now();
  volatile double sink = 0;
  while (std::chrono::steady_clock::now() - start < std::chrono::milliseconds(200)) sink += 1.0;
  EXPECT_GT(ReadProcStat(getpid())->CpuSeconds(), before);

  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) _exit(0);
  ASSERT_EQ(waitpid(child, nullptr, 0), child);
  EXPECT_FALSE(ReadProcStat(child).has_value());
}

}  // namespace
}  // namespace probeless::launch
