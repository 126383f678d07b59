// face_light_eval: estimates the light of every Extended Yale B light image of subjects a model was
// not trained on and compares the optimal linear direction with the file name's azimuth and
// elevation (Knorr & Kurz 2014, sec. 5.1). Writes JSON figures and optional PNG plots.
//
//   face_light_eval --model MODEL --yaleb DIR|--synthetic DIR [--subjects LIST]
//                   [--landmarks aligned|tracker] [--head-pose none|tracker [--train-yaleb DIR]]
//                   --json OUT
//                   [--plots DIR] [--ridge X] [--back-prior X] [--robust] [--robust-threshold X]
//                   [--non-negative] [--weight-floor X]
#include "probeless/node/main.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/model.h"
#include "probeless/face_light/yaleb.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/sampling.h"
#include "probeless/node/flags.h"
#include "probeless/parse/number.h"
#include "probeless/sh/sh.h"

namespace fl = probeless::face_light;
namespace sh = probeless::sh;

namespace {

constexpr double kDeg = 180 / std::numbers::pi;

constexpr const char* kDescription =
    "estimates the light of every Extended Yale B light image of subjects the model was not\n"
    "trained on and compares its direction with the file name's azimuth and elevation (Knorr &\n"
    "Kurz 2014, sec. 5.1); --model, --yaleb (or --synthetic) and --json are required. Estimator\n"
    "options: docs/face_light.md.";

struct Result {
  int subject = 0;
  double true_azimuth = 0, true_elevation = 0;  // degrees
  double azimuth = 0, elevation = 0;            // estimated, degrees
  double angular_error = 0;                     // degrees
  double microseconds = 0;
};

double Mean(const std::vector<double>& v) {
  double sum = 0;
  for (double x : v) sum += x;
  return v.empty() ? 0 : sum / v.size();
}

double Std(const std::vector<double>& v) {
  const double mean = Mean(v);
  double sum = 0;
  for (double x : v) sum += (x - mean) * (x - mean);
  return v.size() < 2 ? 0 : std::sqrt(sum / (v.size() - 1));
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : (v[v.size() / 2 - 1] + v[v.size() / 2]) / 2;
}

// Scatter plot of estimated vs true angles (paper fig. 6): x = true, y = estimated, both over
// [-range, range] degrees, with the diagonal.
void ScatterPlot(const std::string& path, const std::string& title,
                 const std::vector<std::pair<double, double>>& points, double range) {
  constexpr int kSize = 480, kMargin = 50;
  cv::Mat image(kSize + 2 * kMargin, kSize + 2 * kMargin, CV_8UC3, cv::Scalar(255, 255, 255));
  const auto to_pixel = [&](double x, double y) {
    return cv::Point(static_cast<int>(kMargin + (x + range) / (2 * range) * kSize),
                     static_cast<int>(kMargin + (range - y) / (2 * range) * kSize));
  };
  for (double t = -range; t <= range + 1e-9; t += range / 4) {
    cv::line(image, to_pixel(t, -range), to_pixel(t, range), cv::Scalar(225, 225, 225));
    cv::line(image, to_pixel(-range, t), to_pixel(range, t), cv::Scalar(225, 225, 225));
    char label[16];
    std::snprintf(label, sizeof label, "%.0f", t);
    cv::putText(image, label, to_pixel(t, -range) + cv::Point(-12, 18), cv::FONT_HERSHEY_PLAIN, 0.9,
                cv::Scalar(0, 0, 0));
    cv::putText(image, label, to_pixel(-range, t) + cv::Point(-42, 4), cv::FONT_HERSHEY_PLAIN, 0.9,
                cv::Scalar(0, 0, 0));
  }
  cv::rectangle(image, to_pixel(-range, range), to_pixel(range, -range), cv::Scalar(0, 0, 0));
  cv::line(image, to_pixel(-range, -range), to_pixel(range, range), cv::Scalar(0, 160, 0));
  for (const auto& [x, y] : points) {
    cv::circle(image, to_pixel(x, std::clamp(y, -range, range)), 2, cv::Scalar(200, 60, 0),
               cv::FILLED);
  }
  cv::putText(image, title, cv::Point(kMargin, 30), cv::FONT_HERSHEY_SIMPLEX, 0.6,
              cv::Scalar(0, 0, 0));
  cv::putText(image, "true (deg)", cv::Point(kMargin + kSize / 2 - 40, kSize + 2 * kMargin - 8),
              cv::FONT_HERSHEY_PLAIN, 1.0, cv::Scalar(0, 0, 0));
  if (!cv::imwrite(path, image)) throw fl::FaceLightError(path + ": cannot write PNG");
}

// Diverging colour (blue < 0 < red) of value / scale.
cv::Vec3b Diverging(double t) {
  t = std::clamp(t, -1.0, 1.0);
  const auto channel = [](double x) { return static_cast<uint8_t>(std::clamp(x, 0.0, 255.0)); };
  if (t >= 0) return {channel(255 * (1 - t)), channel(255 * (1 - t)), 255};
  return {255, channel(255 * (1 + t)), channel(255 * (1 + t))};
}

cv::Mat LatLongPanel(const std::array<double, 9>& light, double scale, int width, int height) {
  std::vector<float> coefficients(light.begin(), light.end());
  std::vector<float> values(static_cast<size_t>(width) * height);
  sh::RenderLatLong(coefficients, 3, 1, width, height, values);
  cv::Mat panel(height, width, CV_8UC3);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u)
      panel.at<cv::Vec3b>(v, u) = Diverging(values[v * width + u] / scale);
  }
  return panel;
}

