// launch/scene_light_sim.yaml with 3 frames of data/scenarios/courtyard_sun.yaml: the sim
// in lock-step with scene_light (depth mode, normals from the sensor depth); one /scene/light and
// one /scene/transfer per frame, paired with /groundtruth/light by header.sequence, plausible
// (valid bands, unit direction, confidence in [0, 1], transfer 640x480x16); with indirect:=true
// one /scene/indirect (rgb32f 640x480, finite, non-negative, lit somewhere) for every frame after
// the first (it needs the previous frame's light); plus the node's one-line error for a bad mode.
// launch/scene_light.yaml with aux:=true on the same scenario: player (lock-step) -> fusion
// (publish_aux) -> scene_light (use_aux): every frame gets 3 auxiliary views of 128 x 128 with its
// G_r's stamp and scene_light uses them; auxiliary views of the wrong type on /scene/aux stop
// scene_light with one line, a malformed one is one error line and the frame runs without views;
// with temporal_frames the temporal fit gets every frame's camera rotation from fusion's pose.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"

namespace {

using namespace probeless;
using namespace std::chrono_literals;

TEST(SceneLightLaunch, SimInLockStepWithSceneLight) {
  bus::Subscriber lights("/scene/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 64});
  bus::Subscriber truths("/groundtruth/light", msgs::TopicTypeOf<msgs::ShLight>(),
                         {.queue_depth = 64});
  bus::Subscriber transfers("/scene/transfer", msgs::TopicTypeOf<msgs::TransferBuffer>(),
                            {.queue_depth = 8});
  bus::Subscriber indirects("/scene/indirect", msgs::TopicTypeOf<msgs::Image>(),
                            {.queue_depth = 8});
  struct IndirectStats {
    uint32_t width = 0, height = 0;
    msgs::Encoding encoding = msgs::Encoding::kInvalid;
    size_t non_finite = 0, negative = 0, lit = 0;
  };
  std::map<uint64_t, IndirectStats> indirect;
  std::map<uint64_t, msgs::ShLight> estimated, truth;
  std::map<uint64_t, std::array<uint32_t, 3>> transfer_shape;
  std::atomic<bool> stop{false};
  std::thread drain([&] {
    while (!stop) {
      bool any = false;
      while (auto s = lights.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::ShLight>(s->data());
        estimated[m->header.sequence] = *m;
        any = true;
      }
      while (auto s = truths.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::ShLight>(s->data());
        truth[m->header.sequence] = *m;
        any = true;
      }
      while (auto s = transfers.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::TransferBuffer>(s->data());
        m->Validate(m.payload.size());
        transfer_shape[m->header.sequence] = {m->width, m->height, m->coefficient_count};
        any = true;
      }
      while (auto s = indirects.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::Image>(s->data());
        IndirectStats st{m->width, m->height, m->encoding};
        if (m->encoding == msgs::Encoding::kRgb32f) {
          for (float v : msgs::ImageChannels<float>(*m, m.payload)) {
            st.non_finite += !std::isfinite(v);
            st.negative += v < 0;
            st.lit += v > 1e-6f;
          }
        }
        indirect[m->header.sequence] = st;
        any = true;
      }
      if (!any) std::this_thread::sleep_for(1ms);
    }
  });
  const std::string err = "/tmp/scene_light_launch_test_" + std::to_string(getpid()) + ".txt";
  const std::string command =
      std::string(PROBELESS_BIN_DIR) + "/probeless launch " + PROBELESS_SOURCE_DIR +
      "/launch/scene_light_sim.yaml frames:=3 " + "scenario:=" + PROBELESS_SOURCE_DIR +
      "/data/scenarios/courtyard_sun.yaml indirect:=true < /dev/null > /dev/null 2> " + err;
  const int status = std::system(command.c_str());
  std::this_thread::sleep_for(300ms);
  stop = true;
  drain.join();
  std::string log;
  if (FILE* f = std::fopen(err.c_str(), "r")) {
    char buf[4096];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) log.append(buf, n);
    std::fclose(f);
  }
  std::remove(err.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log;
  EXPECT_EQ(truth.size(), 3u) << log;
  ASSERT_EQ(estimated.size(), 3u) << log;
  // Both say they are linear radiance in the camera's units (msgs::ShLight::units).
  for (const auto& [sequence, light] : estimated) {
    EXPECT_EQ(light.units, msgs::ShLightUnits::kLinear) << sequence;
  }
  for (const auto& [sequence, light] : truth) {
    EXPECT_EQ(light.units, msgs::ShLightUnits::kLinear) << sequence;
  }
  EXPECT_EQ(transfer_shape.size(), 3u);
  ASSERT_EQ(indirect.size(), 2u) << log;  // frames 2 and 3: frame 1 has no previous light
  EXPECT_FALSE(indirect.count(estimated.begin()->first));
  for (const auto& [seq, st] : indirect) {
    EXPECT_EQ(st.encoding, msgs::Encoding::kRgb32f) << "frame " << seq;
    EXPECT_EQ(st.width, 640u);
    EXPECT_EQ(st.height, 480u);
    EXPECT_EQ(st.non_finite, 0u) << "frame " << seq;
    EXPECT_EQ(st.negative, 0u) << "frame " << seq;
    // Courtyard: the sunlit ground and walls bounce light into the corners and under the table.
    EXPECT_GT(st.lit, 640u * 480u * 3 / 100) << "frame " << seq;
  }
  for (const auto& [seq, e] : estimated) {
    ASSERT_TRUE(truth.count(seq)) << "no ground truth for frame " << seq;
    EXPECT_EQ(e.bands, 4u);
    EXPECT_GE(e.confidence, 0.0f);
    EXPECT_LE(e.confidence, 1.0f);
    const float* d = e.dominant_direction;
    EXPECT_NEAR(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), 1.0, 1e-4);
    const float* t = truth[seq].dominant_direction;
    const double angle =
        std::acos(std::clamp(d[0] * t[0] + d[1] * t[1] + d[2] * t[2], -1.0f, 1.0f)) * 180 / M_PI;
    std::printf("frame %llu: dominant direction error %.1f deg (sensor depth)\n",
                static_cast<unsigned long long>(seq), angle);
    EXPECT_LT(angle, 60.0) << "frame " << seq;  // with sensor noise; docs/light.md
    const auto shape = transfer_shape[seq];
    EXPECT_EQ(shape[0], 640u);
    EXPECT_EQ(shape[1], 480u);
    EXPECT_EQ(shape[2], 16u);
  }
}

// Runs scene_light with `params` (ros-args) and returns its exit status and stderr.
std::pair<int, std::string> RunSceneLight(const std::string& params) {
  const std::string err = "/tmp/scene_light_params_" + std::to_string(getpid()) + ".txt";
  const std::string command = std::string(PROBELESS_BIN_DIR) + "/scene_light --ros-args " + params +
                              " < /dev/null 2> " + err;
  const int status = std::system(command.c_str());
  std::string log;
  if (FILE* f = std::fopen(err.c_str(), "r")) {
    char buf[1024];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) log.append(buf, n);
    std::fclose(f);
  }
  std::remove(err.c_str());
  return {status, log};
}

