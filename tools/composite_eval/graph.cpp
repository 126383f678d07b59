#include "graph.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <stdexcept>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"

namespace probeless::composite_eval {

namespace {

volatile sig_atomic_t stop_requested = 0;

Rgb8 CopyImage(const bus::Sample& s) {
  const auto m = msgs::ReadMessage<msgs::Image>(s.data());
  Rgb8 out;
  out.width = static_cast<int>(m->width);
  out.height = static_cast<int>(m->height);
  out.rgb.resize(static_cast<size_t>(out.width) * out.height * 3);
  const size_t row_bytes = static_cast<size_t>(out.width) * 3;
  for (int y = 0; y < out.height; ++y) {
    std::memcpy(out.rgb.data() + y * row_bytes, m.payload.data() + static_cast<size_t>(y) * m->step,
                row_bytes);
  }
  return out;
}

}  // namespace

void RequestStop() { stop_requested = 1; }
bool StopRequested() { return stop_requested != 0; }

GraphOutput RunGraph(const GraphArgs& args, const std::function<void(size_t)>& progress) {
  // The bus reads the domain at each call: set it before the subscribers and the fork.
  ::setenv("PROBELESS_DOMAIN", args.domain.c_str(), 1);
  GraphOutput out;
  {
    bus::SubscriberOptions options;
    options.queue_depth = bus::kMaxQueueDepth;
    options.node_name = "/composite_eval";
    bus::Subscriber ours("/render/composite", msgs::TopicTypeOf<msgs::Image>(), options);
    bus::Subscriber oracle("/render/composite_oracle", msgs::TopicTypeOf<msgs::Image>(), options);
    bus::Subscriber baseline("/render/composite_baseline", msgs::TopicTypeOf<msgs::Image>(),
                             options);
    bus::Subscriber light("/scene/light", msgs::TopicTypeOf<msgs::ShLight>(), options);

    std::vector<std::string> argv_text = {args.probeless, "launch", args.launch_file};
    argv_text.insert(argv_text.end(), args.launch_args.begin(), args.launch_args.end());
    std::vector<char*> argv;
    for (std::string& a : argv_text) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int log_fd = ::open(args.log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (log_fd < 0) throw std::runtime_error("cannot write " + args.log_path);
    const pid_t pid = ::fork();
    if (pid < 0) throw std::runtime_error(std::string("fork: ") + std::strerror(errno));
    if (pid == 0) {
      ::dup2(log_fd, 1);
      ::dup2(log_fd, 2);
      const int null_fd = ::open("/dev/null", O_RDONLY);
      if (null_fd >= 0) ::dup2(null_fd, 0);
      ::execv(argv[0], argv.data());
      std::fprintf(stderr, "cannot run %s: %s\n", argv[0], std::strerror(errno));
      ::_exit(127);
    }
    ::close(log_fd);

    bus::WaitSet waits;
    waits.Add(ours);
    waits.Add(oracle);
    waits.Add(baseline);
    waits.Add(light);
    const auto start = std::chrono::steady_clock::now();
    size_t reported = 0;
    auto drain = [&] {
      while (auto s = ours.TryTake()) {
        const int64_t stamp = msgs::ReadMessage<msgs::Image>(s->data())->header.stamp_ns;
        out.ours[stamp] = CopyImage(*s);
      }
      while (auto s = oracle.TryTake()) {
        const int64_t stamp = msgs::ReadMessage<msgs::Image>(s->data())->header.stamp_ns;
        out.oracle[stamp] = CopyImage(*s);
      }
      while (auto s = baseline.TryTake()) {
        const int64_t stamp = msgs::ReadMessage<msgs::Image>(s->data())->header.stamp_ns;
        out.baseline[stamp] = CopyImage(*s);
      }
      while (auto s = light.TryTake()) {
        const msgs::ShLight l = *msgs::ReadMessage<msgs::ShLight>(s->data());
        out.lights[l.header.stamp_ns] = l;
      }
      if (out.baseline.size() > reported) {
        reported = out.baseline.size();
        if (progress) progress(reported);
      }
    };
    int status = 0;
    bool interrupted = false;
    for (;;) {
      waits.Wait(std::chrono::milliseconds(100));
      drain();
      const pid_t done = ::waitpid(pid, &status, WNOHANG);
      if (done == pid) break;
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (!interrupted && (elapsed > args.timeout_s || StopRequested())) {
        ::kill(pid, SIGINT);  // the supervisor stops its graph
        interrupted = true;
        out.timed_out = !StopRequested();
        out.interrupted = StopRequested();
      }
    }
    drain();
    out.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  ::unsetenv("PROBELESS_DOMAIN");
  return out;
}

}  // namespace probeless::composite_eval
