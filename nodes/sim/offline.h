// sim's offline modes: a contact sheet of a scenario, a Yale-B-style face data set, the
// evaluation world's generated scenes. Each writes files, prints one summary line on stdout and
// progress on stderr.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "probeless/sim/generate.h"
#include "probeless/sim/simulator.h"
#include "probeless/sim/yaleb_style.h"

namespace probeless::sim_node {

// A progress callback (done, total) printing "[info] [sim] <what>: <unit> k/N (x <unit>s/s)" on
// stderr at most once a second, and at the end.
std::function<void(uint64_t, uint64_t)> ProgressPrinter(const std::string& what,
                                                        const std::string& unit = "frame");

// A contact sheet of up to 8 of the first `frames` frames evenly spread, RGB above a colour-mapped
// depth (0-5 m), written to `path` (a PNG). Throws std::runtime_error if it cannot be written.
void WritePreview(sim::Scenario scenario, uint64_t frames, int threads, const std::string& path);

// sim --yaleb-style: sim::WriteYaleBStyleDataset into `out_dir`, with the ICT mesh and the light
// list of the shared data when present. Throws node::UsageError for a mesh other than procedural
// or ict, an ict mesh not found, or options sim::YaleBStyleOptions::Validate refuses. Returns 0.
int WriteYaleBStyle(const std::string& out_dir, sim::YaleBStyleOptions options);

// sim --generate: `count` (>= 1) scenes of split `split_name` with seeds SplitSeedBase(split) +
// seed + k, one after the other, into `out_dir`; with `resume`, scenes whose scene.json exists
// are skipped. Throws node::UsageError for a bad count, an empty out_dir or seeds crossing into
// the next split's range, sim::ScenarioError for a bad split or options. Returns 0.
int Generate(int count, uint64_t seed, const std::string& split_name, const std::string& out_dir,
             sim::GenerateOptions options, bool resume);

}  // namespace probeless::sim_node
