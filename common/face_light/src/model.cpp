// Face frame helpers, patch sampling and the model file (see probeless/face_light/model.h).
#include "probeless/face_light/model.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "probeless/parse/number.h"
#include "probeless/sh/sh.h"

namespace probeless::face_light {
namespace {

std::string FormatFloat(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.9g", value);
  return buffer;
}

// Line-oriented reader of the model text with error context.
class Reader {
 public:
  Reader(std::string_view text, std::string_view name) : text_(text), name_(name) {}

  [[noreturn]] void Fail(const std::string& problem) const {
    throw FaceLightError(std::string(name_) + ": line " + std::to_string(line_number_) + ": " +
                         problem);
  }

  // Next non-empty, non-comment line split into words; fails at the end of the text.
  std::vector<std::string_view> NextLine(std::string_view expected_what) {
    while (position_ < text_.size()) {
      const size_t end = std::min(text_.find('\n', position_), text_.size());
      std::string_view line = text_.substr(position_, end - position_);
      position_ = end + 1;
      ++line_number_;
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      if (line.empty() || line.front() == '#') continue;
      std::vector<std::string_view> words;
      size_t i = 0;
      while (i < line.size()) {
        while (i < line.size() && line[i] == ' ') ++i;
        const size_t start = i;
        while (i < line.size() && line[i] != ' ') ++i;
        if (i > start) words.push_back(line.substr(start, i - start));
      }
      if (words.empty()) continue;  // a line of spaces is blank (found by face_model_fuzz)
      return words;
    }
    ++line_number_;
    Fail("unexpected end of file, expected " + std::string(expected_what) + " (truncated?)");
  }

  // Next line "<key> <values...>" with exactly `count` values (or at least one if count < 0).
  std::vector<std::string_view> Field(std::string_view key, int count) {
    std::vector<std::string_view> words = NextLine(std::string("'").append(key).append("'"));
    if (words.front() != key) {
      Fail("expected '" + std::string(key) + "', found '" + std::string(words.front()) + "'");
    }
    words.erase(words.begin());
    if (count >= 0 && static_cast<int>(words.size()) != count) {
      Fail(std::string("'").append(key) + "' needs " + std::to_string(count) + " value(s), found " +
           std::to_string(words.size()));
    }
    return words;
  }

  long Integer(std::string_view word, std::string_view what) const {
    long value = 0;
    const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), value);
    if (error != std::errc() || end != word.data() + word.size()) {
      Fail("bad " + std::string(what) + " '" + std::string(word) + "' (expected an integer)");
    }
    return value;
  }

  double Real(std::string_view word, std::string_view what) const {
    // parse::'s rules (strtod also took hexadecimal).
    const auto value = parse::TryParseDouble(word);
    if (!value) {
      Fail("bad " + std::string(what) + " '" + std::string(word) + "' (expected a finite number)");
    }
    return *value;
  }

  int line_number() const { return line_number_; }

 private:
  std::string_view text_;
  std::string_view name_;
  size_t position_ = 0;
  int line_number_ = 0;
};

constexpr std::string_view kFrameName = "yaleb-crop-168x192-normalised";
constexpr std::string_view kLightFrameName = "x=subject-left,y=chin,z=into-head";

}  // namespace

Point2 CropPixelFromNormalised(Point2 uv) {
  return {uv.x * kCropWidth - 0.5, uv.y * kCropHeight - 0.5};
}

Point2 NormalisedFromCropPixel(Point2 pixel) {
  return {(pixel.x + 0.5) / kCropWidth, (pixel.y + 0.5) / kCropHeight};
}

double SimilarityTransform::Scale() const { return std::sqrt(a * a + b * b); }

