// Dataset folders as Sources: Microsoft 7-Scenes, TUM RGB-D, Extended Yale Face Database B, a
// folder of images and a video file. Which topics each kind produces, with units and frames, is in
// docs/dataset.md. MCAP logs ("mcap") are opened by the MCAP source, not here.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "probeless/dataset/source.h"

namespace probeless::dataset {

// How a dataset folder is turned into a stream. Every field has a usable default.
struct DatasetOptions {
  // Frame rate in frames per second of sources without their own timestamps (7scenes, yaleb,
  // images; video when the file does not state its rate): frame i has log time i / fps. > 0.
  double fps = 30;
  // Optional camera calibration overriding the dataset's own or default intrinsics: a ROS
  // camera_info YAML file (camera_calibration / camera_info_manager format) or an OpenCV
  // FileStorage YAML/XML file (camera_matrix|cameraMatrix|K, distortion_coefficients|distCoeffs|D,
  // image_width, image_height). Empty = none. Its image size, when given, must match the images.
  std::string camera_info_path;
  // Topics of the camera: <topic_prefix>/image, /depth, /camera_info. Absolute, no trailing '/'.
  std::string topic_prefix = "/camera";
  // Topics of the ground truth: <ground_truth_prefix>/pose, /light. Absolute, no trailing '/'.
  std::string ground_truth_prefix = "/groundtruth";
  // At most this many frames (an image with its depth, camera info and ground truth) per pass;
  // 0 = all.
  uint64_t max_frames = 0;
  // Extended Yale B only: the subject numbers to play (e.g. {1, 5} for yaleB01 and yaleB05), in
  // the order of the subjects' numbers whatever the order here; empty = every subject found.
  // A subject that is not in the folder is an error.
  std::vector<int> yaleb_subjects;
  // frame_id of images, camera info and light (the camera optical frame: x right, y down,
  // z forward) and the child frame of ground-truth camera poses. At most 31 characters.
  std::string camera_frame_id = "camera";
  // Parent frame of ground-truth camera poses. At most 31 characters.
  std::string world_frame_id = "world";
  // 7-Scenes only: resample each 640x480 colour image onto the depth image's pixel grid (bilinear,
  // per-pixel parallax from the depth; holes at the frame's median depth) so that /camera/image is
  // registered to /camera/depth, the convention of probeless cameras. 7-Scenes publishes no colour
  // calibration: the colour camera is the Kinect v1's nominal one (fx = fy = 525 px, principal
  // point (320, 240), 2.5 cm from the depth camera along x; docs/dataset.md shows the check).
  // false, frames of another size, or a folder without depth files: the colour files as they are.
  bool register_colour = true;
};

// The dataset kinds OpenDataset accepts in "kind:PATH", in the order auto-detection tries them:
// "tum", "7scenes", "yaleb", "images", "video".
const std::vector<std::string>& DatasetKinds();

// The kind of the dataset at `path` (a folder or a file), by these rules in order:
//   a file named *.mcap                                  -> "mcap" (not opened by OpenDataset)
//   a file named *.avi|mp4|mkv|mov|webm|m4v|mpg|mpeg|wmv -> "video"
//   a folder with rgb.txt and depth.txt                  -> "tum"
//   a folder with frame-XXXXXX.color.jpg|png files       -> "7scenes"
//   a folder with yaleBxx_P00A±aaaE±ee.pgm files, or with yaleBxx/ sub-folders holding them
//                                                        -> "yaleb"
//   a folder with png|jpg|jpeg|pgm|ppm|bmp files         -> "images"
// Throws DatasetError if the path does not exist or nothing matches (listing what was looked for).
std::string DetectDatasetKind(const std::string& path);

// Opens `spec`: "PATH" (kind detected by DetectDatasetKind) or "KIND:PATH" with KIND one of
// DatasetKinds(). Checks the folder's structure, lists its frames and reads the first image (for
// the exact message sizes of topics()); every other file is read lazily in Next(). Throws
// DatasetError for an unknown kind, an "mcap" spec or path (use the MCAP source), invalid options,
// or a missing or malformed file (naming it and what was expected).
std::unique_ptr<Source> OpenDataset(const std::string& spec, const DatasetOptions& options = {});

}  // namespace probeless::dataset
