// Fusion's map across a restart: a pipeline resumed from another's Checkpoint() holds the same
// map (its own checkpoint is byte-identical), relocalises on its first frame and tracks on like
// the uninterrupted pipeline; a broken or foreign checkpoint gives one line and an empty
// pipeline; the files are written atomically, on a thread, and removed on Discard.
#include "probeless/recon/checkpoint.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "probeless/recon/pipeline.h"
#include "probeless/testing/expect.h"
#include "src/byte_io.h"
#include "test_scene.h"

namespace probeless::recon {
namespace {

using testing::PoseFrom;

constexpr int64_t kStart = 1'000'000'000LL, kStep = 33'333'333LL;  // 30 fps stamps, ns

Pose Truth(int i) { return PoseFrom(0, 0.0035 * i, 0, 0.005 * i, 0, 0); }

// Frame i of the corner scene with Kinect-like noise (fixed seed per frame).
DepthImage Frame(int i) {
  static const testing::Scene scene = testing::CornerScene();
  DepthImage depth = scene.Render(Truth(i), testing::TestIntrinsics());
  std::mt19937 rng(100 + i);
  std::normal_distribution<float> unit(0.0f, 1.0f);
  for (float& z : depth.data) {
    if (z > 0) z += (0.0012f + 0.0019f * (z - 0.4f) * (z - 0.4f)) * unit(rng);
  }
  return depth;
}

FusionOptions Options() {
  FusionOptions o;
  o.merge_enabled = false;
  o.volume = testing::TestVolumeOptions();
  return o;
}

double Distance(const Pose& a, const Pose& b) {
  const double d[3] = {a.t[0] - b.t[0], a.t[1] - b.t[1], a.t[2] - b.t[2]};
  return std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
}

TEST(Checkpoint, ResumedPipelineHasTheSameMapRelocalisesAndTracksLikeTheUninterrupted) {
  const Intrinsics k = testing::TestIntrinsics();
  constexpr int kFrames = 24, kSaved = 12, kResumed = 15;  // frames 13, 14 never reach the resumed
  FusionPipeline uninterrupted(Options());
  std::vector<Pose> poses;
  std::vector<std::byte> saved;
  for (int i = 0; i < kFrames; ++i) {
    const FrameResult r = uninterrupted.Process(Frame(i), k, nullptr, nullptr, kStart + i * kStep);
    ASSERT_EQ(r.state, TrackingState::kTracking) << "frame " << i;
    poses.push_back(r.camera_to_world);
    if (i == kSaved) saved = uninterrupted.Checkpoint();
  }
  ASSERT_FALSE(saved.empty());

  FusionPipeline resumed(Options());
  resumed.Resume(saved, "map.ckpt");
  EXPECT_EQ(resumed.state(), TrackingState::kLost);
  EXPECT_EQ(resumed.Checkpoint(), saved);  // the same volume, pose and monitor, bit for bit
  EXPECT_GT(resumed.volume().ObservedBricks(), 100);
  for (int i = kResumed; i < kFrames; ++i) {
    const FrameResult r = resumed.Process(Frame(i), k, nullptr, nullptr, kStart + i * kStep);
    SCOPED_TRACE("frame " + std::to_string(i));
    ASSERT_EQ(r.state, TrackingState::kTracking) << r.quality.text << " " << r.icp.failure;
    EXPECT_EQ(r.relocalised, i == kResumed);
    EXPECT_TRUE(r.integrated);
    EXPECT_LT(Distance(r.camera_to_world, poses[i]), 0.003);
    EXPECT_LT((r.camera_to_world.Inverse() * poses[i]).RotationAngle(), 0.3 * M_PI / 180);
    EXPECT_LT(Distance(r.camera_to_world, Truth(i)), 0.01);
  }

  // Without the checkpoint a process started at frame 15 begins a new map at the initial pose.
  FusionPipeline fresh(Options());
  const FrameResult r = fresh.Process(Frame(kResumed), k, nullptr, nullptr, kStart);
  EXPECT_GT(Distance(r.camera_to_world, Truth(kResumed)), 0.07);
}

TEST(Checkpoint, NothingToSaveBeforeTheFirstFrameAndAfterReset) {
  FusionPipeline pipeline(Options());
  EXPECT_TRUE(pipeline.Checkpoint().empty());
  pipeline.Process(Frame(0), testing::TestIntrinsics(), nullptr);
  EXPECT_FALSE(pipeline.Checkpoint().empty());
  pipeline.Reset();
  EXPECT_TRUE(pipeline.Checkpoint().empty());
}

// `bytes` with a fresh checksum after an edit of its body.
std::vector<std::byte> Resealed(std::vector<std::byte> bytes) {
  const uint64_t sum = detail::Checksum(std::span(bytes).first(bytes.size() - 8));
  std::memcpy(bytes.data() + bytes.size() - 8, &sum, 8);
  return bytes;
}

TEST(Checkpoint, BrokenOrForeignCheckpointsGiveOneLineAndAnEmptyPipeline) {
  FusionPipeline source(Options());
  source.Process(Frame(0), testing::TestIntrinsics(), nullptr, nullptr, kStart);
  const std::vector<std::byte> good = source.Checkpoint();
  FusionPipeline p(Options());
  auto resume = [&](const std::vector<std::byte>& bytes) {
    return probeless::testing::ThrownMessage<ReconError>([&] { p.Resume(bytes, "map.ckpt"); });
  };
  std::vector<std::byte> text(40, std::byte{'x'});
  EXPECT_EQ(resume(text), "map.ckpt: not a fusion checkpoint (expected it to start with PLFUSMAP)");
  EXPECT_EQ(resume(std::vector<std::byte>(good.begin(), good.begin() + 18)),
            "map.ckpt: truncated at byte 18 (expected 6 more)");
  EXPECT_EQ(resume(std::vector<std::byte>(good.begin(), good.begin() + good.size() / 2)),
            "map.ckpt: checksum mismatch (the file is corrupt or truncated)");
  std::vector<std::byte> flipped = good;
  flipped[good.size() / 2] ^= std::byte{0x10};
  EXPECT_EQ(resume(flipped), "map.ckpt: checksum mismatch (the file is corrupt or truncated)");
  std::vector<std::byte> version = good;
  version[8] = std::byte{2};
  EXPECT_EQ(resume(version), "map.ckpt: checkpoint version 2, expected 1");
  std::vector<std::byte> order = good;
  std::swap(order[12], order[15]);
  EXPECT_EQ(resume(order), "map.ckpt: written on a machine of another byte order");
  // A voxel out of range behind a valid checksum: the first brick's first TSDF value (header 16 +
  // volume 28 + pose 96 + 16 + monitor 61 bytes, brick count 4, brick index 4).
  std::vector<std::byte> voxel = good;
  const size_t first_tsdf = 16 + 28 + 96 + 16 + 61 + 4 + 4;
  uint32_t brick;
  std::memcpy(&brick, voxel.data() + first_tsdf - 4, 4);
  const float bad = 1.5f;
  std::memcpy(voxel.data() + first_tsdf, &bad, 4);
  EXPECT_EQ(resume(Resealed(voxel)),
            "map.ckpt: brick " + std::to_string(brick) + " voxel 0 has weight " +
                std::to_string(static_cast<int>(voxel[first_tsdf + 2048])) + " and tsdf " +
                std::to_string(bad) +
                " (expected weight <= max_weight 64 and tsdf in [-1, 1], or weight 0 unobserved)");
  std::vector<std::byte> extra = good;
  extra.insert(extra.end() - 8, std::byte{0});
  EXPECT_EQ(resume(Resealed(extra)), "map.ckpt: 1 bytes after the last brick");
  EXPECT_EQ(p.state(), TrackingState::kEmpty);
  EXPECT_EQ(p.volume().ObservedBricks(), 0);

  FusionOptions other = Options();
  other.volume.resolution = 128;
  FusionPipeline coarse(other);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      coarse.Resume(good, "map.ckpt"), ReconError,
      "map.ckpt: written for volume resolution 256, the pipeline has 128");
  other = Options();
  other.volume.origin.z = 0.5f;
  FusionPipeline moved(other);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      moved.Resume(good, "map.ckpt"), ReconError,
      "map.ckpt: written for volume origin (-1.000000, -1.000000, 0.200000), the pipeline "
      "has (-1.000000, -1.000000, 0.500000)");
  // The good one still resumes.
  EXPECT_EQ(resume(good), "(no error)");
  EXPECT_EQ(p.Checkpoint(), good);
}