SimilarityTransform FitSimilarity(std::span<const Point2> from, std::span<const Point2> to) {
  if (from.size() != to.size() || from.size() < 2) {
    throw FaceLightError("FitSimilarity: need the same number (>= 2) of points, got " +
                         std::to_string(from.size()) + " and " + std::to_string(to.size()));
  }
  const double n = static_cast<double>(from.size());
  Point2 mf, mt;
  for (size_t i = 0; i < from.size(); ++i) {
    mf.x += from[i].x / n, mf.y += from[i].y / n;
    mt.x += to[i].x / n, mt.y += to[i].y / n;
  }
  // Closed-form least squares for a = s cos(theta), b = s sin(theta) on centred points.
  double sxx = 0, num_a = 0, num_b = 0;
  for (size_t i = 0; i < from.size(); ++i) {
    const double fx = from[i].x - mf.x, fy = from[i].y - mf.y;
    const double tx = to[i].x - mt.x, ty = to[i].y - mt.y;
    sxx += fx * fx + fy * fy;
    num_a += fx * tx + fy * ty;
    num_b += fx * ty - fy * tx;
  }
  if (!(sxx > 1e-12)) throw FaceLightError("FitSimilarity: source points are all equal");
  SimilarityTransform t;
  t.a = num_a / sxx;
  t.b = num_b / sxx;
  t.tx = mt.x - (t.a * mf.x - t.b * mf.y);
  t.ty = mt.y - (t.b * mf.x + t.a * mf.y);
  return t;
}

void SamplePatches(const uint8_t* image, int width, int height, size_t stride, int channels,
                   const SimilarityTransform& crop_to_image, std::span<const Point2> positions,
                   int patch_radius_px, int saturation_level, std::span<float> values,
                   std::span<uint8_t> valid) {
  if (channels < 1 || channels > 3 || width < 1 || height < 1 ||
      stride < static_cast<size_t>(width) * channels || patch_radius_px < 0) {
    throw FaceLightError("SamplePatches: bad image " + std::to_string(width) + "x" +
                         std::to_string(height) + "x" + std::to_string(channels) + " stride " +
                         std::to_string(stride) + " or patch radius " +
                         std::to_string(patch_radius_px));
  }
  if (values.size() != positions.size() * channels || valid.size() != positions.size()) {
    throw FaceLightError("SamplePatches: " + std::to_string(positions.size()) + " positions need " +
                         std::to_string(positions.size() * channels) + " values and " +
                         std::to_string(positions.size()) + " flags, got " +
                         std::to_string(values.size()) + " and " + std::to_string(valid.size()));
  }
  const int r = static_cast<int>(std::lround(patch_radius_px * crop_to_image.Scale()));
  for (size_t i = 0; i < positions.size(); ++i) {
    const Point2 p = crop_to_image.Apply(CropPixelFromNormalised(positions[i]));
    const long cx = std::lround(p.x), cy = std::lround(p.y);
    bool ok = std::isfinite(p.x) && std::isfinite(p.y) && cx - r >= 0 && cy - r >= 0 &&
              cx + r < width && cy + r < height;
    double sum[3] = {0, 0, 0};
    int count = 0;
    for (long y = std::max<long>(cy - r, 0); y <= std::min<long>(cy + r, height - 1); ++y) {
      for (long x = std::max<long>(cx - r, 0); x <= std::min<long>(cx + r, width - 1); ++x) {
        const uint8_t* pixel = image + y * stride + x * channels;
        for (int c = 0; c < channels; ++c) {
          sum[c] += pixel[c];
          if (pixel[c] >= saturation_level) ok = false;
        }
        ++count;
      }
    }
    for (int c = 0; c < channels; ++c) {
      values[i * channels + c] = count > 0 ? static_cast<float>(sum[c] / count / 255.0) : 0.0f;
    }
    valid[i] = (ok && count > 0) ? 1 : 0;
  }
}

