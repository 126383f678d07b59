#include "probeless/foxglove/channels.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"

namespace probeless::foxglove {
namespace {

namespace m = probeless::msgs;
using ::testing::ElementsAre;

BusTopic Image(const std::string& topic) {
  return {topic, std::string(m::Image::kTypeName), m::Image::kLayoutHash};
}
BusTopic Light(const std::string& topic) {
  return {topic, std::string(m::ShLight::kTypeName), m::ShLight::kLayoutHash};
}

std::string FilterError(const TopicSelection& s) {
  try {
    TopicFilter f(s);
  } catch (const FoxgloveError& e) {
    return e.what();
  }
  return "no error";
}

TEST(TopicFilterTest, AllListRegexExclude) {
  TopicFilter all({.all = true, .exclude = "^/debug"});
  EXPECT_TRUE(all.Selected("/camera/image"));
  EXPECT_FALSE(all.Selected("/debug/x"));
  TopicFilter list({.topics = {"/a", "/b"}});
  EXPECT_TRUE(list.Selected("/a"));
  EXPECT_FALSE(list.Selected("/a/b"));
  TopicFilter regex({.regex = "^/camera/"});
  EXPECT_TRUE(regex.Selected("/camera/depth"));
  EXPECT_FALSE(regex.Selected("/scene/light"));
  EXPECT_EQ(FilterError({}), "no topics selected (expected all, a topic list or a regex)");
  EXPECT_THAT(FilterError({.regex = "("}), ::testing::StartsWith("invalid topic regex '(': "));
  EXPECT_THAT(FilterError({.topics = {"camera"}}), ::testing::StartsWith("topics: "));
}

TEST(ChannelTableTest, AdvertisesTheRecorderSchemasAndKeepsIds) {
  ChannelTable table({.selection = {.all = true}, .jpeg_topics = {"/render/composite"}});
  const std::vector<BusTopic> topics = {
      Image("/camera/image"),
      Light("/scene/light"),
      Image("/render/composite"),
      {"/clock", std::string(m::Header::kTypeName), m::Header::kLayoutHash}};
  ChannelChanges c = table.Update(topics);
  ASSERT_EQ(c.added.size(), 4u);  // image, light, composite + its JPEG channel
  EXPECT_TRUE(c.removed.empty());
  EXPECT_THAT(c.notices, ElementsAre("/clock: type probeless_msgs/Header has no ROS 2 "
                                     "conversion; not advertised"));
  EXPECT_TRUE(c.warnings.empty());
  const log::Ros2Converter& image = log::Ros2ConverterFor<m::Image>();
  for (const Channel& ch : c.added) {
    EXPECT_EQ(ch.encoding, "cdr");
    EXPECT_EQ(ch.schema_encoding, "ros2msg");
    if (ch.topic == "/render/composite/compressed") {
      EXPECT_EQ(ch.schema_name, "sensor_msgs/msg/CompressedImage");
      EXPECT_EQ(ch.schema, log::CompressedImageSchemaText());
      EXPECT_EQ(table.Find(ch.id)->kind, ChannelKind::kJpeg);
      EXPECT_EQ(table.Find(ch.id)->bus_topic, "/render/composite");
    } else if (ch.topic == "/scene/light") {
      EXPECT_EQ(ch.schema_name, "probeless_msgs/msg/ShLight");
      EXPECT_EQ(ch.schema, log::Ros2ConverterFor<m::ShLight>().schema_text());
    } else {
      EXPECT_EQ(ch.schema_name, image.ros2_type());
      EXPECT_EQ(ch.schema, image.schema_text());
    }
  }
  // Nothing changes: nothing reported, warnings only once.
  c = table.Update(topics);
  EXPECT_TRUE(c.added.empty() && c.removed.empty() && c.warnings.empty() && c.notices.empty());

  // The light goes, then comes back: same id.
  uint32_t light_id = 0;
  for (const Channel& ch : table.Channels()) {
    if (ch.topic == "/scene/light") light_id = ch.id;
  }
  c = table.Update(std::vector<BusTopic>{topics[0], topics[2]});
  EXPECT_THAT(c.removed, ElementsAre(light_id));
  EXPECT_EQ(table.Find(light_id), nullptr);
  c = table.Update(topics);
  ASSERT_EQ(c.added.size(), 1u);
  EXPECT_EQ(c.added[0].id, light_id);

  // Retyped: a new channel id.
  c = table.Update(std::vector<BusTopic>{topics[0], Image("/scene/light"), topics[2]});
  EXPECT_THAT(c.removed, ElementsAre(light_id));
  ASSERT_EQ(c.added.size(), 1u);
  EXPECT_NE(c.added[0].id, light_id);
  EXPECT_EQ(c.added[0].schema_name, "sensor_msgs/msg/Image");
}

TEST(ChannelTableTest, SelectionAndJpegRules) {
  ChannelTable table(
      {.selection = {.regex = "^/scene/"}, .jpeg_topics = {"/camera/image", "/scene/light"}});
  ChannelChanges c = table.Update(
      std::vector<BusTopic>{Image("/camera/image"), Light("/scene/light"), Image("/other")});
  std::vector<std::string> names;
  for (const Channel& ch : c.added) names.push_back(ch.topic);
  // /camera/image is not selected, but its JPEG channel is; /scene/light has no JPEG channel.
  EXPECT_THAT(names, ::testing::UnorderedElementsAre("/camera/image/compressed", "/scene/light"));
  EXPECT_THAT(c.warnings,
              ElementsAre("/scene/light: type probeless_msgs/ShLight is not an image; no "
                          "JPEG channel"));
  // A layout of another build is not advertised.
  ChannelTable other({.selection = {.all = true}});
  c = other.Update(std::vector<BusTopic>{{"/x", std::string(m::Image::kTypeName), 1234}});
  EXPECT_TRUE(c.added.empty());
  EXPECT_THAT(c.warnings, ElementsAre("/x: type probeless_msgs/Image has a layout hash this build "
                                      "does not convert; not advertised"));
}

}  // namespace
}  // namespace probeless::foxglove