TEST(Checkpoint, FilesAreWrittenAtomicallyOnAThreadAndRemovedOnDiscard) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("probeless_checkpoint_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "map.ckpt").string();
  EXPECT_FALSE(ReadFileIfExists(path).has_value());
  const std::vector<std::byte> a(1000, std::byte{1}), b(3000, std::byte{2});
  WriteFileAtomically(path, a);
  EXPECT_EQ(*ReadFileIfExists(path), a);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  {
    CheckpointWriter writer(path);
    writer.Submit(b);
    writer.Flush();
    EXPECT_EQ(*ReadFileIfExists(path), b);
    EXPECT_EQ(writer.written(), 1u);
    writer.Submit(a);  // written by the destructor at the latest
  }
  EXPECT_EQ(*ReadFileIfExists(path), a);
  {
    CheckpointWriter writer(path);
    writer.Submit(b);
    writer.Discard();
    EXPECT_FALSE(std::filesystem::exists(path));
    writer.Flush();
  }
  EXPECT_FALSE(std::filesystem::exists(path));
  PROBELESS_EXPECT_THROWS_MESSAGE(ReadFileIfExists(dir.string()), ReconError,
                                  "checkpoint '" + dir.string() + "': cannot read: Is a directory");
  // A write that fails is reported by the next call.
  const std::string missing = (dir / "no" / "map.ckpt").string();
  CheckpointWriter writer(missing);
  writer.Submit(a);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      writer.Flush(), ReconError,
      "checkpoint '" + missing + "': cannot create " + missing + ".tmp: No such file or directory");
  EXPECT_NO_THROW(writer.Flush());  // reported once
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace probeless::recon