TEST(SceneLightLaunch, BadModeIsAOneLineError) {
  const auto [status, log] = RunSceneLight("-p mode:=lidar");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2);
  EXPECT_EQ(log,
            "[error] [scene_light] node '/scene_light': parameter 'mode' = \"lidar\" (from -p) is "
            "not one of gbuffer|depth\n");
  const auto [status2, log2] = RunSceneLight("-p gbuffer_normals:=volume");
  EXPECT_TRUE(WIFEXITED(status2) && WEXITSTATUS(status2) == 2);
  EXPECT_EQ(log2,
            "[error] [scene_light] node '/scene_light': parameter 'gbuffer_normals' = \"volume\" "
            "(from -p) is not one of fusion|depth\n");
  const auto [status3, log3] = RunSceneLight("-p shadow_depth:=tsdf");
  EXPECT_TRUE(WIFEXITED(status3) && WEXITSTATUS(status3) == 2);
  EXPECT_EQ(log3,
            "[error] [scene_light] node '/scene_light': parameter 'shadow_depth' = \"tsdf\" (from "
            "-p) is not one of raw|gbuffer\n");
  const auto [status4, log4] = RunSceneLight("-p max_intensity:=0.001");
  EXPECT_TRUE(WIFEXITED(status4) && WEXITSTATUS(status4) == 2);
  EXPECT_EQ(
      log4,
      "[error] [scene_light] node '/scene_light': parameter 'max_intensity' = 0.001 (from -p) "
      "is out of range: expected a value in (0.004, inf) linear grey\n");
  const auto [status5, log5] = RunSceneLight("-p shadow_min_contrast:=0.5");
  EXPECT_TRUE(WIFEXITED(status5) && WEXITSTATUS(status5) == 2);
  EXPECT_EQ(
      log5,
      "[error] [scene_light] node '/scene_light': parameter 'shadow_min_contrast' = 0.5 (from "
      "-p) is out of range: expected a value in [1, inf)\n");
  const auto [status6, log6] = RunSceneLight("-p bandz:=3");
  EXPECT_TRUE(WIFEXITED(status6) && WEXITSTATUS(status6) == 2);
  EXPECT_EQ(log6,
            "[error] [scene_light] node '/scene_light': unknown parameter 'bandz' (from -p); did "
            "you mean 'bands'?\n");
}