// One picture per image: the face with its samples, then lat-long truth (the directional light's
// band-2 projection scaled to the estimate's intensity), estimate and difference, on one colour
// scale; crosses mark the true (green) and estimated (black) directions.
void LatLongFigure(const std::string& path, const fl::YaleBImage& face,
                   const fl::FaceLightModel& model, const fl::LightEstimate& estimate,
                   const Result& result) {
  constexpr int kW = 256, kH = 128;
  std::array<double, 9> estimated{}, truth{}, difference{};
  for (int n = 0; n < 9; ++n) estimated[n] = estimate.coefficients[n][0];
  const std::vector<double> directional =
      sh::DirectionalLight(fl::YaleBLightDirection(result.true_azimuth, result.true_elevation),
                           std::max(estimate.intensity, 1e-6f), 3);
  double scale = 1e-9;
  for (int n = 0; n < 9; ++n) {
    truth[n] = directional[n];
    difference[n] = estimated[n] - truth[n];
  }
  for (const auto& light : {estimated, truth}) {
    std::vector<float> c(light.begin(), light.end()), values(kW * kH);
    sh::RenderLatLong(c, 3, 1, kW, kH, values);
    for (float x : values) scale = std::max(scale, static_cast<double>(std::abs(x)));
  }
  cv::Mat face_image(face.height, face.width, CV_8UC1, const_cast<uint8_t*>(face.pixels.data()));
  cv::Mat face_colour;
  cv::cvtColor(face_image, face_colour, cv::COLOR_GRAY2BGR);
  for (const fl::Point2& p : model.positions) {
    const fl::Point2 px = fl::CropPixelFromNormalised(p);
    face_colour.at<cv::Vec3b>(static_cast<int>(std::lround(px.y)),
                              static_cast<int>(std::lround(px.x))) = cv::Vec3b(0, 200, 255);
  }
  cv::Mat face_small;
  cv::resize(face_colour, face_small, cv::Size(kH * face.width / face.height, kH));
  cv::Mat canvas(kH + 24, face_small.cols + 3 * (kW + 8) + 8, CV_8UC3, cv::Scalar(255, 255, 255));
  face_small.copyTo(canvas(cv::Rect(0, 24, face_small.cols, kH)));
  const char* titles[3] = {"truth (band 2)", "estimate", "estimate - truth"};
  const std::array<double, 9>* lights[3] = {&truth, &estimated, &difference};
  for (int k = 0; k < 3; ++k) {
    const int x0 = face_small.cols + 8 + k * (kW + 8);
    LatLongPanel(*lights[k], scale, kW, kH).copyTo(canvas(cv::Rect(x0, 24, kW, kH)));
    cv::putText(canvas, titles[k], cv::Point(x0, 17), cv::FONT_HERSHEY_PLAIN, 1.0,
                cv::Scalar(0, 0, 0));
    const auto mark = [&](double azimuth, double elevation, cv::Scalar colour) {
      const int u = static_cast<int>((180 - azimuth) / 360 * kW);
      const int v = static_cast<int>((90 - elevation) / 180 * kH);
      cv::drawMarker(canvas, cv::Point(x0 + u, 24 + v), colour, cv::MARKER_CROSS, 10, 2);
    };
    mark(result.true_azimuth, result.true_elevation, cv::Scalar(0, 160, 0));
    mark(result.azimuth, result.elevation, cv::Scalar(0, 0, 0));
  }
  if (!cv::imwrite(path, canvas)) throw fl::FaceLightError(path + ": cannot write PNG");
}