void FaceLightModel::Validate() const {
  const std::string prefix = "face_light model: ";
  if (positions.empty() || positions.size() > kMaxSamples) {
    throw FaceLightError(prefix + std::to_string(positions.size()) + " samples, expected 1..512");
  }
  if (rtf.size() != positions.size() || residual_rms.size() != positions.size()) {
    throw FaceLightError(prefix + "rtf/residual_rms sizes " + std::to_string(rtf.size()) + "/" +
                         std::to_string(residual_rms.size()) + " differ from " +
                         std::to_string(positions.size()) + " positions");
  }
  for (size_t i = 0; i < positions.size(); ++i) {
    const Point2 p = positions[i];
    if (!(p.x >= 0 && p.x <= 1 && p.y >= 0 && p.y <= 1)) {
      throw FaceLightError(prefix + "sample " + std::to_string(i) + " position outside [0, 1]^2");
    }
    for (float t : rtf[i]) {
      if (!std::isfinite(t)) {
        throw FaceLightError(prefix + "sample " + std::to_string(i) + " has a non-finite RTF");
      }
    }
    if (!(residual_rms[i] >= 0 && std::isfinite(residual_rms[i]))) {
      throw FaceLightError(prefix + "sample " + std::to_string(i) + " has a bad residual_rms");
    }
  }
  if (patch_radius_px < 0 || patch_radius_px > 16) {
    throw FaceLightError(prefix + "patch_radius_px " + std::to_string(patch_radius_px) +
                         " out of range 0..16");
  }
  if (!(intensity_exponent > 0 && intensity_exponent <= 2)) {
    throw FaceLightError(prefix + "intensity_exponent must be in (0, 2]");
  }
  if (direction_bands != 0 && direction_bands != 4 && direction_bands != 5) {
    throw FaceLightError(prefix + "direction_bands " + std::to_string(direction_bands) +
                         " must be 0, 4 or 5");
  }
  const size_t direction_values = positions.size() * direction_bands * direction_bands;
  if (direction_rtf.size() != direction_values) {
    throw FaceLightError(prefix + std::to_string(direction_rtf.size()) +
                         " direction RTF values, expected " + std::to_string(direction_values));
  }
  for (float t : direction_rtf) {
    if (!std::isfinite(t)) throw FaceLightError(prefix + "non-finite direction RTF value");
  }
}

std::string SerializeModel(const FaceLightModel& model) {
  model.Validate();
  std::ostringstream out;
  out << FaceLightModel::kMagic << ' ' << FaceLightModel::kFormatVersion << '\n';
  out << "# Knorr & Kurz 2014 radiance transfer functions; see docs/face_light.md\n";
  out << "sh_convention " << sh::kConventionName << '\n';
  out << "sh_bands " << kShBands << '\n';
  out << "direction_bands " << model.direction_bands << '\n';
  out << "frame " << kFrameName << '\n';
  out << "light_frame " << kLightFrameName << '\n';
  out << "patch_box_radius_px " << model.patch_radius_px << '\n';
  out << "intensity_exponent " << FormatFloat(model.intensity_exponent) << '\n';
  out << "albedo " << model.training.albedo << '\n';
  out << "training_subjects";
  for (int s : model.training.subjects) out << ' ' << s;
  out << '\n';
  out << "training_images " << model.training.images << '\n';
  out << "candidates " << model.training.candidates << '\n';
  out << "percentile " << FormatFloat(model.training.percentile) << '\n';
  out << "samples " << model.SampleCount() << '\n';
  const int dn = model.direction_bands * model.direction_bands;
  out << "# sample u v residual_rms t0..t8"
      << (dn > 0 ? " d0..d" + std::to_string(dn - 1) + " (direction RTF)" : std::string()) << '\n';
  for (int i = 0; i < model.SampleCount(); ++i) {
    out << "sample " << FormatFloat(model.positions[i].x) << ' '
        << FormatFloat(model.positions[i].y) << ' ' << FormatFloat(model.residual_rms[i]);
    for (float t : model.rtf[i]) out << ' ' << FormatFloat(t);
    for (int n = 0; n < dn; ++n) out << ' ' << FormatFloat(model.direction_rtf[i * dn + n]);
    out << '\n';
  }
  out << "end\n";
  return out.str();
}