std::string ReadFile(const std::string& path) {
  std::string text;
  if (FILE* f = std::fopen(path.c_str(), "r")) {
    char buf[4096];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
    std::fclose(f);
  }
  return text;
}

struct AuxInfo {
  uint32_t count = 0;
  std::vector<std::array<uint32_t, 3>> views;  // role, width, height
  size_t with_depth = 0;                       // pixels with a surface over all views
  std::string error;
};

// launch/scene_light.yaml with aux:=true (and `extra` args) on 3 courtyard frames: the views on
// /scene/aux by stamp, the stamps of /scene/light and the launch's stderr.
void RunAuxLaunch(const std::string& extra, std::map<int64_t, AuxInfo>* aux,
                  std::set<int64_t>* light_stamps, std::string* log) {
  bus::Subscriber lights("/scene/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 64});
  bus::Subscriber auxes("/scene/aux", msgs::TopicTypeOf<msgs::AuxiliaryViews>(),
                        {.queue_depth = 16});
  std::atomic<bool> stop{false};
  std::thread drain([&] {
    while (!stop) {
      bool any = false;
      while (auto s = lights.TryTake()) {
        light_stamps->insert(msgs::ReadMessage<msgs::ShLight>(s->data())->header.stamp_ns);
        any = true;
      }
      while (auto s = auxes.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::AuxiliaryViews>(s->data());
        AuxInfo a;
        a.count = m->view_count;
        try {
          for (uint32_t i = 0; i < m->view_count; ++i) {
            const auto& v = m->views[i];
            a.views.push_back({static_cast<uint32_t>(v.role), v.width, v.height});
            for (float d : msgs::AuxiliaryDepth(*m, m.payload, i)) a.with_depth += d > 0;
          }
        } catch (const msgs::MessageError& e) {
          a.error = e.what();
        }
        (*aux)[m->header.stamp_ns] = a;
        any = true;
      }
      if (!any) std::this_thread::sleep_for(1ms);
    }
  });
  const std::string err = "/tmp/scene_light_aux_launch_" + std::to_string(getpid()) + ".txt";
  // The courtyard needs the demo's 6 m volume (the default 2 m cube loses tracking there).
  const std::string command =
      std::string(PROBELESS_BIN_DIR) + "/probeless launch " + PROBELESS_SOURCE_DIR +
      "/launch/scene_light.yaml max_frames:=3 log:=sim:" + PROBELESS_SOURCE_DIR +
      "/data/scenarios/courtyard_sun.yaml aux:=true volume_size:=6.0 'volume_origin:=[-3.0, "
      "-3.0, 0.3]' truncation:=0.08 depth_max:=6.0 " +
      extra + " < /dev/null > /dev/null 2> " + err;
  const int status = std::system(command.c_str());
  std::this_thread::sleep_for(300ms);
  stop = true;
  drain.join();
  *log = ReadFile(err);
  std::remove(err.c_str());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << *log;
}

TEST(SceneLightLaunch, FusionAuxiliaryViewsReachSceneLight) {
  std::map<int64_t, AuxInfo> aux;
  std::set<int64_t> light_stamps;
  std::string log;
  // The courtyard's clear sun: the shadow search on (its geometry is checked below).
  RunAuxLaunch("shadows:=true", &aux, &light_stamps, &log);
  EXPECT_EQ(light_stamps.size(), 3u) << log;
  ASSERT_EQ(aux.size(), 3u) << log;
  for (const auto& [stamp, a] : aux) {
    EXPECT_TRUE(light_stamps.count(stamp)) << "views of stamp " << stamp << " match no light";
    EXPECT_EQ(a.error, "");
    ASSERT_EQ(a.count, 3u);
    ASSERT_EQ(a.views.size(), 3u);
    for (uint32_t i = 0; i < 3; ++i) {
      EXPECT_EQ(a.views[i][0], i + 1);  // left, right, top
      EXPECT_EQ(a.views[i][1], 128u);
      EXPECT_EQ(a.views[i][2], 128u);
    }
    EXPECT_GT(a.with_depth, 1000u) << "the views see the fused courtyard";
  }
  EXPECT_NE(log.find("auxiliary views: used for 3 frames, missing for 0, malformed for 0"),
            std::string::npos)
      << log;
  // shadow_depth raw (default): every G_r found the camera/depth image of its stamp.
  EXPECT_NE(log.find("shadow search on the frame's depth image for 3 frames, on G_r for 0"),
            std::string::npos)
      << log;
}

TEST(SceneLightLaunch, TemporalFitIsRotatedByFusionsPoses) {
  std::map<int64_t, AuxInfo> aux;
  std::set<int64_t> light_stamps;
  std::string log;
  RunAuxLaunch("light_model:=distant temporal_frames:=3", &aux, &light_stamps, &log);
  EXPECT_EQ(light_stamps.size(), 3u) << log;
  // Fusion publishes each frame's pose before its G_r: every frame finds its own.
  EXPECT_NE(
      log.find("temporal fit: rotated by scene/pose for 3 frames, no pose of their own for 0"),
      std::string::npos)
      << log;
  EXPECT_EQ(log.find("focus: used for"), std::string::npos) << log;  // no focus given
}

TEST(SceneLightLaunch, FusionAddsTheLightViewFromSceneLight) {
  // aux_light: frame 1 has no light yet (3 views); scene_light's estimate of frame 1 reaches
  // fusion before frame 2 (lock-step), so frames 2 and 3 carry the light view too.
  std::map<int64_t, AuxInfo> aux;
  std::set<int64_t> light_stamps;
  std::string log;
  RunAuxLaunch("aux_light:=true", &aux, &light_stamps, &log);
  ASSERT_EQ(aux.size(), 3u) << log;
  std::vector<uint32_t> counts;
  for (const auto& [stamp, a] : aux) counts.push_back(a.count);
  EXPECT_EQ(counts, (std::vector<uint32_t>{3, 4, 4})) << log;
  for (const auto& [stamp, a] : aux) {
    EXPECT_EQ(a.error, "");
    if (a.count == 4) {
      EXPECT_EQ(a.views[3][0], 4u);  // light
      EXPECT_EQ(a.views[3][1], 128u);
    }
  }
}

TEST(SceneLightLaunch, WrongTypeOnTheAuxTopicIsAOneLineError) {
  const bus::Publisher wrong("/scene/aux", msgs::TopicTypeOf<msgs::Image>(),
                             {.max_message_bytes = 1024});
  const auto [status, log] = RunSceneLight("-p use_aux:=true");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) != 0) << log;
  EXPECT_EQ(std::count(log.begin(), log.end(), '\n'), 1) << log;
  EXPECT_NE(log.find("probeless_msgs/AuxiliaryViews"), std::string::npos) << log;
  EXPECT_NE(log.find("probeless_msgs/Image"), std::string::npos) << log;
  const auto [status2, log2] = RunSceneLight("-p use_aux:=true -p mode:=depth");
  EXPECT_TRUE(WIFEXITED(status2) && WEXITSTATUS(status2) == 2);
  EXPECT_EQ(log2,
            "[error] [scene_light] scene_light: use_aux needs mode gbuffer (the views come from "
            "fusion)\n");
}

