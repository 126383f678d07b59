// The message readers under fixed-seed mutations of valid messages of every type: bit flips,
// header words set to boundary values, truncation and extension (msgs_reader_check.h). Runs in
// every test build and in the address/undefined sanitizer build (label sanitize), where a read
// past a sample's end or an overflow in a size computation is caught; libFuzzer cannot compile
// these headers with Debian's clang 14 (tests/fuzz/CMakeLists.txt).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <vector>

#include "msgs_reader_check.h"

namespace probeless::fuzz {
namespace {

constexpr const char* kKindNames[kMessageKinds] = {"image",
                                                   "camera_info",
                                                   "geometry_buffer",
                                                   "transfer_buffer",
                                                   "auxiliary_views",
                                                   "sh_light",
                                                   "face_observation",
                                                   "tracking_status",
                                                   "ack"};

struct Seed {
  uint8_t kind;
  std::vector<uint8_t> bytes;
};

template <class M>
std::vector<uint8_t> Bytes(size_t size, const std::function<void(M&, std::byte*)>& fill) {
  std::vector<uint8_t> zeros(size, 0);
  AlignedSample buffer(zeros.data(), size);  // 64-byte aligned, as the bus's slots
  auto view = msgs::WriteMessage<M>(buffer.mutable_bytes());
  fill(*view, view.payload.data());
  std::vector<uint8_t> out(size);
  std::memcpy(out.data(), buffer.bytes().data(), size);
  return out;
}

// One valid message of each kind (ReadAsMessage accepts each: checked below).
std::vector<Seed> ValidSeeds() {
  using namespace msgs;
  std::vector<Seed> seeds;
  seeds.push_back(
      {0, Bytes<Image>(Image::MessageBytesFor(7, 5, Encoding::kRgb8), [](Image& m, std::byte*) {
         m.Init(7, 5, Encoding::kRgb8);
         m.header.SetFrameId("camera");
       })});
  seeds.push_back({0, Bytes<Image>(sizeof(Image) + 3 * 16, [](Image& m, std::byte*) {
                     m.Init(5, 3, Encoding::kDepth16);
                     m.step = 16;  // padded rows
                   })});
  seeds.push_back(
      {0, Bytes<Image>(Image::MessageBytesFor(4, 4, Encoding::kFloat32),
                       [](Image& m, std::byte*) { m.Init(4, 4, Encoding::kFloat32); })});
  seeds.push_back({1, Bytes<CameraInfo>(sizeof(CameraInfo), [](CameraInfo& m, std::byte*) {
                     m.width = 640;
                     m.height = 480;
                     m.fx = m.fy = 525;
                     m.cx = 319.5;
                     m.cy = 239.5;
                     m.distortion_model = DistortionModel::kPlumbBob;
                     m.distortion_count = DistortionCoefficientCount(DistortionModel::kPlumbBob);
                     m.depth_scale = 0.001;
                   })});
  seeds.push_back({2, Bytes<GeometryBuffer>(GeometryBuffer::MessageBytesFor(6, 4),
                                            [](GeometryBuffer& m, std::byte*) { m.Init(6, 4); })});
  seeds.push_back(
      {3, Bytes<TransferBuffer>(TransferBuffer::MessageBytesFor(5, 3, 9),
                                [](TransferBuffer& m, std::byte*) { m.Init(5, 3, 9); })});
  seeds.push_back({4, Bytes<AuxiliaryViews>(AuxiliaryViews::MessageBytesFor(2, 3, 2),
                                            [](AuxiliaryViews& m, std::byte*) {
                                              m.view_count = 2;
                                              for (uint32_t i = 0; i < 2; ++i) {
                                                AuxiliaryView& v = m.views[i];
                                                v.role = i ? AuxiliaryViewRole::kRight
                                                           : AuxiliaryViewRole::kLeft;
                                                v.width = 3;
                                                v.height = 2;
                                                v.pixel_size_m = 0.01f;
                                                v.rotation[0] = v.rotation[4] = v.rotation[8] = 1;
                                              }
                                              m.SetStandardLayout();
                                            })});
  seeds.push_back({5, Bytes<ShLight>(sizeof(ShLight), [](ShLight& m, std::byte*) {
                     m.bands = 3;
                     m.units = ShLightUnits::kLinear;
                     m.confidence = 0.5f;
                   })});
  seeds.push_back(
      {6, Bytes<FaceObservation>(sizeof(FaceObservation), [](FaceObservation& m, std::byte*) {})});
  seeds.push_back(
      {7, Bytes<TrackingStatus>(sizeof(TrackingStatus), [](TrackingStatus& m, std::byte*) {
         m.state = TrackingStatusState::kTracked;
         m.score = 1;
       })});
  seeds.push_back({8, Bytes<Ack>(sizeof(Ack), [](Ack& m, std::byte*) {})});
  return seeds;
}

bool Accepted(const Seed& seed) {
  const AlignedSample sample(seed.bytes.data(), seed.bytes.size());
  try {
    ReadAsMessage(seed.kind, sample.bytes());
    return true;
  } catch (const msgs::MessageError& e) {
    EXPECT_EQ(std::strchr(e.what(), '\n'), nullptr) << e.what();
    return false;
  }
}

// With $PROBELESS_WRITE_MSGS_SEEDS=DIR also writes each seed as msgs_reader_fuzz's input (the
// kind byte, then the sample): how tests/fuzz/corpus/msgs_reader was made.
TEST(MsgsReaderMutation, EveryValidSeedIsAccepted) {
  const char* out = std::getenv("PROBELESS_WRITE_MSGS_SEEDS");
  int n = 0;
  for (const Seed& seed : ValidSeeds()) {
    EXPECT_TRUE(Accepted(seed)) << "kind " << int(seed.kind);
    if (out == nullptr) continue;
    std::ofstream file(
        std::string(out) + "/" + kKindNames[seed.kind % kMessageKinds] + "_" + std::to_string(n++),
        std::ios::binary);
    file.put(static_cast<char>(seed.kind));
    file.write(reinterpret_cast<const char*>(seed.bytes.data()),
               static_cast<std::streamsize>(seed.bytes.size()));
  }
}

TEST(MsgsReaderMutation, MutatedMessagesAreAcceptedWithinTheirBoundsOrRejectedWithOneLine) {
  const std::vector<Seed> seeds = ValidSeeds();
  std::mt19937_64 rng(20261204);
  const uint32_t kBoundary[] = {0u,    1u,    2u,          3u,          63u,         64u,
                                4096u, 4097u, 0x7fffffffu, 0x80000000u, 0xfffffff0u, 0xffffffffu};
  int accepted = 0, rejected = 0;
  for (int iteration = 0; iteration < 30000; ++iteration) {
    Seed m = seeds[rng() % seeds.size()];
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits; ++e) {
      const uint64_t what = rng() % 4;
      if (what == 0 && !m.bytes.empty()) {  // a bit flip anywhere
        m.bytes[rng() % m.bytes.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
      } else if (what == 1 && m.bytes.size() >= 4) {  // a 32-bit field of the struct at a boundary
        const size_t fields = std::min<size_t>(m.bytes.size(), 448) / 4;
        const uint32_t v = kBoundary[rng() % std::size(kBoundary)];
        std::memcpy(&m.bytes[4 * (rng() % fields)], &v, 4);
      } else if (what == 2 && !m.bytes.empty()) {  // truncated
        m.bytes.resize(rng() % m.bytes.size());
      } else {  // extended by random bytes
        const size_t more = rng() % 256;
        for (size_t i = 0; i < more; ++i) m.bytes.push_back(static_cast<uint8_t>(rng()));
      }
    }
    (Accepted(m) ? accepted : rejected)++;
  }
  // Both outcomes occur: the mutations reach past the first check and some stay valid.
  EXPECT_GT(accepted, 1000);
  EXPECT_GT(rejected, 1000);
  std::printf("30000 mutations: %d accepted, %d rejected\n", accepted, rejected);
}

}  // namespace
}  // namespace probeless::fuzz