FaceLightModel ParseModel(std::string_view text, std::string_view name) {
  Reader reader(text, name);
  std::vector<std::string_view> words = reader.NextLine("the magic line");
  if (words.front() != FaceLightModel::kMagic) {
    reader.Fail("not a face_light model (expected magic '" + std::string(FaceLightModel::kMagic) +
                "')");
  }
  if (words.size() != 2) reader.Fail("expected '<magic> <version>'");
  const long version = reader.Integer(words[1], "version");
  if (version != 1 && version != FaceLightModel::kFormatVersion) {
    reader.Fail("unsupported version " + std::to_string(version) + " (expected 1 or " +
                std::to_string(FaceLightModel::kFormatVersion) + ")");
  }
  FaceLightModel model;
  if (const auto v = reader.Field("sh_convention", 1); v[0] != sh::kConventionName) {
    reader.Fail("SH convention '" + std::string(v[0]) + "' differs from '" +
                std::string(sh::kConventionName) + "'");
  }
  if (reader.Integer(reader.Field("sh_bands", 1)[0], "sh_bands") != kShBands) {
    reader.Fail("sh_bands must be 3");
  }
  if (version >= 2) {
    const long bands = reader.Integer(reader.Field("direction_bands", 1)[0], "direction_bands");
    if (bands != 0 && bands != 4 && bands != 5) {
      reader.Fail("direction_bands " + std::to_string(bands) + " must be 0, 4 or 5");
    }
    model.direction_bands = static_cast<int>(bands);
  }
  const int dn = model.direction_bands * model.direction_bands;
  if (const auto v = reader.Field("frame", 1); v[0] != kFrameName) {
    reader.Fail("frame '" + std::string(v[0]) + "' differs from '" + std::string(kFrameName) + "'");
  }
  if (const auto v = reader.Field("light_frame", 1); v[0] != kLightFrameName) {
    reader.Fail("light_frame '" + std::string(v[0]) + "' differs from '" +
                std::string(kLightFrameName) + "'");
  }
  model.patch_radius_px = static_cast<int>(
      reader.Integer(reader.Field("patch_box_radius_px", 1)[0], "patch_box_radius_px"));
  if (model.patch_radius_px < 0 || model.patch_radius_px > 16) {
    reader.Fail("patch_box_radius_px " + std::to_string(model.patch_radius_px) +
                " out of range 0..16");
  }
  model.intensity_exponent =
      reader.Real(reader.Field("intensity_exponent", 1)[0], "intensity_exponent");
  if (!(model.intensity_exponent > 0 && model.intensity_exponent <= 2)) {
    reader.Fail("intensity_exponent must be in (0, 2]");
  }
  model.training.albedo = std::string(reader.Field("albedo", 1)[0]);
  for (std::string_view word : reader.Field("training_subjects", -1)) {
    model.training.subjects.push_back(static_cast<int>(reader.Integer(word, "subject")));
  }
  model.training.images =
      static_cast<int>(reader.Integer(reader.Field("training_images", 1)[0], "training_images"));
  model.training.candidates =
      static_cast<int>(reader.Integer(reader.Field("candidates", 1)[0], "candidates"));
  model.training.percentile = reader.Real(reader.Field("percentile", 1)[0], "percentile");
  const long samples = reader.Integer(reader.Field("samples", 1)[0], "samples");
  if (samples < 1 || samples > kMaxSamples) {
    reader.Fail("samples " + std::to_string(samples) + " out of range 1..512");
  }
  for (long i = 0; i < samples; ++i) {
    const std::vector<std::string_view> v = reader.Field("sample", 3 + kRtfCoefficients + dn);
    const Point2 p{reader.Real(v[0], "u"), reader.Real(v[1], "v")};
    if (!(p.x >= 0 && p.x <= 1 && p.y >= 0 && p.y <= 1)) {
      reader.Fail("sample position outside [0, 1]^2");
    }
    const double residual = reader.Real(v[2], "residual_rms");
    if (residual < 0) reader.Fail("negative residual_rms");
    std::array<float, kRtfCoefficients> t{};
    for (int n = 0; n < kRtfCoefficients; ++n) {
      t[n] = static_cast<float>(reader.Real(v[3 + n], "RTF coefficient"));
    }
    model.positions.push_back(p);
    model.residual_rms.push_back(static_cast<float>(residual));
    model.rtf.push_back(t);
    for (int n = 0; n < dn; ++n) {
      model.direction_rtf.push_back(static_cast<float>(
          reader.Real(v[3 + kRtfCoefficients + n], "direction RTF coefficient")));
    }
  }
  reader.Field("end", 0);
  model.Validate();
  return model;
}

void SaveModel(const FaceLightModel& model, const std::string& path) {
  const std::string text = SerializeModel(model);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw FaceLightError(path + ": cannot open for writing");
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.close();
  if (!out) throw FaceLightError(path + ": write failed");
}

FaceLightModel LoadModel(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FaceLightError(path + ": cannot open model file");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) throw FaceLightError(path + ": read failed");
  return ParseModel(buffer.str(), path);
}

}  // namespace probeless::face_light