// Waits until `topic` has a live subscriber (the node under test is up).
bool WaitForSubscriber(const std::string& topic, std::chrono::seconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    for (const auto& t : bus::ListTopics()) {
      if (t.topic != topic) continue;
      for (const auto& s : t.subscribers) {
        if (s.alive) return true;
      }
    }
    std::this_thread::sleep_for(20ms);
  }
  return false;
}

TEST(SceneLightLaunch, MalformedAuxiliaryViewsAreAnErrorLineNotACrash) {
  constexpr uint32_t kW = 64, kH = 48;
  bus::Publisher info_pub("/camera/camera_info", msgs::TopicTypeOf<msgs::CameraInfo>(),
                          {.max_message_bytes = sizeof(msgs::CameraInfo)});
  bus::Publisher image_pub(
      "/camera/image", msgs::TopicTypeOf<msgs::Image>(),
      {.max_message_bytes = msgs::Image::MessageBytesFor(kW, kH, msgs::Encoding::kRgb8)});
  bus::Publisher gbuffer_pub("/scene/gbuffer", msgs::TopicTypeOf<msgs::GeometryBuffer>(),
                             {.max_message_bytes = msgs::GeometryBuffer::MessageBytesFor(kW, kH)});
  bus::Publisher aux_pub("/scene/aux", msgs::TopicTypeOf<msgs::AuxiliaryViews>(),
                         {.max_message_bytes = msgs::AuxiliaryViews::MessageBytesFor(3, 8, 8)});
  bus::Subscriber transfers("/scene/transfer", msgs::TopicTypeOf<msgs::TransferBuffer>(),
                            {.queue_depth = 4});
  const std::string err = "/tmp/scene_light_aux_bad_" + std::to_string(getpid()) + ".txt";
  const std::string pid_file = err + ".pid";
  const std::string command = std::string(PROBELESS_BIN_DIR) +
                              "/scene_light --ros-args -p use_aux:=true -p shadows:=false "
                              "< /dev/null 2> " +
                              err + " & echo $! > " + pid_file + "; wait";
  std::thread node([&] { std::system(command.c_str()); });
  ASSERT_TRUE(WaitForSubscriber("/scene/gbuffer", 20s));
  ASSERT_TRUE(WaitForSubscriber("/scene/aux", 5s));
  const int64_t stamp = 1'000'000'000;
  {
    bus::Loan loan = info_pub.Borrow(sizeof(msgs::CameraInfo));
    auto m = msgs::WriteMessage<msgs::CameraInfo>(loan.data());
    m->header.stamp_ns = stamp;
    m->width = kW;
    m->height = kH;
    m->fx = m->fy = 50;
    m->cx = (kW - 1) / 2.0;
    m->cy = (kH - 1) / 2.0;
    m->depth_scale = 0.001;
    info_pub.Publish(std::move(loan));
  }
  {
    bus::Loan loan = image_pub.Borrow(msgs::Image::MessageBytesFor(kW, kH, msgs::Encoding::kRgb8));
    auto m = msgs::WriteMessage<msgs::Image>(loan.data());
    m->header.stamp_ns = stamp;
    m->header.sequence = 1;
    m->Init(kW, kH, msgs::Encoding::kRgb8);
    for (uint8_t& c : msgs::ImageChannels<uint8_t>(*m, m.payload)) c = 120;
    image_pub.Publish(std::move(loan));
  }
  std::this_thread::sleep_for(200ms);
  {
    // Declares 3 views of 128 x 128 in a slot that holds 8 x 8 ones: the size does not match.
    bus::Loan loan = aux_pub.Borrow(msgs::AuxiliaryViews::MessageBytesFor(3, 8, 8));
    auto m = msgs::WriteMessage<msgs::AuxiliaryViews>(loan.data());
    m->header.stamp_ns = stamp;
    m->view_count = 3;
    for (uint32_t i = 0; i < 3; ++i) {
      auto& v = m->views[i];
      v.role = static_cast<msgs::AuxiliaryViewRole>(i + 1);
      v.width = v.height = 128;
      v.pixel_size_m = 0.03f;
      v.rotation[0] = v.rotation[4] = v.rotation[8] = 1;
    }
    m->SetStandardLayout();
    aux_pub.Publish(std::move(loan));
  }
  {
    // A floor-like plane 1 m away facing the camera.
    bus::Loan loan = gbuffer_pub.Borrow(msgs::GeometryBuffer::MessageBytesFor(kW, kH));
    auto m = msgs::WriteMessage<msgs::GeometryBuffer>(loan.data());
    m->header.stamp_ns = stamp;
    m->header.sequence = 1;
    m->Init(kW, kH);
    for (float& d : msgs::DepthPlane(*m, m.payload)) d = 1.0f;
    const std::span<float> n = msgs::NormalsPlane(*m, m.payload);
    for (size_t p = 0; p < n.size(); p += 3) n[p + 2] = -1.0f;
    for (uint8_t& c : msgs::ColourPlane(*m, m.payload)) c = 120;
    gbuffer_pub.Publish(std::move(loan));
  }
  std::optional<bus::Sample> transfer = transfers.Take(20s);
  pid_t pid = 0;
  std::ifstream(pid_file) >> pid;
  if (pid > 0) kill(pid, SIGINT);
  node.join();
  const std::string log = ReadFile(err);
  std::remove(err.c_str());
  std::remove(pid_file.c_str());
  ASSERT_TRUE(transfer.has_value()) << "the frame was not processed: " << log;
  EXPECT_EQ(msgs::ReadMessage<msgs::TransferBuffer>(transfer->data())->header.stamp_ns, stamp);
  EXPECT_NE(log.find("probeless_msgs/AuxiliaryViews view 0 (left 128x128): depth plane (offset "
                     "0, 65536 bytes) exceeds the payload of"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("(frame 1 runs without auxiliary views)"), std::string::npos) << log;
  EXPECT_NE(log.find("malformed for 1"), std::string::npos) << log;  // ran on to a clean exit
}

}  // namespace
