// Unit tests of the bridge's naming, QoS and route parsing and the generated Cyclone config.
#include "probeless/dds_bridge/bridge.h"

#include <gtest/gtest.h>

#include <cstdlib>

namespace probeless::dds_bridge {
namespace {

TEST(DdsBridgeNames, TopicAndTypeNamesFollowRos2) {
  EXPECT_EQ(DdsTopicName("/camera/image"), "rt/camera/image");
  EXPECT_EQ(RosTopicName("rt/camera/image"), "/camera/image");
  EXPECT_EQ(RosTopicName("DCPSParticipant"), "");
  EXPECT_EQ(DdsTypeName("sensor_msgs/msg/Image"), "sensor_msgs::msg::dds_::Image_");
  EXPECT_EQ(Ros2TypeName("sensor_msgs::msg::dds_::Image_"), "sensor_msgs/msg/Image");
  EXPECT_EQ(Ros2TypeName("geometry_msgs::msg::dds_::PoseStamped_"), "geometry_msgs/msg/PoseStamped");
  EXPECT_EQ(Ros2TypeName("Image"), "");
}

TEST(DdsBridgeParse, QosRulesAndRoutes) {
  const QosRule r = ParseQosRule("/camera/.*=best_effort,3,");
  EXPECT_EQ(r.regex, "/camera/.*");
  EXPECT_EQ(r.reliability, Reliability::kBestEffort);
  EXPECT_EQ(r.depth, 3u);
  EXPECT_FALSE(r.durability.has_value());
  EXPECT_EQ(ParseQosRule("/tf=,,transient_local").durability, Durability::kTransientLocal);
  EXPECT_THROW(ParseQosRule("/x=fast"), DdsBridgeError);
  EXPECT_THROW(ParseQosRule("/x=reliable,0"), DdsBridgeError);
  EXPECT_THROW(ParseQosRule("nothing"), DdsBridgeError);
  const Route a = ParseRoute("/camera/image:=/robot1/camera/image");
  EXPECT_EQ(a.from, "/camera/image");
  EXPECT_EQ(a.to, "/robot1/camera/image");
  EXPECT_EQ(ParseRoute("/a").to, "/a");
  EXPECT_THROW(ParseRoute("no slash"), DdsBridgeError);
}

TEST(DdsBridgeConfig, LoopbackOnlyByDefault) {
  BridgeOptions o;
  const std::string xml = CycloneConfig(o);
  EXPECT_NE(xml.find("<NetworkInterface address=\"127.0.0.1\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<AllowMulticast>false</AllowMulticast>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<Peer address=\"127.0.0.1\"/>"), std::string::npos) << xml;
  o.interfaces = {"eth0"};
  o.peers = {"192.0.2.7"};
  const std::string explicit_xml = CycloneConfig(o);
  EXPECT_NE(explicit_xml.find("<NetworkInterface name=\"eth0\"/>"), std::string::npos);
  EXPECT_EQ(explicit_xml.find("127.0.0.1"), std::string::npos);
}

TEST(DdsBridgeConfig, DomainId) {
  EXPECT_EQ(ResolveDomainId(7), 7);
  EXPECT_THROW(ResolveDomainId(300), DdsBridgeError);
  setenv("ROS_DOMAIN_ID", "12", 1);
  EXPECT_EQ(ResolveDomainId(-1), 12);
  setenv("ROS_DOMAIN_ID", "x", 1);
  EXPECT_THROW(ResolveDomainId(-1), DdsBridgeError);
  unsetenv("ROS_DOMAIN_ID");
  EXPECT_EQ(ResolveDomainId(-1), 0);
}

}  // namespace
}  // namespace probeless::dds_bridge