// --synthetic: the colour error on the .ppm images of `sim --yaleb-style --rgb` (docs/sim.md).
// Per image, EstimateRgb on the RGB patches; estimated light colour = band-0 coefficient per
// channel raised to 1 / intensity_exponent (undoing the model's response); true colour from the
// sidecar yaleBxx_P00_lights.txt. "Corrected": the inputs are first divided by the subject's skin
// chromaticity, measured on its frontal-lit .ppm (median of value / true light colour per
// channel, normalised to mean 1), as a calibration shot; "uncorrected" keeps the skin tint.
struct ColourFigures {
  std::vector<double> corrected, uncorrected;  // angles, degrees
};

double ColourAngle(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const double n = std::sqrt((a[0] * a[0] + a[1] * a[1] + a[2] * a[2]) *
                             (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]));
  return n > 0 ? std::acos(std::clamp(dot / n, -1.0, 1.0)) * kDeg : 90;
}

ColourFigures EvaluateSyntheticColour(const std::string& dir, const std::vector<int>& subjects,
                                      const fl::FaceLightModel& model,
                                      const fl::FaceLightEstimator& estimator) {
  ColourFigures figures;
  const int n = model.SampleCount();
  for (int subject : subjects) {
    char folder_name[16];
    std::snprintf(folder_name, sizeof folder_name, "yaleB%02d", subject);
    const std::filesystem::path folder = std::filesystem::path(dir) / folder_name;
    std::ifstream sidecar(folder / (std::string(folder_name) + "_P00_lights.txt"));
    std::vector<std::pair<std::string, std::array<double, 3>>> files;  // .ppm, light colour
    std::string line;
    while (std::getline(sidecar, line)) {
      char file[64];
      double a, e, dx, dy, dz, r, g, b;
      if (std::sscanf(line.c_str(), "%63s %lf %lf %lf %lf %lf %lf %lf %lf", file, &a, &e, &dx, &dy,
                      &dz, &r, &g, &b) == 9 &&
          std::string_view(file).ends_with(".ppm")) {
        files.push_back({file, {r, g, b}});
      }
    }
    if (files.empty()) continue;
    std::sort(files.begin(), files.end());
    const auto sample = [&](const std::string& file, std::vector<float>& values,
                            std::vector<uint8_t>& valid) {
      const std::string path = (folder / file).string();
      cv::Mat bgr = cv::imread(path, cv::IMREAD_COLOR);
      if (bgr.empty()) throw fl::FaceLightError(path + ": cannot decode image");
      if (bgr.cols != fl::kCropWidth || bgr.rows != fl::kCropHeight) {
        throw fl::FaceLightError(path + ": image is " + std::to_string(bgr.cols) + "x" +
                                 std::to_string(bgr.rows) + ", expected the 168x192 crop");
      }
      cv::Mat rgb;
      cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
      fl::SamplePatches(rgb.ptr<uint8_t>(), rgb.cols, rgb.rows, rgb.step, 3,
                        fl::SimilarityTransform{}, model.positions, model.patch_radius_px, 255,
                        values, valid);
    };
    std::vector<float> values(3 * n), scaled(3 * n);
    std::vector<uint8_t> valid(n);
    std::vector<uint64_t> bits((n + 63) / 64);
    // Skin chromaticity from the frontal-lit image.
    std::array<double, 3> skin{1, 1, 1};
    for (const auto& [file, colour] : files) {
      if (file.find("A+000E+00") == std::string::npos) continue;
      sample(file, values, valid);
      for (int c = 0; c < 3; ++c) {
        std::vector<double> ratios;
        for (int i = 0; i < n; ++i) {
          if (valid[i] && values[3 * i + c] > 0) ratios.push_back(values[3 * i + c] / colour[c]);
        }
        skin[c] = Median(ratios);
      }
      const double mean = (skin[0] + skin[1] + skin[2]) / 3;
      for (double& k : skin) k = mean > 0 && k > 0 ? k / mean : 1;
    }
    for (const auto& [file, colour] : files) {
      sample(file, values, valid);
      std::fill(bits.begin(), bits.end(), 0);
      for (int i = 0; i < n; ++i) {
        if (valid[i]) bits[i / 64] |= uint64_t{1} << (i % 64);
      }
      for (int i = 0; i < 3 * n; ++i) scaled[i] = static_cast<float>(values[i] / skin[i % 3]);
      for (int pass = 0; pass < 2; ++pass) {
        const fl::LightEstimate e = estimator.EstimateRgb(pass == 0 ? scaled : values, bits);
        std::array<double, 3> estimated{};
        for (int c = 0; c < 3; ++c) {
          estimated[c] = std::pow(std::max(static_cast<double>(e.coefficients[0][c]), 1e-9),
                                  1.0 / model.intensity_exponent);
        }
        (pass == 0 ? figures.corrected : figures.uncorrected)
            .push_back(e.channels == 0 ? 90.0 : ColourAngle(estimated, colour));
      }
    }
  }
  return figures;
}

