// demo_report: reads an MCAP recording of a light-estimation graph and writes what a person wants
// to look at: estimated vs true light direction over time (PNG), the angular error per frame, and
// per-node latency figures (JSON and a text summary).
//
//   demo_report LOG.mcap --estimate /face/light --truth /groundtruth/light --out DIR [--name face]
//               [--stage /camera/camera_info:/face/observation:/face/light]
//
// Estimates and truths are msgs::ShLight in the same frame (the camera frame), matched by
// header.stamp_ns. Directions are shown as azimuth = atan2(-x, -z) (positive: light from the image
// left, the subject's right, as in Extended Yale B) and elevation = asin(-y), in degrees, in the
// camera frame (x right, y down, z forward). --stage lists topics of one frame in pipeline order;
// the latency of each stage is the difference of the bus publish times of consecutive topics for
// the same header stamp. Writes DIR/<name>_light.png, DIR/<name>_report.json and prints the
// summary. Exit: 0, 2 on bad options or input (one line), 1 otherwise.
#include "probeless/node/main.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/log/mcap.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/header.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/node/flags.h"

namespace {

using namespace probeless;

constexpr double kDeg = 180.0 / M_PI;

struct Direction {
  double azimuth_deg = 0;
  double elevation_deg = 0;
  bool valid = false;
};

Direction ToAngles(const float d[3]) {
  const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (!(n > 1e-6)) return {};
  return {std::atan2(-d[0], -d[2]) * kDeg, std::asin(std::clamp(-d[1] / n, -1.0, 1.0)) * kDeg,
          true};
}

double AngleDeg(const float a[3], const float b[3]) {
  const double na = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  const double nb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
  const double c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (na * nb);
  return std::acos(std::clamp(c, -1.0, 1.0)) * kDeg;
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1,
                    static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5))];
}

std::vector<std::string> Split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream in(text);
  for (std::string part; std::getline(in, part, separator);) {
    if (!part.empty()) parts.push_back(part);
  }
  return parts;
}

