// RTF training (Knorr & Kurz 2014, sec. 3.4, eq. 18) and sample selection (sec. 6).
#include "probeless/face_light/training.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>

#include "linalg.h"
#include "probeless/face_light/yaleb.h"
#include "probeless/sh/sh.h"

namespace probeless::face_light {
namespace {

bool InsideEllipse(double x, double y, double cx, double cy, double ax, double ay) {
  const double dx = (x - cx) / ax, dy = (y - cy) / ay;
  return dx * dx + dy * dy <= 1;
}

void CheckImages(std::span<const TrainingImage> images) {
  if (images.empty()) throw FaceLightError("face_light training: no training images");
  const size_t count = images.front().values.size();
  for (const TrainingImage& image : images) {
    if (image.values.size() != count || image.valid.size() != count) {
      throw FaceLightError("face_light training: subject " + std::to_string(image.subject) +
                           " image has " + std::to_string(image.values.size()) + " values/" +
                           std::to_string(image.valid.size()) + " flags, expected " +
                           std::to_string(count));
    }
  }
}

double Response(double value, double exponent) {
  return exponent == 1 ? value : std::pow(std::max(value, 0.0), exponent);
}

std::vector<double> InverseAlbedos(std::span<const TrainingImage> images);

}  // namespace

std::vector<Point2> CandidatePositions(double step_px) {
  if (!(step_px >= 2 && step_px <= 40)) {
    throw FaceLightError("CandidatePositions: step_px " + std::to_string(step_px) +
                         " out of range 2..40");
  }
  const int nx = static_cast<int>(std::floor((kCropWidth - 1) / step_px)) + 1;
  const int ny = static_cast<int>(std::floor((kCropHeight - 1) / step_px)) + 1;
  const double x0 = (kCropWidth - 1 - (nx - 1) * step_px) / 2;
  const double y0 = (kCropHeight - 1 - (ny - 1) * step_px) / 2;
  std::vector<Point2> out;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const double x = x0 + i * step_px, y = y0 + j * step_px;
      if (!InsideEllipse(x, y, 83.5, 100, 80, 96) || y < 8 || y > 183) continue;
      if (InsideEllipse(x, y, kCanonicalRightEye.x, kCanonicalRightEye.y - 4, 24, 17)) continue;
      if (InsideEllipse(x, y, kCanonicalLeftEye.x, kCanonicalLeftEye.y - 4, 24, 17)) continue;
      if (InsideEllipse(x, y, kCanonicalMouth.x, kCanonicalMouth.y, 26, 9)) continue;
      out.push_back(NormalisedFromCropPixel({x, y}));
    }
  }
  return out;
}

double PersonAlbedo(std::span<const TrainingImage> images, int subject) {
  for (const TrainingImage& image : images) {
    if (image.subject != subject || image.azimuth_deg != 0 || image.elevation_deg != 0) continue;
    std::vector<float> values;
    for (size_t j = 0; j < image.values.size(); ++j) {
      if (image.valid[j]) values.push_back(image.values[j]);
    }
    if (values.empty()) {
      throw FaceLightError("face_light training: subject " + std::to_string(subject) +
                           " frontal-lit image has no valid sample");
    }
    const size_t mid = values.size() / 2;
    std::nth_element(values.begin(), values.begin() + mid, values.end());
    double median = values[mid];
    if (values.size() % 2 == 0) {
      median = (median + *std::max_element(values.begin(), values.begin() + mid)) / 2;
    }
    if (!(median > 0)) {
      throw FaceLightError("face_light training: subject " + std::to_string(subject) +
                           " frontal-lit median intensity is not positive");
    }
    return median;
  }
  throw FaceLightError("face_light training: subject " + std::to_string(subject) +
                       " has no frontal-lit image (azimuth 0, elevation 0)");
}

namespace {
std::vector<double> InverseAlbedos(std::span<const TrainingImage> images) {
  std::set<int> subjects;
  for (const TrainingImage& image : images) subjects.insert(image.subject);
  std::vector<double> inverse_albedo(images.size());
  std::vector<std::pair<int, double>> albedo;
  for (int s : subjects) albedo.emplace_back(s, 1.0 / PersonAlbedo(images, s));
  for (size_t i = 0; i < images.size(); ++i) {
    for (const auto& [s, a] : albedo) {
      if (s == images[i].subject) inverse_albedo[i] = a;
    }
  }
  return inverse_albedo;
}
}  // namespace