// What the face tracker (dlib HOG + 68 landmarks + solvePnP of the generic head,
// docs/face_light.md) finds on a subject's frontal-lit image (A = 0, E = 0): its head rotation
// (face -> camera, row-major) and the canonical-crop -> image similarity the pipeline's sampler
// would use (face_track::CanonicalToImage). Without CLAHE (more accurate landmarks on these evenly
// lit crops, face_track_data_test); intrinsics f = 1050 px at the crop centre (a guess; the
// rotation hardly depends on it: 3000 px changes the evaluation by < 0.05 degrees). Subjects
// without a detected face are left out.
struct FrontalTrack {
  std::array<double, 9> rotation{};
  fl::SimilarityTransform crop_to_image;
};
std::map<int, FrontalTrack> FrontalTracks(const std::string& dir,
                                          const std::vector<int>& subjects) {
  namespace ft = probeless::face_track;
  ft::TrackerOptions options;
  options.clahe_clip_limit = 0;
  ft::FaceTracker tracker(options);
  std::map<int, FrontalTrack> out;
  for (int s : subjects) {
    char name[64];
    std::snprintf(name, sizeof name, "yaleB%02d/yaleB%02d_P00A+000E+00.pgm", s, s);
    const std::string path = (std::filesystem::path(dir) / name).string();
    if (!std::filesystem::exists(path)) continue;
    const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw fl::FaceLightError(path + ": cannot decode image");
    const ft::ImageView view{image.data, image.cols, image.rows, static_cast<size_t>(image.step),
                             ft::PixelFormat::kGray};
    const ft::FaceTrack t = tracker.DetectOnce(
        view, ft::Intrinsics{1050, 1050, (image.cols - 1) / 2.0, (image.rows - 1) / 2.0});
    if (t.found && t.pose.valid) {
      out[s] = {t.pose.rotation, ft::CanonicalToImage(t.landmarks)};
    }
  }
  return out;
}

