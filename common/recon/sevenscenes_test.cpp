// Tracking on the first 50 shared 7-Scenes RedKitchen frames stays within 3 cm of the ground
// truth (after aligning the first pose). Skipped with a message when the data is absent.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "probeless/dataset/datasets.h"
#include "probeless/msgs/msgs.h"
#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"

namespace probeless::recon {
namespace {

std::string DataDir() {
  if (const char* env = std::getenv("PROBELESS_DATA"))
    return std::string(env) + "/7scenes-redkitchen";
  return std::string(PROBELESS_DATA_DIR) + "/7scenes-redkitchen";
}

TEST(SevenScenes, First50FramesTrackWithin3cm) {
  const std::string dir = DataDir();
  if (!std::filesystem::exists(dir)) {
    GTEST_SKIP() << "shared 7-Scenes data not found at " << dir
                 << " (set PROBELESS_DATA to the folder holding 7scenes-redkitchen)";
  }
  dataset::DatasetOptions options;
  options.max_frames = 50;
  auto source = dataset::OpenDataset("7scenes:" + dir, options);
  FusionOptions fusion;
  fusion.merge_enabled = false;
  FusionPipeline pipeline(fusion);
  Intrinsics k;
  bool have_k = false;
  std::vector<Pose> truth;
  std::vector<Pose> estimate;
  int lost = 0;
  while (auto m = source->Next()) {
    const std::string& topic = source->topics()[m->topic_index].topic;
    if (topic == "/camera/camera_info") {
      k = IntrinsicsFromCameraInfo(
          *reinterpret_cast<const msgs::CameraInfo*>(m->message.bytes().data()));
      have_k = true;
    } else if (topic == "/groundtruth/pose") {
      truth.push_back(
          Pose::FromMsg(reinterpret_cast<const msgs::Pose*>(m->message.bytes().data())->transform));
    } else if (topic == "/camera/depth" && have_k) {
      const auto* image = reinterpret_cast<const msgs::Image*>(m->message.bytes().data());
      DepthImage depth;
      DepthFromImage(*image, m->message.bytes().subspan(sizeof(msgs::Image)), 0.001, 0.3f, 4.0f,
                     depth);
      const FrameResult r = pipeline.Process(depth, k, nullptr);
      lost += r.state == TrackingState::kLost;
      estimate.push_back(r.camera_to_world);
    }
  }
  ASSERT_EQ(estimate.size(), 50u);
  ASSERT_EQ(truth.size(), 50u);
  EXPECT_EQ(lost, 0);
  double worst = 0, sum2 = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    const Pose aligned = truth[0] * estimate[i];
    const double dx = aligned.t[0] - truth[i].t[0], dy = aligned.t[1] - truth[i].t[1],
                 dz = aligned.t[2] - truth[i].t[2];
    const double e = std::sqrt(dx * dx + dy * dy + dz * dz);
    worst = std::max(worst, e);
    sum2 += e * e;
  }
  std::printf("7-Scenes first 50 frames: ATE RMSE %.4f m, worst %.4f m\n",
              std::sqrt(sum2 / estimate.size()), worst);
  EXPECT_LT(worst, 0.03);
}

}  // namespace
}  // namespace probeless::recon
