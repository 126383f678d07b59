// recorder: records bus topics into MCAP files until SIGINT/SIGTERM (probeless::record::Recorder).
//
// Params (ROS 2 style, -p name:=value or a params file):
//   topics (string array, [])    topics to record (relative names are resolved in the namespace)
//   regex (string, "")           also record topics matching this ECMAScript regex (search)
//   exclude (string, "")         never record topics matching this regex
//   all (bool, false)            record every topic
//   output (string, "")          file name (no split) or prefix; default probeless_<local time>
//   split_size_mb (double, 0)    new file every this many MB (10^6 bytes; 0 = no size split)
//   split_duration_s (double, 0) new file every this many seconds (0 = no time split)
//   compression (string, none)   none, lz4 or zstd
//   queue_depth (int, 64)        bus queue depth per topic (1..64)
//   chunk_size_mb (double, 8)    MCAP chunk size in MiB
// Command line (own arguments before --ros-args; they override the params):
//   recorder [-o OUTPUT] [-a|--all] [-e REGEX] [-x REGEX] [--compression none|lz4|zstd]
//            [--split-size-mb MB] [--split-duration-s S] [--queue-depth N]
//            [--chunk-size-mb MIB] [TOPIC...]
// At exit prints on stdout one line per topic
//   <topic>: received=N dropped=D invalid=I bytes=B
// (dropped: lost in the bus queue; invalid: failed conversion), then "file: <path>" per file
// and "summary: topics=T received=N dropped=D bytes=B files=F".
// Exit status: 0 after a clean stop; 2 for bad params/options or an output that cannot be
// created (one line on stderr); 1 if recording failed (the report is printed first).
#include <cstdio>
#include <exception>
#include <memory>
#include <string>

#include "params.h"
#include "probeless/node/flags.h"
#include "probeless/node/node.h"
#include "probeless/record/recorder.h"

namespace {

using namespace probeless;

void PrintReport(const record::RecorderStats& stats) {
  std::fputs(record::RecorderReport(stats).c_str(), stdout);
  std::fflush(stdout);
}

int Run(int argc, char** argv) {
  std::string name = "recorder";
  // The recorder's log callback uses the node: declared after it, destroyed before it.
  std::unique_ptr<node::Node> node;
  std::unique_ptr<record::Recorder> recorder;
  try {
    recorder::RecorderSettings s;
    // The command line: declared first for the node's usage text, parsed after the params.
    node::FlagParser flags("recorder", "records bus topics into MCAP files until SIGINT");
    recorder::DeclareFlags(flags, s);
    node = std::make_unique<node::Node>(argc, argv, "recorder", flags.Usage());
    name = node->fully_qualified_name();
    recorder::ReadParams(*node, s);
    node->CheckParamOverrides();
    if (!flags.Parse(node->args())) return 0;
    recorder = std::make_unique<record::Recorder>(recorder::MakeOptions(*node, s));
    recorder->Start();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [%s] %s\n", name.c_str(), e.what());
    return 2;
  }

  node->Info() << "recording to " << recorder->Stats().files.front();
  while (node->ok() && !recorder->Failed()) {
    node->WaitForShutdown(std::chrono::milliseconds(200));
  }
  try {
    const record::RecorderStats stats = recorder->Stop();
    PrintReport(stats);
    node->Info() << "wrote " << stats.written << " messages (" << stats.file_bytes << " bytes) to "
                 << stats.files.size() << " file(s)";
  } catch (const std::exception& e) {
    PrintReport(recorder->Stats());
    std::fprintf(stderr, "[error] [%s] recording failed: %s\n", name.c_str(), e.what());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return Run(argc, argv); }