// The rotation nearest the mean of rotation matrices (the mean re-orthonormalised by Gram-Schmidt
// on its rows; the poses are within a few degrees of each other).
std::array<double, 9> MeanRotation(const std::vector<std::array<double, 9>>& rotations) {
  std::array<double, 9> r{};
  for (const auto& m : rotations) {
    for (int k = 0; k < 9; ++k) r[k] += m[k];
  }
  const auto normalise = [](double* v) {
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; ++k) v[k] /= n;
  };
  normalise(&r[0]);
  const double dot = r[0] * r[3] + r[1] * r[4] + r[2] * r[5];
  for (int k = 0; k < 3; ++k) r[3 + k] -= dot * r[k];
  normalise(&r[3]);
  r[6] = r[1] * r[5] - r[2] * r[4];
  r[7] = r[2] * r[3] - r[0] * r[5];
  r[8] = r[0] * r[4] - r[1] * r[3];
  return r;
}

int Run(int argc, char** argv) {
  std::string model_path, yaleb, subjects_text, json_path, plots, landmarks = "aligned";
  std::string head_pose = "none";
  std::string train_yaleb;  // where the training subjects' images are (--head-pose tracker)
  fl::EstimatorOptions options;
  bool synthetic = false;
  probeless::node::FlagParser flags("face_light_eval", kDescription);
  flags.Add("--model", &model_path, "MODEL", "the face light model (rtf_train --out)");
  flags.AddCallback("--yaleb", "DIR", "the Extended Yale B folder", [&](const std::string& v) {
    yaleb = v;
    synthetic = false;
  });
  flags.AddCallback(
      "--synthetic", "DIR",
      "a `sim --yaleb-style` folder instead of --yaleb; with --rgb images (.ppm) the JSON adds "
      "colour_angle_deg_mean (docs/sim.md)",
      [&](const std::string& v) {
        yaleb = v;
        synthetic = true;
      });
  flags.Add("--subjects", &subjects_text, "LIST",
            "test subjects (default: every subject in DIR the model was not trained on); a "
            "training subject is an error");
  flags.Add("--landmarks", &landmarks, "aligned|tracker",
            "sample positions on the crop as it is (aligned), or mapped onto each subject by the "
            "face tracker's landmarks on its frontal-lit image (tracker; train the model with "
            "rtf_train --align tracker)");
  flags.Add("--head-pose", &head_pose, "none|tracker",
            "tracker: rotate each estimate from the face frame into the camera frame by the "
            "subject's head rotation relative to the training subjects' mean");
  flags.Add("--train-yaleb", &train_yaleb, "DIR",
            "with --head-pose tracker: the Yale B folder of the model's training subjects "
            "(default: the --yaleb folder)");
  flags.Add("--json", &json_path, "OUT", "write the figures as JSON");
  flags.Add("--plots", &plots, "DIR",
            "write azimuth/elevation scatter plots and lat-long maps (PNG)");
  flags.Add("--ridge", &options.ridge, "X", "estimator: ridge");
  flags.Add("--back-prior", &options.back_prior, "X", "estimator: back-hemisphere prior");
  flags.Add("--robust", &options.robust, "estimator: drop outlier samples and re-solve");
  flags.Add("--robust-threshold", &options.robust_threshold, "X", "estimator: outlier threshold");
  flags.Add("--non-negative", &options.non_negative, "estimator: non-negative light");
  flags.Add("--weight-floor", &options.weight_floor, "X", "estimator: sample weight floor");
  flags.AddSwitch(
      "--linear-direction", [&] { options.directional_fit = false; },
      "estimator: Sloan's optimal linear direction (the paper)");
  flags.AddTruncatedInt("--directional-grid", &options.directional_grid, "N",
                        "estimator: start directions");
  flags.AddTruncatedInt("--directional-iterations", &options.directional_iterations, "N",
                        "estimator: Newton iterations");
  flags.AddSwitch(
      "--no-ambient", [&] { options.directional_ambient = false; },
      "estimator: no ambient term in the directional fit");
  flags.AddSwitch(
      "--no-direction-rtfs", [&] { options.use_direction_rtfs = false; },
      "estimator: without the direction RTFs");
  flags.Add("--directional-robust", &options.directional_robust, "K",
            "estimator: robust scale of the directional fit");
  flags.Add("--direction-ridge", &options.direction_ridge, "X", "estimator: direction ridge");
  if (!flags.Parse(argc, argv)) return 0;
  if (model_path.empty() || yaleb.empty() || json_path.empty()) {
    throw probeless::node::UsageError("--model, --yaleb and --json are required (see --help)");
  }
  if (landmarks != "aligned" && landmarks != "tracker") {
    throw fl::FaceLightError("--landmarks '" + landmarks +
                             "' is not supported (aligned: the crop as it is; tracker)");
  }
  const fl::FaceLightModel model = fl::LoadModel(model_path);
  const fl::FaceLightEstimator estimator(model, options);
  const std::vector<int>& trained = model.training.subjects;
  const std::vector<int> available = fl::ListYaleBSubjects(yaleb);
  std::vector<int> subjects;
  if (subjects_text.empty()) {
    for (int s : available) {
      if (std::find(trained.begin(), trained.end(), s) == trained.end()) subjects.push_back(s);
    }
  } else {
    for (int s : fl::ParseSubjectList(subjects_text)) {
      if (std::find(trained.begin(), trained.end(), s) != trained.end()) {
        throw fl::FaceLightError("subject " + std::to_string(s) +
                                 " was used to train the model; evaluate on unseen subjects only");
      }
      if (std::find(available.begin(), available.end(), s) != available.end()) {
        subjects.push_back(s);
      } else {
        std::cerr << "face_light_eval: note: subject " << s << " is not in " << yaleb
                  << ", skipped\n";
      }
    }
  }
  if (subjects.empty())
    throw fl::FaceLightError("no test subject left (all were used in training)");
  if (head_pose != "none" && head_pose != "tracker") {
    throw fl::FaceLightError("--head-pose '" + head_pose + "' is not supported (none or tracker)");
  }
  // Head rotation of each test subject relative to the model's frame (the mean face frame of its
  // training subjects): R_s * mean^T (identity without --head-pose tracker).
  std::map<int, std::array<double, 9>> to_camera;
  std::map<int, FrontalTrack> frontal;
  if (head_pose == "tracker" || landmarks == "tracker") frontal = FrontalTracks(yaleb, subjects);
  if (head_pose == "tracker") {
    // The training subjects' frontal images: --train-yaleb, else the test folder (a folder of
    // unseen subjects alone does not hold them).
    const std::string train_dir = train_yaleb.empty() ? yaleb : train_yaleb;
    const std::map<int, FrontalTrack> training = FrontalTracks(train_dir, trained);
    std::vector<std::array<double, 9>> training_poses;
    for (const auto& [s, track] : training) training_poses.push_back(track.rotation);
    if (training_poses.empty()) {
      std::string list;
      for (int s : trained) list += (list.empty() ? "" : ",") + std::to_string(s);
      throw fl::FaceLightError("--head-pose tracker: no face found on any training subject (" +
                               list + ") in '" + train_dir + "'" +
                               (train_yaleb.empty()
                                    ? ": give the Yale B folder they are in with --train-yaleb DIR"
                                    : ": expected yaleBNN/yaleBNN_P00A+000E+00.pgm images there"));
    }
    const std::array<double, 9> mean = MeanRotation(training_poses);
    for (int s : subjects) {
      if (!frontal.count(s)) {
        std::cerr << "face_light_eval: note: no face found on subject " << s
                  << "'s frontal image, its estimates stay in the face frame\n";
        continue;
      }
      const std::array<double, 9>& r = frontal.at(s).rotation;
      std::array<double, 9> relative{};
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          for (int k = 0; k < 3; ++k) relative[3 * i + j] += r[3 * i + k] * mean[3 * j + k];
        }
      }
      to_camera[s] = relative;
    }
  }
  if (!plots.empty()) std::filesystem::create_directories(plots);

  std::vector<Result> results;
  std::vector<float> values(model.SampleCount());
  std::vector<uint8_t> valid(model.SampleCount());
  std::vector<uint64_t> valid_bits((model.SampleCount() + 63) / 64);
  int figures = 0;
  for (int subject : subjects) {
    fl::SimilarityTransform crop_to_image;  // identity: the crop as it is
    if (landmarks == "tracker") {
      if (frontal.count(subject)) {
        crop_to_image = frontal.at(subject).crop_to_image;
      } else {
        std::cerr << "face_light_eval: note: no face found on subject " << subject
                  << "'s frontal image, sampled on the crop as it is\n";
      }
    }
    for (const fl::YaleBImage& image : fl::LoadYaleBSubject(yaleb, subject)) {
      fl::SamplePatches(image.pixels.data(), image.width, image.height, image.width, 1,
                        crop_to_image, model.positions, model.patch_radius_px, 255, values, valid);
      std::fill(valid_bits.begin(), valid_bits.end(), 0);
      for (int i = 0; i < model.SampleCount(); ++i) {
        if (valid[i]) valid_bits[i / 64] |= uint64_t{1} << (i % 64);
      }
      const auto start = std::chrono::steady_clock::now();
      const fl::LightEstimate estimate = estimator.EstimateGray(values, valid_bits);
      const auto stop = std::chrono::steady_clock::now();
      Result r;
      r.subject = subject;
      r.true_azimuth = image.name.azimuth_deg;
      r.true_elevation = image.name.elevation_deg;
      r.microseconds = std::chrono::duration<double, std::micro>(stop - start).count();
      sh::Vec3 d{estimate.dominant_direction[0], estimate.dominant_direction[1],
                 estimate.dominant_direction[2]};
      if (const auto it = to_camera.find(subject); it != to_camera.end()) {
        const std::array<double, 9>& r = it->second;
        d = {r[0] * d[0] + r[1] * d[1] + r[2] * d[2], r[3] * d[0] + r[4] * d[1] + r[5] * d[2],
             r[6] * d[0] + r[7] * d[1] + r[8] * d[2]};
      }
      const std::array<double, 3> t = fl::YaleBLightDirection(r.true_azimuth, r.true_elevation);
      if (estimate.channels == 0 || d == sh::Vec3{0, 0, 0}) {
        r.angular_error = 180;  // no estimate counts as the worst error
      } else {
        const std::array<double, 2> ae = sh::AzimuthElevation(d);
        r.azimuth = ae[0] * kDeg;
        r.elevation = ae[1] * kDeg;
        const double dot = d[0] * t[0] + d[1] * t[1] + d[2] * t[2];
        r.angular_error = std::acos(std::clamp(dot, -1.0, 1.0)) * kDeg;
      }
      results.push_back(r);
      // A few lat-long figures: the first subject, a spread of light directions.
      if (!plots.empty() && subject == subjects.front() &&
          ((r.true_elevation == 0 && (r.true_azimuth == 0 || std::abs(r.true_azimuth) == 50 ||
                                      std::abs(r.true_azimuth) == 95)) ||
           (r.true_azimuth == 35 && r.true_elevation == 65) ||
           (r.true_azimuth == -110 && r.true_elevation == -20))) {
        char name[96];
        std::snprintf(name, sizeof name, "%s/latlong_yaleB%02d_A%+04dE%+03d.png", plots.c_str(),
                      subject, static_cast<int>(r.true_azimuth),
                      static_cast<int>(r.true_elevation));
        LatLongFigure(name, image, model, estimate, r);
        ++figures;
      }
    }
  }

  std::vector<double> angular, azimuth, elevation, micros, angular_75;
  for (const Result& r : results) {
    angular.push_back(r.angular_error);
    double da = std::fmod(r.azimuth - r.true_azimuth + 540.0, 360.0) - 180.0;
    azimuth.push_back(std::abs(da));
    elevation.push_back(std::abs(r.elevation - r.true_elevation));
    micros.push_back(r.microseconds);
    if (r.angular_error <= 75) angular_75.push_back(r.angular_error);
  }
  std::ofstream json(json_path);
  if (!json) throw fl::FaceLightError(json_path + ": cannot open for writing");
  char buffer[2048];
  std::string subject_list;
  for (int s : subjects) subject_list += (subject_list.empty() ? "" : ", ") + std::to_string(s);
  std::string trained_list;
  for (int s : trained) trained_list += (trained_list.empty() ? "" : ", ") + std::to_string(s);
  std::snprintf(
      buffer, sizeof buffer,
      "{\n  \"model\": \"%s\",\n  \"samples\": %d,\n  \"training_subjects\": [%s],\n"
      "  \"test_subjects\": [%s],\n  \"options\": {\"ridge\": %g, \"back_prior\": %g, "
      "\"robust\": %s, \"robust_threshold\": %g, \"non_negative\": %s, \"weight_floor\": %g, "
      "\"directional_fit\": %s, "
      "\"directional_ambient\": %s, \"direction_bands\": %d, \"head_pose\": \"%s\", "
      "\"landmarks\": \"%s\"},\n"
      "  \"images\": %zu,\n  \"angular_mean_deg\": %.3f,\n  \"angular_median_deg\": %.3f,\n"
      "  \"angular_std_deg\": %.3f,\n  \"angular_mean_deg_below_75\": %.3f,\n"
      "  \"fraction_above_75\": %.4f,\n  \"azimuth_mae_deg\": %.3f,\n  \"azimuth_std_deg\": %.3f,\n"
      "  \"elevation_mae_deg\": %.3f,\n  \"elevation_std_deg\": %.3f,\n"
      "  \"estimate_us_median\": %.3f\n}\n",
      model_path.c_str(), model.SampleCount(), trained_list.c_str(), subject_list.c_str(),
      options.ridge, options.back_prior, options.robust ? "true" : "false",
      options.robust_threshold, options.non_negative ? "true" : "false", options.weight_floor,
      options.directional_fit ? "true" : "false", options.directional_ambient ? "true" : "false",
      options.directional_fit && options.use_direction_rtfs ? model.direction_bands : 0,
      head_pose.c_str(), landmarks.c_str(), results.size(), Mean(angular), Median(angular),
      Std(angular), Mean(angular_75),
      1.0 - static_cast<double>(angular_75.size()) / std::max<size_t>(results.size(), 1),
      Mean(azimuth), Std(azimuth), Mean(elevation), Std(elevation), Median(micros));
  std::string text = buffer;
  if (synthetic) {
    const ColourFigures colour = EvaluateSyntheticColour(yaleb, subjects, model, estimator);
    if (!colour.corrected.empty()) {
      char extra[512];
      std::snprintf(extra, sizeof extra,
                    ",\n  \"rgb_images\": %zu,\n  \"colour_angle_deg_mean\": %.3f,\n"
                    "  \"colour_angle_deg_median\": %.3f,\n"
                    "  \"colour_angle_deg_mean_uncorrected\": %.3f\n}\n",
                    colour.corrected.size(), Mean(colour.corrected), Median(colour.corrected),
                    Mean(colour.uncorrected));
      text = text.substr(0, text.rfind("\n}")) + extra;
    }
  }
  json << text;
  json.close();
  if (!json) throw fl::FaceLightError(json_path + ": write failed");
  std::cout << text;

  if (!plots.empty()) {
    std::vector<std::pair<double, double>> az, el;
    for (const Result& r : results) {
      az.emplace_back(r.true_azimuth, r.azimuth);
      el.emplace_back(r.true_elevation, r.elevation);
    }
    ScatterPlot(plots + "/azimuth.png", "azimuth: estimated vs true (deg)", az, 180);
    ScatterPlot(plots + "/elevation.png", "elevation: estimated vs true (deg)", el, 90);
    std::cerr << "face_light_eval: wrote " << figures + 2 << " PNG files to " << plots << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("face_light_eval", [&] { return Run(argc, argv); });
}
