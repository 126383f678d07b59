// probeless.msgs: every message type of msgs/ as a Python class whose fields read and write the
// message's bytes in place (a received sample's slot, a loan, or memory of the extension), array
// fields and payload planes as numpy views; and the Storage machinery behind them (storage.h).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <map>
#include <new>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "probeless/msgs/msgs.h"
#include "storage.h"

namespace probeless::python {

// --- Storage -------------------------------------------------------------------------------------

std::byte* Storage::data() const {
  CheckAlive();
  return data_;
}

void Storage::CheckAlive() const {
  if (released_) throw py::value_error("probeless: the " + what_ + " was released");
}

void Storage::CheckWritable() const {
  CheckAlive();
  if (!writable_) {
    throw py::value_error("probeless: the " + what_ + " is read-only (copy() it to change it)");
  }
}

void Storage::CheckNoViews(const char* action) const {
  if (views_ > 0) {
    throw py::buffer_error("probeless: cannot " + std::string(action) + " the " + what_ + ": " +
                           std::to_string(views_) +
                           " numpy view(s) of it still exist (del them, or copy the data first)");
  }
}

py::array Storage::MakeView(const std::shared_ptr<Storage>& storage, py::dtype dtype,
                            const void* ptr, std::vector<py::ssize_t> shape,
                            std::vector<py::ssize_t> strides) {
  storage->CheckAlive();
  py::capsule base(new std::shared_ptr<Storage>(storage), [](void* p) {
    auto* held = static_cast<std::shared_ptr<Storage>*>(p);
    --(*held)->views_;
    delete held;
  });
  ++storage->views_;
  py::array array(std::move(dtype), std::move(shape), std::move(strides), ptr, base);
  if (!storage->writable_) {
    py::detail::array_proxy(array.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  }
  return array;
}

OwnedStorage::OwnedStorage(std::string what, size_t bytes)
    : OwnedStorage(std::move(what), log::MessageBuffer(bytes)) {}

OwnedStorage::OwnedStorage(std::string what, log::MessageBuffer buffer)
    : Storage(std::move(what), buffer.bytes().data(), buffer.size(), true),
      buffer_(std::move(buffer)) {}

SampleStorage::SampleStorage(bus::Sample sample, std::string topic,
                             std::shared_ptr<std::mutex> subscriber_mutex)
    : Storage("sample of " + topic, const_cast<std::byte*>(sample.data().data()),
              sample.data().size(), false),
      sample_(std::move(sample)),
      info_(sample_.info()),
      topic_(std::move(topic)),
      mutex_(std::move(subscriber_mutex)) {}

SampleStorage::~SampleStorage() {
  std::lock_guard lock(*mutex_);
  sample_.Release();
}

void SampleStorage::Release() {
  if (released()) return;
  CheckNoViews("release");
  {
    py::gil_scoped_release unlocked;
    std::lock_guard lock(*mutex_);
    sample_.Release();
  }
  MarkReleased();
}

LoanStorage::LoanStorage(bus::Loan loan, std::shared_ptr<PublisherState> publisher)
    : Storage("loan on " + publisher->publisher.topic(), loan.data().data(), loan.size(), true),
      loan_(std::move(loan)),
      publisher_(std::move(publisher)) {}

LoanStorage::~LoanStorage() {
  std::lock_guard lock(publisher_->mutex);
  loan_ = bus::Loan();
}

uint64_t LoanStorage::Publish() {
  CheckAlive();
  CheckNoViews("publish");
  uint64_t sequence = 0;
  {
    py::gil_scoped_release unlocked;
    std::lock_guard lock(publisher_->mutex);
    sequence = publisher_->publisher.Publish(std::move(loan_));
  }
  MarkReleased();
  return sequence;
}

void LoanStorage::Drop() {
  if (released()) return;
  CheckNoViews("drop");
  {
    std::lock_guard lock(publisher_->mutex);
    loan_ = bus::Loan();
  }
  MarkReleased();
}

// --- Registry ------------------------------------------------------------------------------------

namespace {

std::map<std::string, MessageType>& Registry() {
  static std::map<std::string, MessageType> registry;
  return registry;
}

}  // namespace

const MessageType* FindMessageType(const std::string& name) {
  const auto it = Registry().find(name);
  return it == Registry().end() ? nullptr : &it->second;
}

const MessageType& MessageTypeOf(py::handle cls_or_name) {
  if (py::isinstance<py::str>(cls_or_name)) {
    const std::string name = cls_or_name.cast<std::string>();
    if (const MessageType* type = FindMessageType(name)) return *type;
    throw py::type_error("probeless: unknown message type '" + name + "'");
  }
  for (const auto& [name, type] : Registry()) {
    if (cls_or_name.is(type.cls)) return type;
  }
  throw py::type_error(
      "probeless: expected a message class of probeless.msgs (e.g. "
      "probeless.msgs.Image), got " +
      py::repr(cls_or_name).cast<std::string>());
}

AnyMsg AnyMsgOf(py::handle message) {
  AnyMsg out;
  for (const auto& [name, type] : Registry()) {
    if (type.unwrap(message, &out)) return out;
  }
  throw py::type_error("probeless: expected a probeless.msgs message, got " +
                       py::repr(py::type::handle_of(message)).cast<std::string>());
}

namespace {

// --- Enum fields as names ------------------------------------------------------------------------

struct EnumTable {
  const char* type;
  std::vector<std::pair<uint32_t, std::string>> values;

  py::object Name(uint32_t value) const {
    for (const auto& [v, n] : values) {
      if (v == value) return py::str(n);
    }
    return py::int_(value);  // a value the enum does not name (a newer or corrupt message)
  }
  uint32_t Value(py::handle object) const {
    if (py::isinstance<py::str>(object)) {
      const std::string name = object.cast<std::string>();
      for (const auto& [v, n] : values) {
        if (n == name) return v;
      }
      std::string names;
      for (const auto& [v, n] : values) names += (names.empty() ? "" : ", ") + n;
      throw py::value_error(std::string(type) + ": unknown value '" + name + "' (expected " +
                            names + ")");
    }
    return object.cast<uint32_t>();
  }
};

const EnumTable kEncodings{"encoding",
                           {{0, "invalid"},
                            {1, "rgb8"},
                            {2, "bgr8"},
                            {3, "mono8"},
                            {4, "mono16"},
                            {5, "depth16"},
                            {6, "float32"},
                            {7, "rgb32f"}}};
const EnumTable kDistortionModels{"distortion_model",
                                  {{0, "none"}, {1, "plumb_bob"}, {2, "rational_polynomial"}}};
const EnumTable kShLightUnits{
    "units", {{0, "unknown"}, {1, "linear"}, {2, "face_model"}, {3, "linear_unscaled"}}};
const EnumTable kTransferLayouts{"layout", {{0, "invalid"}, {1, "interleaved_float32"}}};
const EnumTable kPlayerCommands{
    "command",
    {{0, "invalid"}, {1, "pause"}, {2, "resume"}, {3, "toggle"}, {4, "step"}, {5, "set_rate"}}};
const EnumTable kTrackingStates{"state",
                                {{0, "invalid"}, {1, "tracked"}, {2, "uncertain"}, {3, "lost"}}};
const EnumTable kAuxiliaryRoles{
    "role", {{0, "invalid"}, {1, "left"}, {2, "right"}, {3, "top"}, {4, "light"}}};

msgs::Encoding EncodingOf(const std::string& name) { return msgs::EncodingFromName(name); }

// --- Field binding -------------------------------------------------------------------------------

template <class T>
struct MemberOf;
template <class C, class T>
struct MemberOf<T C::*> {
  using Class = C;
  using Type = T;
};

template <class T>
constexpr bool kIsNumericArray =
    std::is_array_v<T>&& std::is_arithmetic_v<std::remove_all_extents_t<T>> &&
    !std::is_same_v<std::remove_all_extents_t<T>, char>;

template <class T>
void ShapeOf(std::vector<py::ssize_t>* shape) {
  if constexpr (std::is_array_v<T>) {
    shape->push_back(static_cast<py::ssize_t>(std::extent_v<T>));
    ShapeOf<std::remove_extent_t<T>>(shape);
  }
}

// C-order byte strides of `shape` for elements of `element_bytes`.
std::vector<py::ssize_t> CStrides(const std::vector<py::ssize_t>& shape, size_t element_bytes) {
  std::vector<py::ssize_t> strides(shape.size());
  py::ssize_t stride = static_cast<py::ssize_t>(element_bytes);
  for (size_t i = shape.size(); i-- > 0;) {
    strides[i] = stride;
    stride *= shape[i];
  }
  return strides;
}

template <class M>
using PyClass = py::class_<MsgRef<M>>;

template <class M>
class Binder {
 public:
  Binder(py::module_& m, const char* name, const char* doc) : cls_(m, name, doc) {
    cls_.def(py::init([](py::kwargs fields) {
               auto storage = std::make_shared<OwnedStorage>(std::string(M::kTypeName), sizeof(M));
               ::new (static_cast<void*>(storage->data())) M{};
               MsgRef<M> ref{storage, 0, true};
               py::object self = py::cast(ref);
               for (const auto& [key, value] : fields) {
                 if (!py::hasattr(self, key)) {
                   throw py::type_error(std::string(M::kTypeName) + " has no field '" +
                                        std::string(py::str(key)) + "'");
                 }
                 self.attr(key) = value;
               }
               return ref;
             }),
             "A zeroed message owned by Python; keyword arguments set fields.");
    cls_.attr("type_name") = std::string(M::kTypeName);
    cls_.attr("layout_hash") = M::kLayoutHash;
    cls_.attr("struct_bytes") = sizeof(M);
    cls_.attr("has_payload") = M::kHasPayload;
    cls_.def_property_readonly(
        "writable",
        [](const MsgRef<M>& r) { return r.storage->writable() && !r.storage->released(); },
        "False for a received sample (read-only) and once released.");
    cls_.def(
        "copy",
        [](const MsgRef<M>& r) {
          const size_t bytes = r.top ? r.storage->size() : sizeof(M);
          auto storage = std::make_shared<OwnedStorage>(std::string(M::kTypeName), bytes);
          std::memcpy(storage->data(), r.storage->data() + r.offset, bytes);
          return MsgRef<M>{storage, 0, true};
        },
        "An owned, writable copy (struct and payload), independent of any sample or loan.");
    cls_.def(
        "as_bytes",
        [](const MsgRef<M>& r) {
          const size_t bytes = r.top ? r.storage->size() : sizeof(M);
          return Storage::View<uint8_t>(r.storage, r.storage->data() + r.offset,
                                        {static_cast<py::ssize_t>(bytes)}, {1});
        },
        "The message's bytes (struct, then payload) as a uint8 view.");
    cls_.def("__repr__", [](const MsgRef<M>& r) {
      return "<probeless.msgs." + std::string(M::kTypeName.substr(M::kTypeName.find('/') + 1)) +
             " in " + r.storage->what() + (r.storage->released() ? " (released)>" : ">");
    });
    if constexpr (M::kHasPayload) {
      cls_.def_property_readonly(
          "payload",
          [](const MsgRef<M>& r) {
            const std::span<std::byte> p = r.payload();
            return Storage::View<uint8_t>(r.storage, p.data(), {static_cast<py::ssize_t>(p.size())},
                                          {1});
          },
          "The bytes after the struct (pixels, planes) as a uint8 view.");
    }
    MessageType type;
    type.name = std::string(M::kTypeName);
    type.layout_hash = M::kLayoutHash;
    type.struct_bytes = sizeof(M);
    type.has_payload = M::kHasPayload;
    type.cls = cls_;
    type.wrap = [](std::shared_ptr<Storage> storage) {
      // Size and alignment checks (MessageError naming the type).
      msgs::ReadMessage<M>(std::span<const std::byte>(storage->data(), storage->size()));
      return py::cast(MsgRef<M>{std::move(storage), 0, true});
    };
    type.unwrap = [](py::handle object, AnyMsg* out) {
      if (!py::isinstance<MsgRef<M>>(object)) return false;
      const MsgRef<M>& r = object.cast<const MsgRef<M>&>();
      out->storage = r.storage;
      out->offset = r.offset;
      out->top = r.top;
      out->type = FindMessageType(std::string(M::kTypeName));
      return true;
    };
    type.create_publisher = [](node::Node& node, std::string_view topic,
                               bus::PublisherOptions options) {
      return node.CreatePublisher<M>(topic, std::move(options));
    };
    type.create_subscriber = [](node::Node& node, std::string_view topic,
                                bus::SubscriberOptions options) {
      return node.CreateSubscriber<M>(topic, std::move(options));
    };
    Registry()[type.name] = std::move(type);
  }

  PyClass<M>& cls() { return cls_; }

  // A numeric scalar field.
  template <auto Member>
  Binder& Scalar(const char* name, const char* doc) {
    using T = typename MemberOf<decltype(Member)>::Type;
    static_assert(std::is_arithmetic_v<T>);
    fields_.push_back(name);
    cls_.def_property(
        name, [](const MsgRef<M>& r) { return r.get()->*Member; },
        [](const MsgRef<M>& r, T value) { r.mut()->*Member = value; }, doc);
    return *this;
  }

  // A fixed-size numeric array field: a numpy view of its shape; assigning copies into it.
  template <auto Member>
  Binder& Array(const char* name, const char* doc) {
    using T = typename MemberOf<decltype(Member)>::Type;
    static_assert(kIsNumericArray<T>);
    using E = std::remove_all_extents_t<T>;
    fields_.push_back(name);
    cls_.def_property(
        name,
        [](const MsgRef<M>& r) {
          std::vector<py::ssize_t> shape;
          ShapeOf<T>(&shape);
          return Storage::View<E>(r.storage, &(r.get()->*Member), shape,
                                  CStrides(shape, sizeof(E)));
        },
        [name](const MsgRef<M>& r, py::array_t<E, py::array::forcecast> value) {
          std::vector<py::ssize_t> shape;
          ShapeOf<T>(&shape);
          size_t count = 1;
          for (py::ssize_t s : shape) count *= static_cast<size_t>(s);
          if (static_cast<size_t>(value.size()) != count) {
            throw py::value_error(std::string(M::kTypeName) + "." + name + " holds " +
                                  std::to_string(count) + " values, got " +
                                  std::to_string(value.size()));
          }
          py::array_t<E, py::array::c_style | py::array::forcecast> packed(value);
          std::memcpy(&(r.mut()->*Member), packed.data(), count * sizeof(E));
        },
        doc);
    return *this;
  }

  // A NUL-terminated fixed-capacity text field.
  template <auto Member>
  Binder& String(const char* name, const char* doc) {
    fields_.push_back(name);
    cls_.def_property(
        name, [](const MsgRef<M>& r) { return std::string(msgs::FixedString(r.get()->*Member)); },
        [name](const MsgRef<M>& r, const std::string& value) {
          msgs::SetFixedString(r.mut()->*Member, value, name);
        },
        doc);
    return *this;
  }

  // A nested message struct: a message object over the same bytes; assigning copies one in.
  template <auto Member>
  Binder& Struct(const char* name, const char* doc) {
    using N = typename MemberOf<decltype(Member)>::Type;
    fields_.push_back(name);
    cls_.def_property(
        name,
        [](const MsgRef<M>& r) {
          const auto* base = reinterpret_cast<const std::byte*>(r.get());
          const auto* field = reinterpret_cast<const std::byte*>(&(r.get()->*Member));
          return MsgRef<N>{r.storage, r.offset + static_cast<size_t>(field - base), false};
        },
        [](const MsgRef<M>& r, const MsgRef<N>& value) {
          const N copy = *value.get();
          r.mut()->*Member = copy;
        },
        doc);
    return *this;
  }

  // An enum field, read and written by its lower-case name (an int is accepted too).
  template <auto Member>
  Binder& Enum(const char* name, const EnumTable& table, const char* doc) {
    using E = typename MemberOf<decltype(Member)>::Type;
    fields_.push_back(name);
    cls_.def_property(
        name,
        [&table](const MsgRef<M>& r) {
          return table.Name(static_cast<uint32_t>(r.get()->*Member));
        },
        [&table](const MsgRef<M>& r, py::object value) {
          r.mut()->*Member = static_cast<E>(table.Value(value));
        },
        doc);
    return *this;
  }

  // Publishes the field list as the class attribute `fields` (for to_dict and repr).
  void Finish() { cls_.attr("fields") = py::tuple(py::cast(fields_)); }

 private:
  PyClass<M> cls_;
  std::vector<std::string> fields_;
};

// A whole message with `payload_bytes` after the struct, owned by Python, made by `init`.
template <class M, class Init>
MsgRef<M> CreateOwned(size_t payload_bytes, Init&& init) {
  auto storage =
      std::make_shared<OwnedStorage>(std::string(M::kTypeName), sizeof(M) + payload_bytes);
  M* message = ::new (static_cast<void*>(storage->data())) M{};
  init(*message);
  return MsgRef<M>{storage, 0, true};
}

void BindHeaderAndGeometry(py::module_& m) {
  Binder<msgs::Header> header(m, "Header", "Stamp, sequence and frame of a message's data.");
  header
      .Scalar<&msgs::Header::stamp_ns>("stamp_ns",
                                       "acquisition time, ns since the epoch (CLOCK_REALTIME)")
      .Scalar<&msgs::Header::stamp_mono_ns>("stamp_mono_ns",
                                            "the same instant on CLOCK_MONOTONIC, ns")
      .Scalar<&msgs::Header::sequence>("sequence", "producer's frame counter from 1; 0 = unset")
      .String<&msgs::Header::frame_id>("frame_id", "coordinate frame, at most 31 characters")
      .Finish();
  header.cls().def(
      "stamp_now", [](const MsgRef<msgs::Header>& r) { r.mut()->StampNow(); },
      "Sets both stamps to now (CLOCK_REALTIME and CLOCK_MONOTONIC).");

  Binder<msgs::Vector3> vector3(m, "Vector3", "A 3-vector (metres for positions).");
  vector3.Scalar<&msgs::Vector3::x>("x", "")
      .Scalar<&msgs::Vector3::y>("y", "")
      .Scalar<&msgs::Vector3::z>("z", "")
      .Finish();
  Binder<msgs::Quaternion> quaternion(m, "Quaternion",
                                      "Unit quaternion w + xi + yj + zk; (0, 0, 0, 0) = unset.");
  quaternion.Scalar<&msgs::Quaternion::w>("w", "")
      .Scalar<&msgs::Quaternion::x>("x", "")
      .Scalar<&msgs::Quaternion::y>("y", "")
      .Scalar<&msgs::Quaternion::z>("z", "")
      .Finish();
  Binder<msgs::RigidTransform> transform(
      m, "RigidTransform", "Child -> parent: p_parent = R(rotation) p_child + translation.");
  transform
      .Struct<&msgs::RigidTransform::translation>("translation", "child origin in the parent, m")
      .Struct<&msgs::RigidTransform::rotation>("rotation", "child axes into parent axes")
      .Finish();
  transform.cls().def(
      "apply",
      [](const MsgRef<msgs::RigidTransform>& r, std::array<double, 3> p) {
        const msgs::Vector3 q = r.get()->Apply({p[0], p[1], p[2]});
        return std::array<double, 3>{q.x, q.y, q.z};
      },
      py::arg("point"), "Maps a point (x, y, z) of the child frame into the parent frame.");

  Binder<msgs::Pose> pose(m, "Pose", "A stamped transform child_frame_id -> parent_frame_id.");
  pose.Struct<&msgs::Pose::header>("header", "")
      .String<&msgs::Pose::parent_frame_id>("parent_frame_id", "at most 31 characters")
      .String<&msgs::Pose::child_frame_id>("child_frame_id", "at most 31 characters")
      .Struct<&msgs::Pose::transform>("transform", "child -> parent, metres")
      .Finish();
}

void BindImage(py::module_& m) {
  Binder<msgs::Image> image(m, "Image",
                            "A camera frame; its pixels follow the struct in the same slot.");
  image.Struct<&msgs::Image::header>("header", "")
      .Scalar<&msgs::Image::width>("width", "pixels per row")
      .Scalar<&msgs::Image::height>("height", "rows")
      .Scalar<&msgs::Image::step>("step", "bytes per row")
      .Enum<&msgs::Image::encoding>("encoding", kEncodings,
                                    "rgb8, bgr8, mono8, mono16, depth16 (mm), float32, rgb32f")
      .Finish();
  auto& cls = image.cls();
  cls.def_property_readonly(
      "pixels",
      [](const MsgRef<msgs::Image>& r) {
        const msgs::Image& im = *r.get();
        const std::span<std::byte> payload = r.payload();
        im.Validate(payload.size());
        const uint32_t channels = msgs::ChannelCount(im.encoding);
        const uint32_t bpc = msgs::BytesPerChannel(im.encoding);
        std::vector<py::ssize_t> shape{im.height, im.width};
        std::vector<py::ssize_t> strides{im.step, static_cast<py::ssize_t>(channels * bpc)};
        if (channels > 1) {
          shape.push_back(channels);
          strides.push_back(bpc);
        }
        switch (bpc) {
          case 1:
            return Storage::View<uint8_t>(r.storage, payload.data(), shape, strides);
          case 2:
            return Storage::View<uint16_t>(r.storage, payload.data(), shape, strides);
          default:
            return Storage::View<float>(r.storage, payload.data(), shape, strides);
        }
      },
      "The pixels in place: H x W x C (C = 3: rgb8, bgr8, rgb32f) or H x W, dtype uint8, "
      "uint16 or float32 by encoding, row stride `step`. Raises MessageError for an invalid "
      "image.");
  cls.def(
      "init",
      [](const MsgRef<msgs::Image>& r, uint32_t width, uint32_t height,
         const std::string& encoding) { r.mut()->Init(width, height, EncodingOf(encoding)); },
      py::arg("width"), py::arg("height"), py::arg("encoding"),
      "Sets width, height, encoding and a packed step.");
  cls.def(
      "validate", [](const MsgRef<msgs::Image>& r) { r.get()->Validate(r.payload().size()); },
      "Raises MessageError unless the image is consistent with its payload.");
  cls.def("describe", [](const MsgRef<msgs::Image>& r) { return r.get()->Describe(); });
  cls.def_static(
      "create",
      [](uint32_t width, uint32_t height, const std::string& encoding) {
        const msgs::Encoding e = EncodingOf(encoding);
        return CreateOwned<msgs::Image>(msgs::Image::PackedPayloadBytes(width, height, e),
                                        [&](msgs::Image& im) { im.Init(width, height, e); });
      },
      py::arg("width"), py::arg("height"), py::arg("encoding"),
      "An owned image with zeroed pixels (for publish() by copy; loans avoid the copy).");
  cls.def_static(
      "message_bytes_for",
      [](uint32_t width, uint32_t height, const std::string& encoding) {
        return msgs::Image::MessageBytesFor(width, height, EncodingOf(encoding));
      },
      py::arg("width"), py::arg("height"), py::arg("encoding"),
      "Whole message bytes of a packed image: the max_message_bytes a publisher needs.");

  Binder<msgs::CameraInfo> info(m, "CameraInfo", "Pinhole intrinsics and lens distortion.");
  info.Struct<&msgs::CameraInfo::header>("header", "")
      .Scalar<&msgs::CameraInfo::width>("width", "pixels")
      .Scalar<&msgs::CameraInfo::height>("height", "pixels")
      .Scalar<&msgs::CameraInfo::fx>("fx", "focal length x, pixels")
      .Scalar<&msgs::CameraInfo::fy>("fy", "focal length y, pixels")
      .Scalar<&msgs::CameraInfo::cx>("cx", "principal point x, pixels")
      .Scalar<&msgs::CameraInfo::cy>("cy", "principal point y, pixels")
      .Enum<&msgs::CameraInfo::distortion_model>("distortion_model", kDistortionModels,
                                                 "none, plumb_bob, rational_polynomial")
      .Scalar<&msgs::CameraInfo::distortion_count>("distortion_count", "0, 5 or 8")
      .Array<&msgs::CameraInfo::distortion>("distortion", "OpenCV order, 8 entries")
      .Scalar<&msgs::CameraInfo::depth_scale>("depth_scale", "metres per depth unit")
      .Finish();
  info.cls().def(
      "validate", [](const MsgRef<msgs::CameraInfo>& r) { r.get()->Validate(); },
      "Raises MessageError for an inconsistent calibration.");
}

void BindLight(py::module_& m) {
  Binder<msgs::ShLight> light(m, "ShLight", "Incident light as RGB SH coefficients.");
  light.Struct<&msgs::ShLight::header>("header", "")
      .Scalar<&msgs::ShLight::bands>("bands", "1..5")
      .Enum<&msgs::ShLight::units>("units", kShLightUnits,
                                   "unknown, linear, face_model, linear_unscaled")
      .Array<&msgs::ShLight::coefficients>("coefficients", "[l(l+1)+m][R, G, B], 25 x 3")
      .Array<&msgs::ShLight::dominant_direction>("dominant_direction", "unit, towards the light")
      .Scalar<&msgs::ShLight::intensity>("intensity", "radiance of the dominant light")
      .Scalar<&msgs::ShLight::confidence>("confidence", "[0, 1]")
      .Finish();
  light.cls().def(
      "validate", [](const MsgRef<msgs::ShLight>& r) { r.get()->Validate(); },
      "Raises MessageError for bands, units or confidence out of range.");

  Binder<msgs::FaceObservation> face(m, "FaceObservation",
                                     "A tracked face: landmarks, head pose, shading samples.");
  face.Struct<&msgs::FaceObservation::header>("header", "")
      .Scalar<&msgs::FaceObservation::face_detected>("face_detected", "0/1")
      .Scalar<&msgs::FaceObservation::landmark_count>("landmark_count", "0..68")
      .Array<&msgs::FaceObservation::landmarks>("landmarks", "68 x 2 pixels (x right, y down)")
      .Struct<&msgs::FaceObservation::head_pose>("head_pose", "face frame -> camera frame")
      .Scalar<&msgs::FaceObservation::sample_count>("sample_count", "0..512")
      .Scalar<&msgs::FaceObservation::quality>("quality", "[0, 1]")
      .Array<&msgs::FaceObservation::sample_rgb>("sample_rgb", "512 x 3 linear RGB in [0, 1]")
      .Array<&msgs::FaceObservation::sample_normals>("sample_normals", "512 x 3 unit normals")
      .Array<&msgs::FaceObservation::sample_valid>("sample_valid", "8 uint64 validity words")
      .Finish();
  auto& cls = face.cls();
  cls.def(
      "sample_valid_mask",
      [](const MsgRef<msgs::FaceObservation>& r) {
        const msgs::FaceObservation& f = *r.get();
        py::array_t<bool> mask(
            static_cast<py::ssize_t>(std::min(f.sample_count, msgs::kMaxFaceSamples)));
        auto out = mask.mutable_unchecked<1>();
        for (py::ssize_t i = 0; i < out.shape(0); ++i)
          out(i) = f.SampleValid(static_cast<uint32_t>(i));
        return mask;
      },
      "A bool array (a copy) of the first sample_count validity bits.");
  cls.def(
      "set_sample_valid",
      [](const MsgRef<msgs::FaceObservation>& r, uint32_t i, bool valid) {
        r.mut()->SetSampleValid(i, valid);
      },
      py::arg("index"), py::arg("valid"));
  cls.def("valid_sample_count",
          [](const MsgRef<msgs::FaceObservation>& r) { return r.get()->ValidSampleCount(); });
  cls.def(
      "validate", [](const MsgRef<msgs::FaceObservation>& r) { r.get()->Validate(); },
      "Raises MessageError for counts, flags or quality out of range.");
}

void BindBuffers(py::module_& m) {
  Binder<msgs::GeometryBuffer> gbuffer(m, "GeometryBuffer",
                                       "Depth, normals and colour planes of a view.");
  gbuffer.Struct<&msgs::GeometryBuffer::header>("header", "")
      .Scalar<&msgs::GeometryBuffer::width>("width", "pixels")
      .Scalar<&msgs::GeometryBuffer::height>("height", "pixels")
      .Scalar<&msgs::GeometryBuffer::depth_offset>("depth_offset", "payload byte offset")
      .Scalar<&msgs::GeometryBuffer::normals_offset>("normals_offset", "payload byte offset")
      .Scalar<&msgs::GeometryBuffer::colour_offset>("colour_offset", "payload byte offset")
      .Finish();
  auto& g = gbuffer.cls();
  using GRef = MsgRef<msgs::GeometryBuffer>;
  g.def_property_readonly(
      "depth",
      [](const GRef& r) {
        const auto plane = msgs::DepthPlane(*r.get(), r.payload());
        const py::ssize_t w = r.get()->width, h = r.get()->height;
        return Storage::View<float>(r.storage, plane.data(), {h, w}, CStrides({h, w}, 4));
      },
      "H x W float32 metres along z (0 = no surface), in place.");
  g.def_property_readonly(
      "normals",
      [](const GRef& r) {
        const auto plane = msgs::NormalsPlane(*r.get(), r.payload());
        const py::ssize_t w = r.get()->width, h = r.get()->height;
        return Storage::View<float>(r.storage, plane.data(), {h, w, 3}, CStrides({h, w, 3}, 4));
      },
      "H x W x 3 float32 unit normals (camera frame), in place.");
  g.def_property_readonly(
      "colour",
      [](const GRef& r) {
        const auto plane = msgs::ColourPlane(*r.get(), r.payload());
        const py::ssize_t w = r.get()->width, h = r.get()->height;
        return Storage::View<uint8_t>(r.storage, plane.data(), {h, w, 3}, CStrides({h, w, 3}, 1));
      },
      "H x W x 3 uint8 sRGB, in place.");
  g.def(
      "init", [](const GRef& r, uint32_t w, uint32_t h) { r.mut()->Init(w, h); }, py::arg("width"),
      py::arg("height"), "Sets the size and the standard plane offsets.");
  g.def(
      "validate", [](const GRef& r) { r.get()->Validate(r.payload().size()); },
      "Raises MessageError for planes outside the payload or overlapping.");
  g.def_static(
      "create",
      [](uint32_t w, uint32_t h) {
        return CreateOwned<msgs::GeometryBuffer>(msgs::GeometryBuffer::StandardPayloadBytes(w, h),
                                                 [&](msgs::GeometryBuffer& b) { b.Init(w, h); });
      },
      py::arg("width"), py::arg("height"));
  g.def_static("message_bytes_for", &msgs::GeometryBuffer::MessageBytesFor, py::arg("width"),
               py::arg("height"));

  Binder<msgs::TransferBuffer> transfer(m, "TransferBuffer", "Per-pixel SH transfer vectors.");
  transfer.Struct<&msgs::TransferBuffer::header>("header", "")
      .Scalar<&msgs::TransferBuffer::width>("width", "pixels")
      .Scalar<&msgs::TransferBuffer::height>("height", "pixels")
      .Scalar<&msgs::TransferBuffer::coefficient_count>("coefficient_count", "1, 4, 9, 16, 25")
      .Enum<&msgs::TransferBuffer::layout>("layout", kTransferLayouts, "interleaved_float32")
      .Finish();
  auto& t = transfer.cls();
  using TRef = MsgRef<msgs::TransferBuffer>;
  t.def_property_readonly(
      "coefficients",
      [](const TRef& r) {
        const auto all = msgs::TransferCoefficients(*r.get(), r.payload());
        const py::ssize_t w = r.get()->width, h = r.get()->height, c = r.get()->coefficient_count;
        return Storage::View<float>(r.storage, all.data(), {h, w, c}, CStrides({h, w, c}, 4));
      },
      "H x W x coefficient_count float32, in place.");
  t.def(
      "init",
      [](const TRef& r, uint32_t w, uint32_t h, uint32_t count) { r.mut()->Init(w, h, count); },
      py::arg("width"), py::arg("height"), py::arg("coefficient_count"));
  t.def("validate", [](const TRef& r) { r.get()->Validate(r.payload().size()); });
  t.def_static(
      "create",
      [](uint32_t w, uint32_t h, uint32_t count) {
        msgs::TransferBuffer probe;
        probe.Init(w, h, count);  // MessageError for a bad count
        return CreateOwned<msgs::TransferBuffer>(
            msgs::TransferBuffer::PayloadBytesFor(w, h, count),
            [&](msgs::TransferBuffer& b) { b.Init(w, h, count); });
      },
      py::arg("width"), py::arg("height"), py::arg("coefficient_count"));
  t.def_static("message_bytes_for", &msgs::TransferBuffer::MessageBytesFor, py::arg("width"),
               py::arg("height"), py::arg("coefficient_count"));

  Binder<msgs::AuxiliaryView> view(m, "AuxiliaryView", "One orthographic auxiliary view.");
  view.Enum<&msgs::AuxiliaryView::role>("role", kAuxiliaryRoles, "left, right, top, light")
      .Scalar<&msgs::AuxiliaryView::width>("width", "pixels")
      .Scalar<&msgs::AuxiliaryView::height>("height", "pixels")
      .Scalar<&msgs::AuxiliaryView::pixel_size_m>("pixel_size_m", "metres per pixel")
      .Array<&msgs::AuxiliaryView::rotation>("rotation", "view -> camera, row-major 9")
      .Array<&msgs::AuxiliaryView::translation>("translation", "view origin in the camera, m")
      .Scalar<&msgs::AuxiliaryView::depth_offset>("depth_offset", "payload byte offset")
      .Finish();

  Binder<msgs::AuxiliaryViews> views(m, "AuxiliaryViews", "Up to 4 auxiliary depth views.");
  views.Struct<&msgs::AuxiliaryViews::header>("header", "")
      .Scalar<&msgs::AuxiliaryViews::view_count>("view_count", "0..4")
      .Finish();
  auto& a = views.cls();
  using ARef = MsgRef<msgs::AuxiliaryViews>;
  a.def_property_readonly(
      "views",
      [](const ARef& r) {
        py::list out;
        for (uint32_t i = 0; i < msgs::kMaxAuxiliaryViews; ++i) {
          out.append(MsgRef<msgs::AuxiliaryView>{
              r.storage,
              r.offset + offsetof(msgs::AuxiliaryViews, views) + i * sizeof(msgs::AuxiliaryView),
              false});
        }
        return py::tuple(out);
      },
      "The 4 view structs (those at index >= view_count are unused).");
  a.def(
      "depth",
      [](const ARef& r, uint32_t index) {
        const auto plane = msgs::AuxiliaryDepth(*r.get(), r.payload(), index);
        const py::ssize_t w = r.get()->views[index].width, h = r.get()->views[index].height;
        return Storage::View<float>(r.storage, plane.data(), {h, w}, CStrides({h, w}, 4));
      },
      py::arg("index"), "View `index`'s depth plane, h x w float32 metres, in place.");
  a.def("set_standard_layout", [](const ARef& r) { r.mut()->SetStandardLayout(); });
  a.def("validate", [](const ARef& r) { r.get()->Validate(r.payload().size()); });
  a.def_static("message_bytes_for", &msgs::AuxiliaryViews::MessageBytesFor, py::arg("count"),
               py::arg("width"), py::arg("height"));

  Binder<msgs::TrackingStatus> tracking(m, "TrackingStatus", "The camera tracker's verdict.");
  using S = msgs::TrackingStatus;
  tracking.Struct<&S::header>("header", "")
      .Enum<&S::state>("state", kTrackingStates, "tracked, uncertain, lost")
      .Scalar<&S::score>("score", "[0, 1]")
      .Scalar<&S::reasons>("reasons", "kTrackingReason* bits")
      .Scalar<&S::integrated>("integrated", "0/1")
      .Scalar<&S::relocalised>("relocalised", "0/1")
      .Scalar<&S::rms_m>("rms_m", "ICP RMS, m")
      .Scalar<&S::inlier_fraction>("inlier_fraction", "0..1")
      .Scalar<&S::residual_ratio>("residual_ratio", "")
      .Scalar<&S::inlier_ratio>("inlier_ratio", "")
      .Scalar<&S::motion_translation_m>("motion_translation_m", "m")
      .Scalar<&S::motion_rotation_deg>("motion_rotation_deg", "deg")
      .Scalar<&S::observability>("observability", "0..1")
      .Scalar<&S::frames>("frames", "")
      .Scalar<&S::tracked_frames>("tracked_frames", "")
      .Scalar<&S::uncertain_frames>("uncertain_frames", "")
      .Scalar<&S::lost_frames>("lost_frames", "")
      .Scalar<&S::relocalisations>("relocalisations", "")
      .String<&S::reason_text>("reason_text", "one line; empty when tracked")
      .Finish();
  tracking.cls().def("validate", [](const MsgRef<S>& r) { r.get()->Validate(); });

  Binder<msgs::Ack> ack(m, "Ack", "A node's acknowledgement of one processed input.");
  ack.Struct<&msgs::Ack::header>("header", "")
      .String<&msgs::Ack::topic>("topic", "resolved input topic")
      .Scalar<&msgs::Ack::publisher_pid>("publisher_pid", "")
      .Scalar<&msgs::Ack::publish_sequence>("publish_sequence", "")
      .Finish();
  Binder<msgs::PlayerControl> control(m, "PlayerControl", "A command to the player.");
  control.Struct<&msgs::PlayerControl::header>("header", "")
      .Enum<&msgs::PlayerControl::command>("command", kPlayerCommands,
                                           "pause, resume, toggle, step, set_rate")
      .Scalar<&msgs::PlayerControl::rate>("rate", "set_rate: the new rate factor")
      .Finish();
}

}  // namespace

void BindMsgs(py::module_& m) {
  py::module_ sub = m.def_submodule("msgs", "Every probeless message type (docs/messages.md).");
  BindHeaderAndGeometry(sub);
  BindImage(sub);
  BindLight(sub);
  BindBuffers(sub);
  py::list names;
  for (const auto& [name, type] : Registry()) names.append(type.cls);
  sub.attr("ALL") = py::tuple(names);
}

}  // namespace probeless::python
