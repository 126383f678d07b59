// Replays fuzz inputs without libFuzzer: `<fuzzer>_replay FILE_OR_DIR...` calls the target's
// LLVMFuzzerTestOneInput once per file (a directory's files in name order) and prints how many
// ran. A crash, an abort of a contract check or an escaped exception fails the ctest run
// (<name>_seeds, registered by probeless_add_fuzzer in every test build).
//
// `--mutate SECONDS [--seed N]` then keeps going with random mutations of those inputs (byte
// flips, inserts, erases, copies, splices; no coverage feedback) for the readers a compiler cannot
// build as libFuzzer targets (docs/fuzzing.md). An input that crashes or aborts is written to
// ./crash-replay-<seed>-<n> before the process dies.
#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "probeless/parse/number.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

// The input being run, for the crash handler (async-signal-safe: open/write only).
std::vector<uint8_t> g_current;
char g_crash_path[64] = "crash-replay";

void OnCrash(int signal) {
  const int fd = ::open(g_crash_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd >= 0) {
    const ssize_t ignored = ::write(fd, g_current.data(), g_current.size());
    (void)ignored;
    ::close(fd);
  }
  const char message[] = "replay: crashing input written to ";
  (void)!::write(2, message, sizeof(message) - 1);
  (void)!::write(2, g_crash_path, std::strlen(g_crash_path));
  (void)!::write(2, "\n", 1);
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

void Run(const std::vector<uint8_t>& input) {
  g_current = input;
  LLVMFuzzerTestOneInput(g_current.data(), g_current.size());
}

std::vector<uint8_t> Mutate(std::vector<uint8_t> in, const std::vector<std::vector<uint8_t>>& all,
                            std::mt19937_64& rng) {
  auto pick = [&](size_t n) { return n == 0 ? size_t{0} : static_cast<size_t>(rng() % n); };
  const int steps = 1 + static_cast<int>(rng() % 4);
  for (int s = 0; s < steps; ++s) {
    switch (rng() % 6) {
      case 0:  // flip a bit
        if (!in.empty()) in[pick(in.size())] ^= static_cast<uint8_t>(1u << (rng() % 8));
        break;
      case 1:  // a random or an interesting byte
        if (!in.empty()) {
          static const uint8_t kBytes[] = {0, 0xff, '-', '9', '\n', ' ', ':', '[', '0', '.'};
          in[pick(in.size())] =
              rng() % 2 ? static_cast<uint8_t>(rng()) : kBytes[rng() % sizeof(kBytes)];
        }
        break;
      case 2: {  // insert bytes
        const size_t at = pick(in.size() + 1);
        in.insert(in.begin() + static_cast<long>(at), 1 + rng() % 8, static_cast<uint8_t>(rng()));
        break;
      }
      case 3: {  // erase a range
        if (in.empty()) break;
        const size_t at = pick(in.size());
        const size_t n = 1 + pick(std::min<size_t>(in.size() - at, 64));
        in.erase(in.begin() + static_cast<long>(at), in.begin() + static_cast<long>(at + n));
        break;
      }
      case 4: {  // duplicate a range
        if (in.empty()) break;
        const size_t at = pick(in.size());
        const size_t n = 1 + pick(std::min<size_t>(in.size() - at, 64));
        const std::vector<uint8_t> part(in.begin() + static_cast<long>(at),
                                        in.begin() + static_cast<long>(at + n));
        in.insert(in.begin() + static_cast<long>(pick(in.size() + 1)), part.begin(), part.end());
        break;
      }
      default: {  // splice: our head, another input's tail
        const std::vector<uint8_t>& other = all[pick(all.size())];
        in.resize(pick(in.size() + 1));
        in.insert(in.end(), other.begin() + static_cast<long>(pick(other.size() + 1)), other.end());
        break;
      }
    }
  }
  return in;
}

std::vector<uint8_t> ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "replay: cannot read '%s'\n", path.c_str());
    std::exit(2);
  }
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

int main(int argc, char** argv) {
  double mutate_seconds = 0;
  uint64_t seed = 1;
  std::vector<std::string> paths;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if ((a == "--mutate" || a == "--seed") && i + 1 < argc) {
      if (a == "--mutate") {
        mutate_seconds = probeless::parse::ParseDouble(a, argv[++i], 0);
      } else {
        seed = probeless::parse::ParseInteger<uint64_t>(a, argv[++i]);
      }
    } else {
      paths.push_back(a);
    }
  }
  if (paths.empty()) {
    std::fprintf(stderr, "usage: %s [--mutate SECONDS [--seed N]] FILE_OR_DIR...\n", argv[0]);
    return 2;
  }
  for (int s : {SIGSEGV, SIGABRT, SIGBUS, SIGFPE, SIGILL}) std::signal(s, OnCrash);
  std::vector<std::vector<uint8_t>> inputs;
  size_t count = 0;
  for (const std::string& path : paths) {
    const std::filesystem::path arg = path;
    std::vector<std::filesystem::path> files;
    if (std::filesystem::is_directory(arg)) {
      for (const auto& entry : std::filesystem::directory_iterator(arg)) {
        if (entry.is_regular_file()) files.push_back(entry.path());
      }
      std::sort(files.begin(), files.end());
    } else {
      files.push_back(arg);
    }
    for (const auto& file : files) {
      std::printf("replay: %s\n", file.c_str());
      std::fflush(stdout);  // the last name printed is the input that crashed
      inputs.push_back(ReadFile(file));
      Run(inputs.back());
      ++count;
    }
  }
  std::printf("replay: %zu inputs ran\n", count);
  if (count == 0) return 2;
  if (mutate_seconds > 0) {
    std::snprintf(g_crash_path, sizeof(g_crash_path), "crash-replay-%llu",
                  static_cast<unsigned long long>(seed));
    std::mt19937_64 rng(seed);
    const auto end =
        std::chrono::steady_clock::now() + std::chrono::duration<double>(mutate_seconds);
    uint64_t runs = 0;
    while (std::chrono::steady_clock::now() < end) {
      std::vector<uint8_t> input = Mutate(inputs[rng() % inputs.size()], inputs, rng);
      if (input.size() > (1u << 20)) input.resize(1u << 20);
      Run(input);
      // Keep some mutants as further starting points (no coverage: a crude breadth).
      if (rng() % 16 == 0 && inputs.size() < 4096) inputs.push_back(std::move(input));
      ++runs;
    }
    std::printf("replay: %llu mutated inputs ran (seed %llu)\n",
                static_cast<unsigned long long>(runs), static_cast<unsigned long long>(seed));
  }
  return 0;
}
