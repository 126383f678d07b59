#include "probeless/launch/proc_stat.h"

#include <unistd.h>

#include <array>
#include <charconv>
#include <fstream>
#include <string>

namespace probeless::launch {
namespace {

// Whole-token number: false when `token` is not exactly a number of type T.
template <typename T>
bool ParseNumber(std::string_view token, T& value) {
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  return ec == std::errc() && ptr == end && !token.empty();
}

}  // namespace

double ProcStat::CpuSeconds() const {
  return static_cast<double>(utime_ticks + stime_ticks) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

std::optional<ProcStat> ParseProcStat(std::string_view line) {
  while (!line.empty() && (line.back() == '\n' || line.back() == ' ')) line.remove_suffix(1);
  const size_t open = line.find(" (");
  const size_t close = line.rfind(')');
  if (open == std::string_view::npos || close == std::string_view::npos || close < open) {
    return std::nullopt;
  }
  ProcStat s;
  if (!ParseNumber(line.substr(0, open), s.pid)) return std::nullopt;
  // fields[k] is field k + 3 of proc(5): the ones after the command name.
  constexpr int kFirst = 3, kLast = 22;
  std::array<std::string_view, kLast - kFirst + 1> fields;
  std::string_view rest = line.substr(close + 1);
  for (std::string_view& field : fields) {
    if (rest.empty() || rest.front() != ' ') return std::nullopt;
    rest.remove_prefix(1);
    field = rest.substr(0, rest.find(' '));
    rest.remove_prefix(field.size());
  }
  if (fields[0].size() != 1) return std::nullopt;
  s.state = fields[0][0];
  if (!ParseNumber(fields[4 - kFirst], s.ppid) || !ParseNumber(fields[5 - kFirst], s.pgid) ||
      !ParseNumber(fields[14 - kFirst], s.utime_ticks) ||
      !ParseNumber(fields[15 - kFirst], s.stime_ticks) ||
      !ParseNumber(fields[22 - kFirst], s.start_ticks)) {
    return std::nullopt;
  }
  return s;
}

std::optional<ProcStat> ReadProcStat(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(in, line)) return std::nullopt;
  return ParseProcStat(line);
}

}  // namespace probeless::launch
