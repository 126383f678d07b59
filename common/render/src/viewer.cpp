#include "probeless/render/viewer.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/imgproc.hpp>

#include "probeless/raytrace/render.h"
#include "probeless/sh/sh.h"

namespace probeless::render {

namespace {

Panel Blank(int w, int h) {
  Panel p;
  p.width = w;
  p.height = h;
  p.rgb.assign(static_cast<size_t>(w) * h * 3, 40);
  return p;
}

uint8_t Encode(const ToneMapping& tone, float x) { return raytrace::LinearToSrgb8(tone.Apply(x)); }

}  // namespace

void ViewerState::ApplyKeys(const std::vector<int>& keys) {
  for (int k : keys) {
    switch (k) {
      case 'L':
        light_sphere = !light_sphere;
        break;
      case 'M':
        latlong = !latlong;
        break;
      case 'F':
        face_samples = !face_samples;
        break;
      case 'G':
        geometry = !geometry;
        break;
      case 'P':
        pose = !pose;
        break;
      case 'H': {
        const bool any = light_sphere || latlong || face_samples || geometry || pose;
        light_sphere = latlong = face_samples = geometry = pose = !any;
        break;
      }
      case 'Q':
      case 256:
        quit = true;
        break;
      default:
        break;
    }
  }
}

Panel LightSpherePanel(const ShLightRgb& light, const ToneMapping& tone, int size) {
  Panel p = Blank(size, size);
  const int count = light.bands * light.bands;
  std::vector<double> y(static_cast<size_t>(count));
  for (int v = 0; v < size; ++v) {
    for (int u = 0; u < size; ++u) {
      const double x = (u + 0.5) / size * 2 - 1, yy = (v + 0.5) / size * 2 - 1;
      const double r2 = x * x + yy * yy;
      if (r2 > 1) continue;
      // Camera frame: the visible hemisphere faces the camera (-z).
      sh::EvaluateBasis<double>(light.bands, x, yy, -std::sqrt(1 - r2), y.data());
      for (int c = 0; c < 3; ++c) {
        double e = 0;
        for (int k = 0; k < count; ++k) {
          e += sh::ClampedCosineCoefficient(sh::DegreeOf(k)) * light.coefficients[k][c] * y[k];
        }
        p.rgb[(static_cast<size_t>(v) * size + u) * 3 + c] =
            Encode(tone, static_cast<float>(e / std::numbers::pi));
      }
    }
  }
  return p;
}

Panel LatLongPanel(const ShLightRgb& light, const ToneMapping& tone, int width) {
  const int height = std::max(1, width / 2);
  Panel p = Blank(width, height);
  const int count = light.bands * light.bands;
  std::vector<float> coefficients(static_cast<size_t>(count) * 3);
  for (int k = 0; k < count; ++k) {
    for (int c = 0; c < 3; ++c) coefficients[k * 3 + c] = light.coefficients[k][c];
  }
  std::vector<float> image(static_cast<size_t>(width) * height * 3);
  sh::RenderLatLong(coefficients, light.bands, 3, width, height, image);
  for (size_t i = 0; i < image.size(); ++i) p.rgb[i] = Encode(tone, image[i]);
  return p;
}

Panel FaceSamplesPanel(const msgs::FaceObservation& face, int size) {
  Panel p = Blank(size, size);
  cv::Mat view(size, size, CV_8UC3, p.rgb.data());
  cv::circle(view, {size / 2, size / 2}, size / 2 - 2, cv::Scalar(90, 90, 90), 1);
  if (!face.face_detected) return p;
  const uint32_t n = std::min(face.sample_count, msgs::kMaxFaceSamples);
  for (uint32_t i = 0; i < n; ++i) {
    if (!face.SampleValid(i)) continue;
    const float* normal = face.sample_normals[i];
    const int u = static_cast<int>((normal[0] * 0.5f + 0.5f) * (size - 4)) + 2;
    const int v = static_cast<int>((normal[1] * 0.5f + 0.5f) * (size - 4)) + 2;
    cv::circle(view, {u, v}, std::max(2, size / 80),
               cv::Scalar(raytrace::LinearToSrgb8(face.sample_rgb[i][0]),
                          raytrace::LinearToSrgb8(face.sample_rgb[i][1]),
                          raytrace::LinearToSrgb8(face.sample_rgb[i][2])),
               cv::FILLED);
  }
  return p;
}

Panel GeometryPanel(int width, int height, std::span<const float> depth,
                    std::span<const float> normals, int panel_width) {
  if (width < 1 || height < 1 || depth.size() != static_cast<size_t>(width) * height ||
      normals.size() != depth.size() * 3) {
    return Blank(panel_width, std::max(1, panel_width * 3 / 4));
  }
  const int ph = std::max(1, panel_width * height / width);
  Panel p = Blank(panel_width, ph);
  for (int v = 0; v < ph; ++v) {
    const int y = std::min(height - 1, v * height / ph);
    for (int u = 0; u < panel_width; ++u) {
      const int x = std::min(width - 1, u * width / panel_width);
      const size_t i = static_cast<size_t>(y) * width + x;
      uint8_t* out = p.rgb.data() + (static_cast<size_t>(v) * panel_width + u) * 3;
      if (!(depth[i] > 0)) {
        out[0] = out[1] = out[2] = 0;
        continue;
      }
      for (int c = 0; c < 3; ++c) {
        out[c] =
            static_cast<uint8_t>(std::clamp(normals[i * 3 + c] * 0.5f + 0.5f, 0.0f, 1.0f) * 255);
      }
    }
  }
  return p;
}

Panel PosePanel(const msgs::FaceObservation& face, int size) {
  Panel p = Blank(size, size);
  if (!face.face_detected) return p;
  cv::Mat view(size, size, CV_8UC3, p.rgb.data());
  const msgs::Quaternion& q = face.head_pose.rotation;
  const raytrace::Mat3 r = raytrace::Mat3::FromQuaternion(q.w, q.x, q.y, q.z);
  const cv::Point centre(size / 2, size / 2);
  const cv::Scalar colours[3] = {{255, 60, 60}, {60, 255, 60}, {80, 80, 255}};
  for (int axis = 0; axis < 3; ++axis) {
    // The axis direction in the camera frame, drawn orthographically (x right, y down).
    const double dx = r.m[0][axis], dy = r.m[1][axis];
    const cv::Point tip(centre.x + static_cast<int>(dx * size * 0.4),
                        centre.y + static_cast<int>(dy * size * 0.4));
    cv::line(view, centre, tip, colours[axis], 2);
  }
  char text[64];
  std::snprintf(text, sizeof(text), "t %.2f %.2f %.2f", face.head_pose.translation.x,
                face.head_pose.translation.y, face.head_pose.translation.z);
  cv::putText(view, text, {4, size - 6}, cv::FONT_HERSHEY_PLAIN, 0.8, cv::Scalar(230, 230, 230));
  return p;
}

std::vector<Panel> MakePanels(const ViewerState& state, const ViewerInputs& in, int window_width,
                              int window_height) {
  std::vector<Panel> panels;
  const int size = std::max(32, std::min(window_width, window_height) / 4);
  int y = 4;
  auto place = [&](Panel p) {
    p.w = size;
    p.h = std::max(1, size * p.height / std::max(1, p.width));
    p.x = window_width - size - 4;
    p.y = y;
    y += p.h + 4;
    panels.push_back(std::move(p));
  };
  if (state.light_sphere)
    place(in.light ? LightSpherePanel(*in.light, in.tone, 96) : Blank(96, 96));
  if (state.latlong) place(in.light ? LatLongPanel(*in.light, in.tone, 128) : Blank(128, 64));
  if (state.face_samples) place(in.face ? FaceSamplesPanel(*in.face, 128) : Blank(128, 128));
  if (state.geometry) {
    place(GeometryPanel(in.geometry_width, in.geometry_height, in.geometry_depth,
                        in.geometry_normals, 160));
  }
  if (state.pose) place(in.face ? PosePanel(*in.face, 128) : Blank(128, 128));
  return panels;
}

}  // namespace probeless::render
