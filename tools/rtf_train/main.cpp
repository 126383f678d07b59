// rtf_train: trains the Knorr & Kurz (2014) radiance transfer functions on Extended Yale B crops
// and writes a face_light model file (docs/face_light.md).
//
//   rtf_train --yaleb DIR | --synthetic DIR [--subjects LIST] [--points N] [--percentile P]
//             [--patch-radius R]
//             [--intensity-exponent G] [--grid-step PX] [--direction-bands B]
//             [--direction-ridge X] [--align none|tracker] --out MODEL
//
// Progress goes to stderr; errors are one line on stderr (node::RunMain: exit code 2 for bad input,
// 1 otherwise).
#include "probeless/node/main.h"

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "probeless/face_light/model.h"
#include "probeless/face_light/training.h"
#include "probeless/face_light/yaleb.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/sampling.h"
#include "probeless/node/flags.h"
#include "probeless/parse/number.h"

namespace fl = probeless::face_light;
namespace ft = probeless::face_track;

namespace {

constexpr const char* kDescription =
    "trains the Knorr & Kurz (2014) radiance transfer functions on Extended Yale B crops and\n"
    "writes a face_light model file (docs/face_light.md); --yaleb (or --synthetic) and --out are\n"
    "required.";

bool progress_open = false;  // a progress bar is drawn and its line not yet ended

void Progress(const std::string& label, double fraction) {
  constexpr int kWidth = 40;
  const int filled = static_cast<int>(fraction * kWidth + 0.5);
  std::fprintf(stderr, "\r%-28s [%s%s] %3d%%", label.c_str(), std::string(filled, '#').c_str(),
               std::string(kWidth - filled, '.').c_str(), static_cast<int>(fraction * 100 + 0.5));
  progress_open = fraction < 1;
  if (fraction >= 1) std::fputc('\n', stderr);
  std::fflush(stderr);
}

int Run(int argc, char** argv) {
  std::string yaleb, out, subjects_text;
  fl::TrainingOptions options;
  options.intensity_exponent = 0.5;
  options.percentile = 0;       // keep every candidate (512): best for the directional fit
  options.direction_bands = 5;  // direction RTFs, bands 0..4 (docs/face_light.md)
  double grid_step = 6.42;
  std::string align = "none";
  probeless::node::FlagParser flags("rtf_train", kDescription);
  flags.Add("--yaleb", &yaleb, "DIR", "Extended Yale B cropped folder (yaleBxx/ sub-folders)");
  flags.Add("--synthetic", &yaleb, "DIR",
            "a Yale-B-style folder from `sim --yaleb-style` (same layout; the .pgm images are "
            "used, .ppm colour images are ignored)");
  flags.Add("--subjects", &subjects_text, "LIST",
            "training subjects, e.g. 1-28 or 1,3,5-7 (default: all in DIR)");
  flags.AddTruncatedInt("--points", &options.points, "N",
                        "keep exactly N samples (0: use --percentile)");
  flags.Add("--percentile", &options.percentile, "P",
            "keep candidates above the P-th percentile of |RTF coefficient| for at least one "
            "coefficient (0 = every candidate; the paper's 90 keeps ~300 of 512)");
  flags.AddTruncatedInt("--patch-radius", &options.patch_radius_px, "R",
                        "box patch half size in crop pixels (2: 5x5)");
  flags.Add("--intensity-exponent", &options.intensity_exponent, "G",
            "response exponent of the RTF fit (1 = the paper)");
  flags.Add("--grid-step", &grid_step, "PX",
            "candidate grid step in crop pixels (6.42: 512 candidates)");
  flags.AddTruncatedInt(
      "--direction-bands", &options.direction_bands, "B",
      "also fit B-band direction RTFs for the directional fit (0 = none, 4 or 5)");
  flags.Add("--direction-ridge", &options.direction_ridge, "X",
            "Tikhonov weight of the direction RTF fit");
  flags.Add("--align", &align, "none|tracker",
            "sample each subject on the crop as it is (none) or mapped onto the face tracker's "
            "landmarks on its frontal-lit image, as the pipeline samples (tracker)");
  flags.Add("--out", &out, "MODEL", "model file to write");
  if (!flags.Parse(argc, argv)) return 0;
  if (yaleb.empty() || out.empty()) {
    throw probeless::node::UsageError(
        "--yaleb (or --synthetic) and --out are required (see --help)");
  }
  const std::vector<int> available = fl::ListYaleBSubjects(yaleb);
  std::vector<int> subjects;
  if (subjects_text.empty()) {
    subjects = available;
  } else {
    for (int s : fl::ParseSubjectList(subjects_text)) {
      if (std::find(available.begin(), available.end(), s) != available.end()) {
        subjects.push_back(s);
      } else {
        std::cerr << "rtf_train: note: subject " << s << " is not in " << yaleb << ", skipped\n";
      }
    }
  }
  if (subjects.empty()) throw fl::FaceLightError(yaleb + ": no training subject found");
  if (align != "none" && align != "tracker") {
    throw fl::FaceLightError("--align '" + align + "' is not supported (none or tracker)");
  }
  std::optional<ft::FaceTracker> tracker;
  if (align == "tracker") {
    ft::TrackerOptions tracker_options;
    tracker_options.clahe_clip_limit = 0;  // evenly lit crops: more accurate landmarks without
    tracker.emplace(tracker_options);
  }

  const std::vector<fl::Point2> candidates = fl::CandidatePositions(grid_step);
  std::vector<fl::TrainingImage> images;
  for (size_t s = 0; s < subjects.size(); ++s) {
    Progress("loading subjects", static_cast<double>(s) / subjects.size());
    const std::vector<fl::YaleBImage> loaded = fl::LoadYaleBSubject(yaleb, subjects[s]);
    // --align tracker: the canonical crop -> image similarity of the landmarks the face tracker
    // finds on the frontal-lit image (what FaceSampler does live), for all of the subject's images.
    fl::SimilarityTransform crop_to_image;
    if (tracker) {
      bool found = false;
      for (const fl::YaleBImage& image : loaded) {
        if (image.name.azimuth_deg != 0 || image.name.elevation_deg != 0) continue;
        const ft::ImageView view{image.pixels.data(), image.width, image.height,
                                 static_cast<size_t>(image.width), ft::PixelFormat::kGray};
        const ft::FaceTrack t = tracker->DetectOnce(
            view, ft::Intrinsics{1050, 1050, (image.width - 1) / 2.0, (image.height - 1) / 2.0});
        if (t.found) crop_to_image = ft::CanonicalToImage(t.landmarks), found = true;
      }
      if (!found) {
        std::fprintf(stderr,
                     "\nrtf_train: note: no face found on subject %d's frontal image, "
                     "sampled on the crop as it is\n",
                     subjects[s]);
      }
    }
    for (const fl::YaleBImage& image : loaded) {
      fl::TrainingImage sample;
      sample.subject = image.name.subject;
      sample.azimuth_deg = image.name.azimuth_deg;
      sample.elevation_deg = image.name.elevation_deg;
      sample.values.resize(candidates.size());
      sample.valid.resize(candidates.size());
      fl::SamplePatches(image.pixels.data(), image.width, image.height, image.width, 1,
                        crop_to_image, candidates, options.patch_radius_px, 255, sample.values,
                        sample.valid);
      images.push_back(std::move(sample));
    }
  }
  Progress("loading subjects", 1.0);
  const fl::FaceLightModel model = fl::Train(candidates, images, options, [](double fraction) {
    Progress("fitting RTFs (eq. 18)", fraction);
  });
  fl::SaveModel(model, out);
  std::fprintf(stderr,
               "rtf_train: %d subjects, %d images, %d candidates -> %d samples (percentile %.2f), "
               "wrote %s\n",
               static_cast<int>(model.training.subjects.size()), model.training.images,
               model.training.candidates, model.SampleCount(), model.training.percentile,
               out.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("rtf_train", [&] {
    try {
      return Run(argc, argv);
    } catch (...) {
      if (progress_open) std::fputc('\n', stderr);  // the bar is drawn with \r: end its line
      throw;
    }
  });
}