std::vector<double> FitDirectionRtfs(std::span<const TrainingImage> images,
                                     std::span<const int> which, int bands,
                                     double intensity_exponent, double ridge) {
  CheckImages(images);
  if (bands < 1 || bands > 5 || !(ridge >= 0)) {
    throw FaceLightError("face_light training: direction RTF bands must be 1..5, ridge >= 0");
  }
  const int n = bands * bands;
  const std::vector<double> inverse_albedo = InverseAlbedos(images);
  std::vector<double> basis(images.size() * n);
  for (size_t i = 0; i < images.size(); ++i) {
    const std::array<double, 3> d =
        YaleBLightDirection(images[i].azimuth_deg, images[i].elevation_deg);
    sh::EvaluateBasis<double>(bands, d[0], d[1], d[2], &basis[i * n]);
  }
  std::vector<double> out(which.size() * n);
  std::vector<double> normal(static_cast<size_t>(n) * n);
  for (size_t k = 0; k < which.size(); ++k) {
    const size_t j = static_cast<size_t>(which[k]);
    if (j >= images.front().values.size()) {
      throw FaceLightError("face_light training: candidate index out of range");
    }
    std::fill(normal.begin(), normal.end(), 0.0);
    double* rhs = &out[k * n];
    int equations = 0;
    for (size_t i = 0; i < images.size(); ++i) {
      if (!images[i].valid[j]) continue;
      const double value = Response(images[i].values[j] * inverse_albedo[i], intensity_exponent);
      const double* y = &basis[i * n];
      for (int a = 0; a < n; ++a) {
        rhs[a] += y[a] * value;
        for (int b = 0; b <= a; ++b) normal[a * n + b] += y[a] * y[b];
      }
      ++equations;
    }
    double trace = 0;
    for (int a = 0; a < n; ++a) trace += normal[a * n + a];
    for (int a = 0; a < n; ++a) normal[a * n + a] += ridge * trace / n;
    if (equations < 1 || !internal::CholeskyN(normal.data(), n)) {
      throw FaceLightError("face_light training: candidate " + std::to_string(j) +
                           " has no unique " + std::to_string(bands) +
                           "-band direction RTF (raise the direction ridge)");
    }
    internal::CholeskySolveN(normal.data(), n, rhs);
  }
  return out;
}

std::vector<std::array<double, kRtfCoefficients>> FitRtfs(std::span<const TrainingImage> images,
                                                          std::vector<float>* residual_rms,
                                                          double intensity_exponent) {
  CheckImages(images);
  const size_t candidates = images.front().values.size();
  const std::vector<double> inverse_albedo = InverseAlbedos(images);
  std::vector<std::array<double, kRtfCoefficients>> basis(images.size());
  for (size_t i = 0; i < images.size(); ++i) {
    const std::array<double, 3> d =
        YaleBLightDirection(images[i].azimuth_deg, images[i].elevation_deg);
    basis[i] = sh::Basis9(d);  // E_k = Y(w_k), eq. 14
  }
  std::vector<std::array<double, kRtfCoefficients>> rtfs(candidates);
  if (residual_rms) residual_rms->assign(candidates, 0.0f);
  for (size_t j = 0; j < candidates; ++j) {
    // Normal equations of eq. 18 for candidate j over every valid (image, value).
    std::array<double, 81> normal{};
    std::array<double, 9> rhs{};
    int equations = 0;
    for (size_t i = 0; i < images.size(); ++i) {
      if (!images[i].valid[j]) continue;
      const double value = Response(images[i].values[j] * inverse_albedo[i], intensity_exponent);
      const std::array<double, 9>& y = basis[i];
      for (int a = 0; a < 9; ++a) {
        rhs[a] += y[a] * value;
        for (int b = 0; b <= a; ++b) normal[a * 9 + b] += y[a] * y[b];
      }
      ++equations;
    }
    if (equations < kRtfCoefficients || !internal::Cholesky<9>(normal)) {
      throw FaceLightError("face_light training: candidate " + std::to_string(j) + " has " +
                           std::to_string(equations) +
                           " valid equations and no unique RTF (need 9 independent lights)");
    }
    internal::CholeskySolve<9>(normal, rhs.data());
    rtfs[j] = rhs;
    if (residual_rms) {
      double sum = 0;
      for (size_t i = 0; i < images.size(); ++i) {
        if (!images[i].valid[j]) continue;
        double predicted = 0;
        for (int a = 0; a < 9; ++a) predicted += basis[i][a] * rhs[a];
        const double r =
            Response(images[i].values[j] * inverse_albedo[i], intensity_exponent) - predicted;
        sum += r * r;
      }
      (*residual_rms)[j] = static_cast<float>(std::sqrt(sum / equations));
    }
  }
  return rtfs;
}