// One panel: two series (truth green, estimate red) against time. The title has its own band
// above the plot (the top grid line's label used to overlap it).
void DrawPanel(cv::Mat& image, cv::Rect area, const std::string& title,
               const std::vector<double>& t, const std::vector<double>& truth,
               const std::vector<double>& estimate, double lo, double hi) {
  cv::rectangle(image, area, cv::Scalar(200, 200, 200));
  cv::putText(image, title, {area.x + 6, area.y + 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45,
              cv::Scalar(40, 40, 40), 1, cv::LINE_AA);
  if (t.empty()) return;
  const double t0 = t.front();
  const double t1 = std::max(t.back(), t0 + 1e-9);
  auto point = [&](double x, double y) {
    const double u = (x - t0) / (t1 - t0);
    const double v = (std::clamp(y, lo, hi) - lo) / (hi - lo);
    return cv::Point(area.x + 4 + static_cast<int>(u * (area.width - 8)),
                     area.y + area.height - 4 - static_cast<int>(v * (area.height - 34)));
  };
  for (double grid : {lo, 0.0, hi}) {
    cv::line(image, point(t0, grid), point(t1, grid), cv::Scalar(230, 230, 230));
    cv::putText(image, std::to_string(static_cast<int>(grid)), point(t0, grid) + cv::Point(2, -2),
                cv::FONT_HERSHEY_SIMPLEX, 0.35, cv::Scalar(120, 120, 120), 1, cv::LINE_AA);
  }
  auto series = [&](const std::vector<double>& y, cv::Scalar colour) {
    for (size_t i = 1; i < y.size(); ++i) {
      if (std::isnan(y[i - 1]) || std::isnan(y[i])) continue;
      cv::line(image, point(t[i - 1], y[i - 1]), point(t[i], y[i]), colour, 2, cv::LINE_AA);
    }
  };
  series(truth, cv::Scalar(60, 160, 60));
  series(estimate, cv::Scalar(40, 40, 220));
}

int Run(int argc, char** argv) {
  std::string log_path;
  std::string estimate_topic = "/face/light";
  std::string truth_topic = "/groundtruth/light";
  std::string out_dir = ".";
  std::string name = "face";
  std::string stages;
  node::FlagParser flags(
      "demo_report",
      "reads an MCAP recording of a light-estimation graph and writes estimated vs true light\n"
      "direction over time (DIR/<name>_light.png), the angular error per frame and per-node\n"
      "latency figures (DIR/<name>_report.json), and prints the summary");
  flags.AddPositional("LOG.mcap", &log_path, "the recording (required)");
  flags.Add("--estimate", &estimate_topic, "TOPIC", "the estimated msgs::ShLight");
  flags.Add("--truth", &truth_topic, "TOPIC", "the true msgs::ShLight");
  flags.Add("--out", &out_dir, "DIR", "where the PNG and the JSON go");
  flags.Add("--name", &name, "NAME", "prefix of the files written");
  flags.Add("--stage", &stages, "T1:T2:...",
            "topics of one frame in pipeline order: the latency of each stage");
  if (!flags.Parse(argc, argv)) return 0;
  if (log_path.empty()) throw node::UsageError("no log given (demo_report LOG.mcap ...)");

  const log::McapReader reader(log_path);
  const auto& light_converter = log::Ros2ConverterFor<msgs::ShLight>();
  std::map<int64_t, msgs::ShLight> estimates;
  std::map<int64_t, msgs::ShLight> truths;
  const std::vector<std::string> stage_topics = Split(stages, ':');
  // stamp -> topic -> publish time
  std::map<int64_t, std::map<std::string, uint64_t>> published;
  log::MessageCursor cursor = reader.Messages();
  log::MessageView view;
  while (cursor.Next(view)) {
    const std::string& topic = view.channel->topic;
    const bool is_stage =
        std::find(stage_topics.begin(), stage_topics.end(), topic) != stage_topics.end();
    if (topic != estimate_topic && topic != truth_topic && !is_stage) continue;
    const auto* converter = log::FindRos2ConverterByRos2Type(view.schema ? view.schema->name : "");
    if (converter == nullptr) continue;
    const log::MessageBuffer message =
        log::DecodeRos2(*converter, view.data, view.channel->metadata);
    const auto* header = reinterpret_cast<const msgs::Header*>(message.bytes().data());
    if (is_stage) published[header->stamp_ns][topic] = view.publish_time_ns;
    if ((topic == estimate_topic || topic == truth_topic) &&
        converter->probeless_type() == light_converter.probeless_type()) {
      const auto light = *reinterpret_cast<const msgs::ShLight*>(message.bytes().data());
      (topic == estimate_topic ? estimates : truths)[header->stamp_ns] = light;
    }
  }
  if (truths.empty()) {
    throw log::LogError(log_path + ": no " + truth_topic + " messages (msgs::ShLight)");
  }

  // Series over the truth's frames; NaN where there is no estimate.
  std::vector<double> t;
  std::vector<double> true_az;
  std::vector<double> true_el;
  std::vector<double> est_az;
  std::vector<double> est_el;
  std::vector<double> errors;
  const int64_t t0 = truths.begin()->first;
  for (const auto& [stamp, truth] : truths) {
    const Direction td = ToAngles(truth.dominant_direction);
    if (!td.valid) continue;
    t.push_back(static_cast<double>(stamp - t0) / 1e9);
    true_az.push_back(td.azimuth_deg);
    true_el.push_back(td.elevation_deg);
    const auto e = estimates.find(stamp);
    const Direction ed =
        e == estimates.end() ? Direction{} : ToAngles(e->second.dominant_direction);
    est_az.push_back(ed.valid ? ed.azimuth_deg : std::nan(""));
    est_el.push_back(ed.valid ? ed.elevation_deg : std::nan(""));
    if (ed.valid)
      errors.push_back(AngleDeg(truth.dominant_direction, e->second.dominant_direction));
  }

  cv::Mat plot(560, 900, CV_8UC3, cv::Scalar(255, 255, 255));
  DrawPanel(plot, {10, 10, 880, 260}, "azimuth (deg): true green, estimated red", t, true_az,
            est_az, -180, 180);
  DrawPanel(plot, {10, 290, 880, 260}, "elevation (deg): true green, estimated red", t, true_el,
            est_el, -90, 90);
  const std::string png = out_dir + "/" + name + "_light.png";
  if (!cv::imwrite(png, plot)) throw std::runtime_error("cannot write '" + png + "'");

  std::ostringstream json;
  json << "{\"frames\": " << t.size() << ", \"estimates\": " << errors.size()
       << ", \"angular_error_deg_mean\": "
       << (errors.empty() ? 0.0
                          : std::accumulate(errors.begin(), errors.end(), 0.0) / errors.size())
       << ", \"angular_error_deg_median\": " << Percentile(errors, 0.5)
       << ", \"angular_error_deg_p90\": " << Percentile(errors, 0.9) << ", \"latency_ms\": {";
  std::ostringstream summary;
  summary << name << ": " << errors.size() << " estimates over " << t.size()
          << " frames; light direction error median " << Percentile(errors, 0.5) << " deg, p90 "
          << Percentile(errors, 0.9) << " deg\n";
  for (size_t s = 1; s < stage_topics.size(); ++s) {
    std::vector<double> ms;
    for (const auto& [stamp, times] : published) {
      const auto a = times.find(stage_topics[s - 1]);
      const auto b = times.find(stage_topics[s]);
      if (a != times.end() && b != times.end() && b->second >= a->second) {
        ms.push_back(static_cast<double>(b->second - a->second) / 1e6);
      }
    }
    json << (s > 1 ? ", " : "") << "\"" << stage_topics[s]
         << "\": {\"median\": " << Percentile(ms, 0.5) << ", \"p90\": " << Percentile(ms, 0.9)
         << ", \"n\": " << ms.size() << "}";
    summary << "  " << stage_topics[s - 1] << " -> " << stage_topics[s] << ": median "
            << Percentile(ms, 0.5) << " ms, p90 " << Percentile(ms, 0.9) << " ms (" << ms.size()
            << " frames)\n";
  }
  json << "}}\n";
  std::ofstream(out_dir + "/" + name + "_report.json") << json.str();
  std::printf("%s", summary.str().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("demo_report", [&] { return Run(argc, argv); });
}
