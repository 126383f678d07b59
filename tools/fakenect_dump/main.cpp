// fakenect_dump: writes a fakenect dump (libfreenect's Kinect v1 simulator: INDEX.txt, r-*.ppm RGB,
// d-*.pgm raw 11-bit disparity) from any probeless source with colour and depth — a dataset folder
// (7-Scenes, TUM RGB-D) or an MCAP log — so capture_freenect can be tested through the real
// libfreenect API (LD_LIBRARY_PATH=/usr/lib/x86_64-linux-gnu/fakenect FAKENECT_PATH=OUT).
//
//   fakenect_dump SOURCE OUT_DIR [--max-frames N] [--fps F]
//
// Depth in mm becomes raw disparity with the libfreenect model (capture::KinectDepthModel); depths
// the Kinect cannot measure (0, < ~0.32 m, > 10 m) become 2047 ("no data"). Frames must be 640x480
// (the Kinect's medium resolution). Exit: 0 done, 2 bad input (one line on stderr).
#include "probeless/node/main.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "probeless/capture/convert.h"
#include "probeless/msgs/image.h"
#include "probeless/node/flags.h"
#include "probeless/replay/sources.h"

namespace {

using namespace probeless;
namespace fs = std::filesystem;

using node::UsageError;

void WriteFile(const fs::path& path, const std::string& header, const void* data, size_t bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << header;
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
  if (!out) throw UsageError("cannot write '" + path.string() + "'");
}

int Run(int argc, char** argv) {
  uint64_t max_frames = 0;
  dataset::DatasetOptions options;
  std::string source_path, out_path;
  node::FlagParser flags("fakenect_dump",
                         "writes a fakenect dump (libfreenect's Kinect v1 simulator) from any "
                         "probeless source with colour and depth");
  flags.AddPositional(
      "SOURCE", &source_path,
      "a dataset folder (7-Scenes, TUM RGB-D) or an MCAP log with colour and depth (required)");
  flags.AddPositional("OUT_DIR", &out_path,
                      "the fakenect dump (INDEX.txt, r-*.ppm, d-*.pgm), created (required)");
  flags.Add("--max-frames", &max_frames, "N", "at most N colour and N depth frames (0: all)");
  flags.AddPositive("--fps", &options.fps, "F", "frame rate of sources without time stamps");
  if (!flags.Parse(argc, argv)) return 0;
  if (!flags.Given("SOURCE") || !flags.Given("OUT_DIR")) {
    throw UsageError("usage: fakenect_dump SOURCE OUT_DIR [--max-frames N] [--fps F]");
  }
  std::unique_ptr<dataset::Source> source = replay::OpenSource(source_path, options);
  const fs::path out_dir = out_path;
  fs::create_directories(out_dir);
  std::ofstream index(out_dir / "INDEX.txt", std::ios::trunc);
  const capture::KinectDepthModel& model = capture::KinectDepthModel::Default();
  uint64_t colour_frames = 0;
  uint64_t depth_frames = 0;
  std::vector<uint8_t> rgb(640 * 480 * 3);
  std::vector<uint16_t> raw(640 * 480);
  while (std::optional<dataset::StreamMessage> m = source->Next()) {
    const dataset::TopicInfo& topic = source->topics()[m->topic_index];
    if (topic.type_name != msgs::Image::kTypeName) continue;
    msgs::ReadView<msgs::Image> image = msgs::ReadMessage<msgs::Image>(m->message.bytes());
    const msgs::Image& im = *image;
    const bool is_depth = im.encoding == msgs::Encoding::kDepth16;
    if (is_depth ? (max_frames && depth_frames >= max_frames)
                 : (max_frames && colour_frames >= max_frames)) {
      if (max_frames && depth_frames >= max_frames && colour_frames >= max_frames) break;
      continue;
    }
    if (im.width != 640 || im.height != 480) {
      throw UsageError("'" + source_path + "' topic " + topic.topic + " has " +
                       std::to_string(im.width) + "x" + std::to_string(im.height) +
                       " images: fakenect needs 640x480");
    }
    const double t = static_cast<double>(m->log_time_ns) / 1e9;
    const uint32_t device_ts = static_cast<uint32_t>(m->log_time_ns / 1000 * 60);  // 60 MHz
    char name[96];
    if (is_depth) {
      for (uint32_t y = 0; y < 480; ++y) {
        const std::span<const uint16_t> row = msgs::ImageRow<uint16_t>(im, image.payload, y);
        for (uint32_t x = 0; x < 640; ++x) raw[y * 640 + x] = model.ToRaw(row[x]);
      }
      std::snprintf(name, sizeof(name), "d-%.6f-%010u.pgm", t, device_ts);
      WriteFile(out_dir / name, "P5 640 480 65535\n", raw.data(), raw.size() * 2);
      ++depth_frames;
    } else {
      for (uint32_t y = 0; y < 480; ++y) {
        const std::span<const uint8_t> row = msgs::ImageRow<uint8_t>(im, image.payload, y);
        for (uint32_t x = 0; x < 640; ++x) {
          uint8_t* p = &rgb[(y * 640 + x) * 3];
          if (im.encoding == msgs::Encoding::kRgb8) {
            p[0] = row[x * 3], p[1] = row[x * 3 + 1], p[2] = row[x * 3 + 2];
          } else if (im.encoding == msgs::Encoding::kBgr8) {
            p[0] = row[x * 3 + 2], p[1] = row[x * 3 + 1], p[2] = row[x * 3];
          } else if (im.encoding == msgs::Encoding::kMono8) {
            p[0] = p[1] = p[2] = row[x];
          } else {
            throw UsageError("'" + source_path + "' topic " + topic.topic + " has " +
                             std::string(msgs::EncodingName(im.encoding)) +
                             " images: expected rgb8, bgr8, mono8 or depth16");
          }
        }
      }
      std::snprintf(name, sizeof(name), "r-%.6f-%010u.ppm", t, device_ts);
      WriteFile(out_dir / name, "P6 640 480 255\n", rgb.data(), rgb.size());
      ++colour_frames;
    }
    index << name << "\n";
  }
  index.close();
  if (colour_frames + depth_frames == 0) {
    throw UsageError("'" + source_path + "' has no images");
  }
  std::printf("fakenect_dump: wrote %llu RGB and %llu depth frames to %s\n",
              static_cast<unsigned long long>(colour_frames),
              static_cast<unsigned long long>(depth_frames), out_dir.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("fakenect_dump", [&] { return Run(argc, argv); });
}
