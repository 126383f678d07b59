// probeless.log (MCAP reading through log::McapReader and the ROS 2 converters) and the estimators
// on arrays: face_light::FaceLightEstimator / LinearLightConverter and light::ScenePipeline, the
// library objects the face_light and scene_light nodes run.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/linear_light.h"
#include "probeless/face_light/model.h"
#include "probeless/light/directions.h"
#include "probeless/light/messages.h"
#include "probeless/light/pipeline.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"
#include "storage.h"

namespace probeless::python {

namespace {

// --- MCAP ----------------------------------------------------------------------------------------

// One message of a log: its record fields and, when a converter knows its schema, the decoded
// probeless message (owned memory).
struct LogMessage {
  std::string topic;
  uint32_t sequence = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::string schema;  // ROS 2 type, "" for schemaless
  py::object msg;      // a probeless.msgs object, or None
  py::object data;     // the raw (CDR) bytes
};

struct PyCursor {
  std::shared_ptr<log::McapReader> reader;  // outlives the cursor
  std::unique_ptr<log::MessageCursor> cursor;
  bool decode = true;

  LogMessage Next() {
    log::MessageView view;
    if (!cursor->Next(view)) throw py::stop_iteration();
    LogMessage out;
    out.topic = view.channel->topic;
    out.sequence = view.sequence;
    out.log_time_ns = view.log_time_ns;
    out.publish_time_ns = view.publish_time_ns;
    out.schema = view.schema ? view.schema->name : "";
    out.data = py::bytes(reinterpret_cast<const char*>(view.data.data()), view.data.size());
    out.msg = py::none();
    const log::Ros2Converter* converter =
        view.schema ? log::FindRos2ConverterByRos2Type(view.schema->name) : nullptr;
    if (decode && converter != nullptr && view.channel->message_encoding == "cdr") {
      const MessageType* type = FindMessageType(std::string(converter->probeless_type()));
      if (type != nullptr) {
        log::MessageBuffer buffer = log::DecodeRos2(*converter, view.data, view.channel->metadata);
        auto storage = std::make_shared<OwnedStorage>(type->name + " from " + reader->path(),
                                                      std::move(buffer));
        out.msg = type->wrap(std::move(storage));
      }
    }
    return out;
  }
};

void BindLogModule(py::module_& m) {
  py::class_<LogMessage>(m, "LogMessage", "One message read from an MCAP log.")
      .def_readonly("topic", &LogMessage::topic)
      .def_readonly("sequence", &LogMessage::sequence)
      .def_readonly("log_time_ns", &LogMessage::log_time_ns)
      .def_readonly("publish_time_ns", &LogMessage::publish_time_ns)
      .def_readonly("schema", &LogMessage::schema, "ROS 2 type of the channel's schema")
      .def_readonly("msg", &LogMessage::msg,
                    "the decoded probeless message (owned: numpy views stay valid), or None "
                    "for a schema without a probeless type")
      .def_readonly("data", &LogMessage::data, "the record's bytes (CDR)");

  py::class_<PyCursor>(m, "MessageIterator")
      .def("__iter__", [](py::object self) { return self; })
      .def("__next__", &PyCursor::Next);

  py::class_<log::McapReader, std::shared_ptr<log::McapReader>>(
      m, "McapReader",
      "An MCAP log (complete or cut short) read by the C++ reader (common/log); messages are "
      "decoded into probeless.msgs objects with numpy views of their arrays.")
      .def(py::init([](const std::string& path, bool verify_crcs) {
             log::ReaderOptions options;
             options.verify_crcs = verify_crcs;
             return std::make_shared<log::McapReader>(path, options);
           }),
           py::arg("path"), py::arg("verify_crcs") = true,
           "Opens and validates `path`; raises LogError ('<path>: offset N: problem').")
      .def_property_readonly("path", &log::McapReader::path)
      .def_property_readonly("profile", &log::McapReader::profile)
      .def_property_readonly("library", &log::McapReader::library)
      .def_property_readonly("truncated", &log::McapReader::truncated,
                             "no valid footer: the messages were recovered by a scan")
      .def_property_readonly("message_count",
                             [](const log::McapReader& r) { return r.statistics().message_count; })
      .def_property_readonly(
          "start_time_ns",
          [](const log::McapReader& r) { return r.statistics().message_start_time_ns; })
      .def_property_readonly(
          "end_time_ns",
          [](const log::McapReader& r) { return r.statistics().message_end_time_ns; })
      .def(
          "topics",
          [](const log::McapReader& r) {
            py::dict out;
            for (const auto& [id, channel] : r.channels()) {
              const log::Schema* schema = r.FindSchema(channel.schema_id);
              const log::Ros2Converter* converter =
                  schema ? log::FindRos2ConverterByRos2Type(schema->name) : nullptr;
              py::dict d;
              d["schema"] = schema ? schema->name : "";
              d["message_encoding"] = channel.message_encoding;
              d["probeless_type"] =
                  converter ? std::string(converter->probeless_type()) : std::string();
              const auto counts = r.statistics().channel_message_counts;
              const auto it = counts.find(id);
              d["messages"] = it == counts.end() ? 0 : it->second;
              d["metadata"] = channel.metadata;
              out[py::str(channel.topic)] = d;
            }
            return out;
          },
          "topic -> {schema, message_encoding, probeless_type, messages, metadata}")
      .def(
          "messages",
          [](std::shared_ptr<log::McapReader> r, std::optional<std::vector<std::string>> topics,
             uint64_t start_time_ns, std::optional<uint64_t> end_time_ns, bool decode) {
            log::ReadOptions options;
            if (topics) options.topics = *topics;
            options.start_time_ns = start_time_ns;
            if (end_time_ns) options.end_time_ns = *end_time_ns;
            PyCursor cursor;
            cursor.cursor = std::make_unique<log::MessageCursor>(r->Messages(options));
            cursor.reader = std::move(r);
            cursor.decode = decode;
            return cursor;
          },
          py::arg("topics") = py::none(), py::arg("start_time_ns") = 0,
          py::arg("end_time_ns") = py::none(), py::arg("decode") = true,
          "Iterates the messages in log-time order: LogMessage objects (topic, times, msg).");
}

// --- Face light ----------------------------------------------------------------------------------

std::string ResolveData(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty() || fs::path(path).is_absolute() || fs::exists(path)) return path;
  const fs::path candidate = fs::path(PROBELESS_SOURCE_DIR) / path;
  return fs::exists(candidate) ? candidate.string() : path;
}

// Validity bit words (FaceObservation::sample_valid layout) from None, a bool mask of `count`
// samples or uint64 words.
std::vector<uint64_t> ValidBits(const py::object& valid, size_t count) {
  if (valid.is_none()) return {};
  const py::array array = py::array::ensure(valid);
  if (!array) throw py::type_error("probeless: valid must be None, a bool mask or uint64 words");
  if (array.dtype().kind() == 'b') {
    const auto mask = py::array_t<bool, py::array::c_style | py::array::forcecast>(array);
    if (static_cast<size_t>(mask.size()) != count) {
      throw py::value_error("probeless: the valid mask has " + std::to_string(mask.size()) +
                            " entries for " + std::to_string(count) + " samples");
    }
    std::vector<uint64_t> bits((count + 63) / 64, 0);
    for (size_t i = 0; i < count; ++i) {
      if (mask.data()[i]) bits[i / 64] |= uint64_t{1} << (i % 64);
    }
    return bits;
  }
  const auto words = py::array_t<uint64_t, py::array::c_style | py::array::forcecast>(array);
  return std::vector<uint64_t>(words.data(), words.data() + words.size());
}

py::dict EstimateDict(const face_light::LightEstimate& e) {
  py::dict d;
  py::array_t<float> coefficients({face_light::kRtfCoefficients, 3});
  std::memcpy(coefficients.mutable_data(), e.coefficients.data(), sizeof(e.coefficients));
  d["channels"] = e.channels;
  d["coefficients"] = coefficients;
  d["dominant_direction"] = e.dominant_direction;
  d["intensity"] = e.intensity;
  d["confidence"] = e.confidence;
  d["samples_used"] = e.samples_used;
  d["samples_rejected"] = e.samples_rejected;
  d["rms_residual"] = e.rms_residual;
  return d;
}

face_light::LightEstimate EstimateFromDict(const py::dict& d) {
  face_light::LightEstimate e;
  e.channels = d["channels"].cast<int>();
  const auto c = py::array_t<float, py::array::c_style | py::array::forcecast>(d["coefficients"]);
  if (c.size() != face_light::kRtfCoefficients * 3) {
    throw py::value_error("probeless: an estimate's coefficients are 9 x 3");
  }
  std::memcpy(e.coefficients.data(), c.data(), sizeof(e.coefficients));
  e.dominant_direction = d["dominant_direction"].cast<std::array<float, 3>>();
  e.intensity = d["intensity"].cast<float>();
  e.confidence = d["confidence"].cast<float>();
  return e;
}

struct PyFaceLight {
  std::string model_path;
  std::unique_ptr<face_light::FaceLightModel> model;
  std::unique_ptr<face_light::FaceLightEstimator> estimator;
  std::unique_ptr<face_light::LinearLightConverter> converter;
};

void BindFaceLight(py::module_& m) {
  py::class_<PyFaceLight>(
      m, "FaceLightEstimator",
      "Knorr & Kurz light from face samples: the face_light node's FaceLightEstimator and "
      "LinearLightConverter on arrays. Estimates are dicts (channels, coefficients 9 x 3 in the "
      "face frame, dominant_direction, intensity, confidence, samples_used, ...).")
      .def(py::init([](const std::string& model, double back_prior, double ridge, bool robust,
                       bool non_negative, double weight_floor, bool directional_fit,
                       std::array<double, 3> skin_albedo, double unit_scale) {
             PyFaceLight self;
             self.model_path = ResolveData(model);
             self.model = std::make_unique<face_light::FaceLightModel>(
                 face_light::LoadModel(self.model_path));
             face_light::EstimatorOptions eo;
             eo.back_prior = back_prior;
             eo.ridge = ridge;
             eo.robust = robust;
             eo.non_negative = non_negative;
             eo.weight_floor = weight_floor;
             eo.directional_fit = directional_fit;
             self.estimator = std::make_unique<face_light::FaceLightEstimator>(*self.model, eo);
             face_light::LinearLightOptions lo;
             lo.skin_albedo = skin_albedo;
             lo.unit_scale = unit_scale;
             self.converter = std::make_unique<face_light::LinearLightConverter>(*self.model, lo);
             return self;
           }),
           py::arg("model") = "data/face_light/default_model.txt", py::arg("back_prior") = 0.1,
           py::arg("ridge") = 0.0, py::arg("robust") = false, py::arg("non_negative") = false,
           py::arg("weight_floor") = 0.0, py::arg("directional_fit") = true,
           py::arg("skin_albedo") = std::array<double, 3>{0.47, 0.32, 0.25},
           py::arg("unit_scale") = 0.223,
           "The node's defaults (docs/nodes.md, face_light). `model` relative to the working "
           "directory or the source tree. Raises FaceLightError for a bad model or options.")
      .def_property_readonly("sample_count",
                             [](const PyFaceLight& f) { return f.estimator->SampleCount(); })
      .def_property_readonly("model_path", [](const PyFaceLight& f) { return f.model_path; })
      .def(
          "estimate_rgb",
          [](const PyFaceLight& f,
             py::array_t<float, py::array::c_style | py::array::forcecast> rgb, py::object valid) {
            const size_t n = static_cast<size_t>(f.estimator->SampleCount());
            const std::vector<uint64_t> bits = ValidBits(valid, n);
            face_light::LightEstimate e;
            {
              py::gil_scoped_release unlocked;
              e = f.estimator->EstimateRgb({rgb.data(), static_cast<size_t>(rgb.size())}, bits);
            }
            return EstimateDict(e);
          },
          py::arg("rgb"), py::arg("valid") = py::none(),
          "Light from N x 3 linear sample colours (model sample order); valid: None, N bools or "
          "uint64 bit words. FaceLightError for a wrong sample count.")
      .def(
          "estimate_gray",
          [](const PyFaceLight& f,
             py::array_t<float, py::array::c_style | py::array::forcecast> intensities,
             py::object valid) {
            const std::vector<uint64_t> bits =
                ValidBits(valid, static_cast<size_t>(f.estimator->SampleCount()));
            face_light::LightEstimate e;
            {
              py::gil_scoped_release unlocked;
              e = f.estimator->EstimateGray(
                  {intensities.data(), static_cast<size_t>(intensities.size())}, bits);
            }
            return EstimateDict(e);
          },
          py::arg("intensities"), py::arg("valid") = py::none())
      .def(
          "estimate_observation",
          [](const PyFaceLight& f, const MsgRef<msgs::FaceObservation>& observation) {
            const msgs::FaceObservation& obs = *observation.get();
            obs.Validate();
            if (static_cast<int>(obs.sample_count) != f.estimator->SampleCount()) {
              throw face_light::FaceLightError("face_light: observation has " +
                                               std::to_string(obs.sample_count) +
                                               " samples but model '" + f.model_path + "' has " +
                                               std::to_string(f.estimator->SampleCount()));
            }
            return EstimateDict(f.estimator->EstimateRgb(
                {&obs.sample_rgb[0][0], obs.sample_count * size_t{3}}, obs.sample_valid));
          },
          py::arg("observation"),
          "estimate_rgb on a msgs.FaceObservation's samples and validity (face frame).")
      .def(
          "linear_light",
          [](const PyFaceLight& f,
             py::array_t<float, py::array::c_style | py::array::forcecast> rgb, py::object valid,
             const py::dict& estimate) {
            const std::vector<uint64_t> bits =
                ValidBits(valid, static_cast<size_t>(f.estimator->SampleCount()));
            const face_light::LinearLight l = f.converter->Convert(
                {rgb.data(), static_cast<size_t>(rgb.size())}, bits, EstimateFromDict(estimate));
            py::dict d;
            py::array_t<float> coefficients({face_light::kRtfCoefficients, 3});
            std::memcpy(coefficients.mutable_data(), l.coefficients.data(), sizeof(l.coefficients));
            d["valid"] = l.valid;
            d["coefficients"] = coefficients;
            d["direction"] = l.direction;
            d["power"] = l.power;
            d["ambient"] = l.ambient;
            d["intensity"] = l.intensity;
            d["direct_fraction"] = l.direct_fraction;
            d["lit_fraction"] = l.lit_fraction;
            d["behind"] = l.behind;
            d["r2"] = l.r2;
            d["samples_used"] = l.samples_used;
            return d;
          },
          py::arg("rgb"), py::arg("valid"), py::arg("estimate"),
          "The node's linear_output conversion: ShLight units, skin albedo compensated.")
      .def(
          "predict",
          [](const PyFaceLight& f, std::array<double, 3> direction, std::array<double, 3> power,
             std::array<double, 3> ambient) {
            const std::vector<float> rgb = f.converter->Predict(direction, power, ambient);
            py::array_t<float> out({static_cast<py::ssize_t>(rgb.size() / 3), py::ssize_t{3}});
            std::memcpy(out.mutable_data(), rgb.data(), rgb.size() * sizeof(float));
            return out;
          },
          py::arg("direction"), py::arg("power"), py::arg("ambient"),
          "The forward model: N x 3 sample colours of the face under a directional light "
          "(face frame) plus uniform radiance, times the skin albedo.");
}

// --- Scene light ---------------------------------------------------------------------------------

struct PyScene {
  std::string mode;
  std::unique_ptr<light::ScenePipeline> pipeline;
};

light::ScenePipelineOptions SceneOptions(const std::string& mode, int bands, int directions,
                                         int subsample, double radius, int threads, int stride,
                                         bool robust, std::optional<double> albedo,
                                         std::optional<bool> shadows, const std::string& model,
                                         bool raw_confidence) {
  if (mode != "gbuffer" && mode != "depth") {
    throw light::LightError("scene_light: mode must be gbuffer or depth, got '" + mode + "'");
  }
  // The scene_light node's defaults (nodes/scene_light OptionsFromParams, docs/nodes.md).
  light::ScenePipelineOptions po;
  po.source = mode == "gbuffer" ? light::SceneGeometrySource::kGeometryBuffer
                                : light::SceneGeometrySource::kDepthImage;
  po.transfer.bands = bands;
  po.transfer.directions = directions;
  po.transfer.subsample = subsample;
  po.transfer.radius_m = static_cast<float>(radius);
  po.transfer.max_occluder_distance_m = 2 * po.transfer.radius_m;
  po.transfer.seed = 1;
  po.transfer.threads = threads;
  po.transfer.analytic_unoccluded = true;
  if (albedo) po.estimate.albedo = static_cast<float>(*albedo);
  po.estimate.stride = stride;
  po.estimate.robust = robust;
  po.estimate.non_negative = false;
  po.estimate.direction_bands = 2;
  po.estimate.albedo_groups = 32;
  po.estimate.max_rows_per_bin = 100;
  po.grey_world_colour = true;
  po.gbuffer_normals = light::GBufferNormals::kGiven;
  po.depth_geometry.normals_from = light::DepthNormals::kAuto;
  po.depth_geometry.smooth_radius = -1;
  po.depth_geometry.step = -1;
  po.light_model = light::ParseLightModel(model);
  po.point.max_lamps = 1;
  po.shadow.enabled = shadows.value_or(false);
  const bool image_cues = mode == "depth";
  po.shadow.image_cues = mode == "gbuffer" && image_cues;
  po.depth_image_cues = mode == "gbuffer" || image_cues;
  po.shadow.stride = 8;
  po.shadows_override_prior = true;
  po.confidence_knots = light::DefaultSceneConfidenceKnots(po.source);
  if (raw_confidence) po.confidence_knots->clear();
  po.shadow.threads = threads;
  po.shadow_geometry = light::ShadowGeometry::kDepthImage;
  return po;
}

// The camera calibration of a msgs.CameraInfo object or (fx, fy, cx, cy), for width x height.
msgs::CameraInfo CameraInfoOf(py::handle camera, uint32_t width, uint32_t height) {
  msgs::CameraInfo info;
  AnyMsg any;
  if (py::isinstance<MsgRef<msgs::CameraInfo>>(camera)) {
    info = *camera.cast<const MsgRef<msgs::CameraInfo>&>().get();
  } else {
    const auto k = camera.cast<std::array<double, 4>>();
    info.fx = k[0];
    info.fy = k[1];
    info.cx = k[2];
    info.cy = k[3];
    info.width = width;
    info.height = height;
  }
  return info;
}

void BindSceneLight(py::module_& m) {
  py::class_<PyScene>(
      m, "ScenePipeline",
      "Gruber et al. scene light: the scene_light node's light::ScenePipeline on arrays, one "
      "object per stream (it carries state between frames).")
      .def(py::init([](const std::string& mode, int bands, int directions, int subsample,
                       double radius, int threads, int stride, bool robust,
                       std::optional<double> albedo, std::optional<bool> shadows,
                       const std::string& light_model, bool raw_confidence) {
             PyScene self;
             self.mode = mode;
             self.pipeline = std::make_unique<light::ScenePipeline>(
                 SceneOptions(mode, bands, directions, subsample, radius, threads, stride, robust,
                              albedo, shadows, light_model, raw_confidence));
             return self;
           }),
           py::arg("mode") = "depth", py::arg("bands") = 4, py::arg("directions") = 32,
           py::arg("subsample") = 1, py::arg("radius") = 0.3, py::arg("threads") = 2,
           py::arg("stride") = 4, py::arg("robust") = true, py::arg("albedo") = py::none(),
           py::arg("shadows") = py::none(), py::arg("light_model") = "auto",
           py::arg("raw_confidence") = false,
           "Options named and defaulted as the node's params (docs/nodes.md, scene_light); "
           "shadows None = off (the node's default). Raises LightError for bad options.")
      .def(
          "process",
          [](PyScene& self, py::array_t<uint8_t, py::array::c_style | py::array::forcecast> image,
             py::object camera, py::object depth, py::object gbuffer_depth,
             py::object gbuffer_normals, int64_t stamp_ns) {
            if (image.ndim() != 3 || image.shape(2) != 3) {
              throw py::value_error("probeless: image must be H x W x 3 uint8 rgb, got shape " +
                                    std::string(py::repr(image.attr("shape"))));
            }
            const uint32_t h = static_cast<uint32_t>(image.shape(0));
            const uint32_t w = static_cast<uint32_t>(image.shape(1));
            msgs::CameraInfo info = CameraInfoOf(camera, w, h);
            msgs::Image colour;
            colour.Init(w, h, msgs::Encoding::kRgb8);
            std::vector<float> grey, depth_m, gdepth, gnormals;
            std::vector<uint8_t> rgb;
            light::GreyFromImage(colour,
                                 {reinterpret_cast<const std::byte*>(image.data()),
                                  static_cast<size_t>(image.nbytes())},
                                 static_cast<int>(w), static_cast<int>(h), &grey, &rgb);
            light::SceneFrame frame;
            frame.stamp_ns = stamp_ns;
            frame.width = static_cast<int>(w);
            frame.height = static_cast<int>(h);
            frame.intrinsics =
                light::IntrinsicsFrom(info, static_cast<int>(w), static_cast<int>(h));
            frame.grey = grey;
            frame.colour = rgb;
            if (!depth.is_none()) {
              const py::array d = py::array::ensure(depth);
              msgs::Image im;
              const bool mm = d.dtype().is(py::dtype::of<uint16_t>());
              const py::array packed =
                  mm ? py::array(
                           py::array_t<uint16_t, py::array::c_style | py::array::forcecast>(d))
                     : py::array(py::array_t<float, py::array::c_style | py::array::forcecast>(d));
              if (packed.ndim() != 2) throw py::value_error("probeless: depth must be H x W");
              im.Init(static_cast<uint32_t>(packed.shape(1)),
                      static_cast<uint32_t>(packed.shape(0)),
                      mm ? msgs::Encoding::kDepth16 : msgs::Encoding::kFloat32);
              if (mm && info.depth_scale == 0) info.depth_scale = 0.001;
              light::DepthFromImage(im,
                                    {reinterpret_cast<const std::byte*>(packed.data()),
                                     static_cast<size_t>(packed.nbytes())},
                                    info, &depth_m);
              frame.depth_image = depth_m;
            }
            if (!gbuffer_depth.is_none()) {
              const auto gd =
                  py::array_t<float, py::array::c_style | py::array::forcecast>(gbuffer_depth);
              const auto gn =
                  py::array_t<float, py::array::c_style | py::array::forcecast>(gbuffer_normals);
              if (gd.size() != static_cast<py::ssize_t>(w) * h ||
                  gn.size() != static_cast<py::ssize_t>(w) * h * 3) {
                throw py::value_error(
                    "probeless: gbuffer_depth must be H x W and gbuffer_normals H x W x 3 float32 "
                    "of the image's size");
              }
              gdepth.assign(gd.data(), gd.data() + gd.size());
              gnormals.assign(gn.data(), gn.data() + gn.size());
              frame.gbuffer_depth = gdepth;
              frame.gbuffer_normals = gnormals;
              frame.gbuffer_colour = rgb;
            }
            const light::ScenePipelineResult* r = nullptr;
            {
              py::gil_scoped_release unlocked;
              r = &self.pipeline->Process(frame);
            }
            py::dict out;
            out["valid"] = r->light.valid;
            out["model"] = r->used == light::LightModel::kPoint ? "point" : "distant";
            auto storage =
                std::make_shared<OwnedStorage>("probeless_msgs/ShLight", sizeof(msgs::ShLight));
            auto* sh = ::new (static_cast<void*>(storage->data())) msgs::ShLight{};
            if (r->light.valid) {
              // As the node publishes it: the white light times the illuminant colour.
              light::FillShLight(r->light, sh);
              for (auto& coefficient : sh->coefficients) {
                for (int c = 0; c < 3; ++c) coefficient[c] *= r->colour[c];
              }
            }
            sh->header.stamp_ns = stamp_ns;
            out["light"] = FindMessageType("probeless_msgs/ShLight")->wrap(storage);
            out["fit_confidence"] = r->evidence.fit_confidence;
            out["shadow_accepted"] = r->evidence.shadow_accepted;
            out["colour"] = r->colour;
            py::dict timings;
            timings["ms_geometry"] = r->timings.ms_geometry;
            timings["ms_transfer"] = r->timings.ms_transfer;
            timings["ms_estimate"] = r->timings.ms_estimate;
            out["timings"] = timings;
            return out;
          },
          py::arg("image"), py::arg("camera"), py::arg("depth") = py::none(),
          py::arg("gbuffer_depth") = py::none(), py::arg("gbuffer_normals") = py::none(),
          py::arg("stamp_ns") = 0,
          "One frame: image H x W x 3 uint8 sRGB, camera a msgs.CameraInfo or (fx, fy, cx, cy); "
          "depth mode: depth H x W (uint16 mm, or float32 m); gbuffer mode: gbuffer_depth (m) "
          "and gbuffer_normals (H x W x 3), depth optional for the shadow search. Returns a dict: "
          "valid, light (msgs.ShLight as the node publishes it), model, fit_confidence, "
          "shadow_accepted, colour, timings. Raises LightError for inconsistent inputs.")
      .def(
          "reset", [](PyScene& self) { self.pipeline->Reset(); },
          "Forgets the state carried between frames.");
}

}  // namespace

void BindLog(py::module_& m) {
  py::module_ sub = m.def_submodule("log", "MCAP logs through the C++ reader (docs/log.md).");
  BindLogModule(sub);
}

void BindEstimators(py::module_& m) {
  py::module_ face = m.def_submodule("face_light", "Light from face samples (docs/face_light.md).");
  BindFaceLight(face);
  py::module_ scene = m.def_submodule("light", "Scene light (docs/light.md).");
  BindSceneLight(scene);
}

}  // namespace probeless::python