std::vector<int> SelectSamples(std::span<const std::array<double, kRtfCoefficients>> rtfs,
                               const TrainingOptions& options, double* applied_percentile) {
  const int count = static_cast<int>(rtfs.size());
  // score[j] = max over n of the rank of |T_jn| among all candidates, as a fraction in [0, 1).
  std::vector<double> score(count, 0.0);
  std::vector<int> order(count);
  for (int n = 0; n < kRtfCoefficients; ++n) {
    for (int j = 0; j < count; ++j) order[j] = j;
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int b) { return std::abs(rtfs[a][n]) < std::abs(rtfs[b][n]); });
    for (int rank = 0; rank < count; ++rank) {
      score[order[rank]] = std::max(score[order[rank]], static_cast<double>(rank) / count);
    }
  }
  std::vector<int> selected;
  if (options.points > 0) {
    for (int j = 0; j < count; ++j) order[j] = j;
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return score[a] > score[b]; });
    selected.assign(order.begin(), order.begin() + std::min(options.points, count));
    double lowest = 1;
    for (int j : selected) lowest = std::min(lowest, score[j]);
    if (applied_percentile) *applied_percentile = 100 * lowest;
    std::sort(selected.begin(), selected.end());
  } else {
    for (int j = 0; j < count; ++j) {
      if (score[j] >= options.percentile / 100) selected.push_back(j);
    }
    if (applied_percentile) *applied_percentile = options.percentile;
  }
  return selected;
}

FaceLightModel Train(std::span<const Point2> candidates, std::span<const TrainingImage> images,
                     const TrainingOptions& options, const std::function<void(double)>& progress) {
  if (!(options.percentile >= 0 && options.percentile < 100) || options.points < 0 ||
      options.points > kMaxSamples || options.patch_radius_px < 0 || options.patch_radius_px > 16 ||
      (options.direction_bands != 0 && options.direction_bands != 4 &&
       options.direction_bands != 5) ||
      !(options.direction_ridge >= 0)) {
    throw FaceLightError(
        "face_light training: options out of range (percentile 0..<100, points "
        "0..512, patch radius 0..16, intensity exponent (0, 2], direction bands 0/4/5, "
        "direction ridge >= 0)");
  }
  CheckImages(images);
  if (images.front().values.size() != candidates.size()) {
    throw FaceLightError("face_light training: images have " +
                         std::to_string(images.front().values.size()) + " values but there are " +
                         std::to_string(candidates.size()) + " candidates");
  }
  if (progress) progress(0.0);
  std::vector<float> residuals;
  const std::vector<std::array<double, kRtfCoefficients>> rtfs =
      FitRtfs(images, &residuals, options.intensity_exponent);
  if (progress) progress(0.8);
  double applied = options.percentile;
  const std::vector<int> selected = SelectSamples(rtfs, options, &applied);
  if (selected.empty() || selected.size() > static_cast<size_t>(kMaxSamples)) {
    throw FaceLightError("face_light training: " + std::to_string(selected.size()) +
                         " samples selected, expected 1..512 (adjust --percentile or --points)");
  }
  FaceLightModel model;
  model.patch_radius_px = options.patch_radius_px;
  model.intensity_exponent = options.intensity_exponent;
  for (int j : selected) {
    model.positions.push_back(candidates[j]);
    std::array<float, kRtfCoefficients> t{};
    for (int n = 0; n < kRtfCoefficients; ++n) t[n] = static_cast<float>(rtfs[j][n]);
    model.rtf.push_back(t);
    model.residual_rms.push_back(residuals[j]);
  }
  if (options.direction_bands > 0) {
    const std::vector<double> d = FitDirectionRtfs(images, selected, options.direction_bands,
                                                   options.intensity_exponent,
                                                   options.direction_ridge);
    model.direction_bands = options.direction_bands;
    model.direction_rtf.assign(d.begin(), d.end());
  }
  std::set<int> subjects;
  for (const TrainingImage& image : images) subjects.insert(image.subject);
  model.training.subjects.assign(subjects.begin(), subjects.end());
  model.training.images = static_cast<int>(images.size());
  model.training.candidates = static_cast<int>(candidates.size());
  model.training.percentile = applied;
  model.Validate();
  if (progress) progress(1.0);
  return model;
}

}  // namespace probeless::face_light
