// The extension module probeless._probeless: its errors, the bus (Publisher, Subscriber, Sample,
// Loan, introspection) and the node runtime (node::Node and the process-wide shutdown state).
#include <pybind11/chrono.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <chrono>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/face_light/model.h"
#include "probeless/light/directions.h"
#include "probeless/log/mcap.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "storage.h"

namespace probeless::python {

namespace {

// What a Python Subscriber wraps; `subscriber` is reset by close().
struct SubscriberState {
  std::optional<bus::Subscriber> subscriber;
  std::shared_ptr<std::mutex> mutex = std::make_shared<std::mutex>();
  const MessageType* type = nullptr;

  bus::Subscriber& Get() {
    if (!subscriber) throw py::value_error("probeless: the subscriber was closed");
    return *subscriber;
  }
};

struct PySubscriber {
  std::shared_ptr<SubscriberState> state;
};

struct PyPublisher {
  std::shared_ptr<PublisherState> state;
  const MessageType* type = nullptr;
  bool closed = false;

  PublisherState& Get() const {
    if (closed) throw py::value_error("probeless: the publisher was closed");
    return *state;
  }
};

struct PySample {
  std::shared_ptr<SampleStorage> storage;
  const MessageType* type = nullptr;
};

struct PyLoan {
  std::shared_ptr<LoanStorage> storage;
  const MessageType* type = nullptr;
};

// Seconds (None = no limit) as a timeout.
std::chrono::nanoseconds TimeoutOf(const std::optional<double>& seconds) {
  if (!seconds) return std::chrono::hours(24 * 365);
  if (!(*seconds >= 0)) throw py::value_error("probeless: timeout must be >= 0 seconds");
  return std::chrono::nanoseconds(static_cast<int64_t>(*seconds * 1e9));
}

PySample Wrap(bus::Sample sample, SubscriberState& state) {
  auto storage =
      std::make_shared<SampleStorage>(std::move(sample), state.Get().topic(), state.mutex);
  // The size and alignment checks of the type (MessageError) before anything reads it.
  state.type->wrap(storage);
  return PySample{std::move(storage), state.type};
}

// Blocks until a sample, the timeout or shutdown (checked every node::kShutdownPollPeriod);
// without a Node's handlers a signal Python handles (SIGINT: KeyboardInterrupt) raises.
std::optional<PySample> Take(SubscriberState& state, const std::optional<double>& timeout) {
  const auto deadline = std::chrono::steady_clock::now() + TimeoutOf(timeout);
  std::optional<bus::Sample> sample;
  {
    py::gil_scoped_release unlocked;
    do {
      const auto remaining = deadline - std::chrono::steady_clock::now();
      const auto wait = std::max<std::chrono::nanoseconds>(
          std::chrono::nanoseconds(0),
          std::min<std::chrono::nanoseconds>(remaining, node::kShutdownPollPeriod));
      {
        std::lock_guard lock(*state.mutex);
        sample = state.Get().Take(wait);
      }
      if (!sample) {
        // Python's own handlers (a script without a Node): Ctrl-C raises KeyboardInterrupt.
        py::gil_scoped_acquire locked;
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
      }
    } while (!sample && node::ok() && std::chrono::steady_clock::now() < deadline);
  }
  if (!sample) return std::nullopt;
  return Wrap(std::move(*sample), state);
}

PyLoan Borrow(const PyPublisher& publisher, size_t bytes) {
  PublisherState& state = publisher.Get();
  if (bytes < publisher.type->struct_bytes) bytes = publisher.type->struct_bytes;
  bus::Loan loan;
  {
    std::lock_guard lock(state.mutex);
    loan = state.publisher.Borrow(bytes);
  }
  auto storage = std::make_shared<LoanStorage>(std::move(loan), publisher.state);
  std::memset(storage->data(), 0, publisher.type->struct_bytes);  // the struct value-initialised
  return PyLoan{std::move(storage), publisher.type};
}

uint64_t PublishCopy(const PyPublisher& publisher, const AnyMsg& message) {
  PublisherState& state = publisher.Get();
  if (message.type == nullptr || message.type->name != state.type_name) {
    throw py::type_error("probeless: publisher on " + state.publisher.topic() + " carries " +
                         state.type_name + ", not " +
                         (message.type ? message.type->name : std::string("this object")));
  }
  const size_t bytes = message.top ? message.storage->size() : message.type->struct_bytes;
  const std::byte* source = message.storage->data() + message.offset;
  py::gil_scoped_release unlocked;
  std::lock_guard lock(state.mutex);
  return state.publisher.PublishCopy({source, bytes});
}

py::dict TopicTypeDict(const bus::TopicType& type) {
  py::dict d;
  d["name"] = type.name;
  d["layout_hash"] = type.layout_hash;
  return d;
}

py::list ListTopics(const std::string& domain) {
  py::list out;
  for (const bus::TopicSnapshot& t : bus::ListTopics(domain)) {
    py::dict topic;
    topic["topic"] = t.topic;
    topic["type"] = TopicTypeDict(t.type);
    py::list publishers;
    for (const auto& p : t.publishers) {
      py::dict d;
      d["pid"] = p.pid;
      d["alive"] = p.alive;
      d["node_name"] = p.node_name;
      d["max_message_bytes"] = p.max_message_bytes;
      d["slot_count"] = p.slot_count;
      d["history"] = p.history;
      d["published"] = p.published;
      d["published_bytes"] = p.published_bytes;
      d["last_publish_mono_ns"] = p.last_publish_mono_ns;
      publishers.append(d);
    }
    py::list subscribers;
    for (const auto& s : t.subscribers) {
      py::dict d;
      d["pid"] = s.pid;
      d["alive"] = s.alive;
      d["node_name"] = s.node_name;
      d["queue_depth"] = s.queue_depth;
      d["queued"] = s.queued;
      d["received"] = s.received;
      d["dropped"] = s.dropped;
      subscribers.append(d);
    }
    topic["publishers"] = publishers;
    topic["subscribers"] = subscribers;
    out.append(topic);
  }
  return out;
}

// --- Node ----------------------------------------------------------------------------------------

struct Subscription {
  std::shared_ptr<SubscriberState> state;
  py::object callback;
};

struct PyNode {
  std::unique_ptr<node::Node> node;
  std::list<Subscription> subscriptions;

  node::Node& Get() const { return *node; }
};

// The C++ parameter type named by `type` (a Python type or a ParamInfo type name).
std::string ParamTypeName(py::handle type) {
  if (py::isinstance<py::str>(type)) return type.cast<std::string>();
  if (type.is(py::type::of(py::bool_()))) return "bool";
  if (type.is(py::type::of(py::int_()))) return "integer";
  if (type.is(py::type::of(py::float_()))) return "double";
  if (type.is(py::type::of(py::str()))) return "string";
  throw py::type_error(
      "probeless: parameter type must be bool, int, float, str or one of "
      "'double_array', 'integer_array', 'string_array'");
}

// The type of a default value: bool, int, float, str or a list of one of them.
std::string ParamTypeOfValue(py::handle value) {
  if (py::isinstance<py::bool_>(value)) return "bool";
  if (py::isinstance<py::int_>(value)) return "integer";
  if (py::isinstance<py::float_>(value)) return "double";
  if (py::isinstance<py::str>(value)) return "string";
  if (py::isinstance<py::list>(value) || py::isinstance<py::tuple>(value)) {
    const py::sequence seq = py::reinterpret_borrow<py::sequence>(value);
    if (seq.size() == 0) {
      throw py::type_error(
          "probeless: an empty list default needs type='double_array', 'integer_array' or "
          "'string_array'");
    }
    bool all_int = true;
    bool all_number = true;
    bool all_str = true;
    for (py::handle item : seq) {
      const bool is_bool = py::isinstance<py::bool_>(item);
      all_int = all_int && py::isinstance<py::int_>(item) && !is_bool;
      all_number = all_number && !is_bool &&
                   (py::isinstance<py::int_>(item) || py::isinstance<py::float_>(item));
      all_str = all_str && py::isinstance<py::str>(item);
    }
    if (all_int) return "integer_array";
    if (all_number) return "double_array";
    if (all_str) return "string_array";
  }
  throw py::type_error(
      "probeless: parameter default must be bool, int, float, str or a list of "
      "numbers or strings, got " +
      py::repr(value).cast<std::string>());
}

py::object Param(node::Node& node, const std::string& name, py::handle default_value,
                 const std::string& type, bool required) {
  if (type == "bool") {
    return py::cast(required ? node.RequireParam<bool>(name)
                             : node.Param<bool>(name, default_value.cast<bool>()));
  }
  if (type == "integer") {
    return py::cast(required ? node.RequireParam<int64_t>(name)
                             : node.Param<int64_t>(name, default_value.cast<int64_t>()));
  }
  if (type == "double") {
    return py::cast(required ? node.RequireParam<double>(name)
                             : node.Param<double>(name, default_value.cast<double>()));
  }
  if (type == "string") {
    return py::cast(required ? node.RequireParam<std::string>(name)
                             : node.Param<std::string>(name, default_value.cast<std::string>()));
  }
  if (type == "double_array") {
    using V = std::vector<double>;
    return py::cast(required ? node.RequireParam<V>(name)
                             : node.Param<V>(name, default_value.cast<V>()));
  }
  if (type == "integer_array") {
    using V = std::vector<int64_t>;
    return py::cast(required ? node.RequireParam<V>(name)
                             : node.Param<V>(name, default_value.cast<V>()));
  }
  if (type == "string_array") {
    using V = std::vector<std::string>;
    return py::cast(required ? node.RequireParam<V>(name)
                             : node.Param<V>(name, default_value.cast<V>()));
  }
  throw py::value_error("probeless: unknown parameter type '" + type +
                        "' (expected bool, integer, double, string, double_array, "
                        "integer_array or string_array)");
}

std::vector<std::string> ArgvOf(const std::optional<std::vector<std::string>>& argv) {
  if (argv) return *argv;
  return py::module_::import("sys").attr("argv").cast<std::vector<std::string>>();
}

void Spin(PyNode& self) {
  std::vector<node::Handler> handlers;
  for (Subscription& s : self.subscriptions) {
    SubscriberState* state = s.state.get();
    py::object* callback = &s.callback;
    handlers.push_back({&state->Get(), [state, callback](bus::Sample&& sample) {
                          py::gil_scoped_acquire locked;
                          PySample wrapped = Wrap(std::move(sample), *state);
                          (*callback)(wrapped);
                          // Valid for the callback only: released before the next one (and before
                          // the acknowledgement), BufferError if it kept a numpy view.
                          wrapped.storage->Release();
                        }});
  }
  py::gil_scoped_release unlocked;
  self.Get().Spin(handlers);
}

}  // namespace

void BindErrors(py::module_& m) {
  py::register_exception<bus::BusError>(m, "BusError", PyExc_RuntimeError);
  py::register_exception<node::NodeError>(m, "NodeError", PyExc_ValueError);
  py::register_exception<msgs::MessageError>(m, "MessageError", PyExc_ValueError);
  py::register_exception<log::LogError>(m, "LogError", PyExc_RuntimeError);
  py::register_exception<light::LightError>(m, "LightError", PyExc_ValueError);
  py::register_exception<face_light::FaceLightError>(m, "FaceLightError", PyExc_ValueError);
}

void BindBus(py::module_& m) {
  py::class_<bus::MessageInfo>(m, "MessageInfo", "Bus metadata of a received message.")
      .def_readonly("sequence", &bus::MessageInfo::sequence, "1, 2, 3, ... per publisher")
      .def_readonly("publish_mono_ns", &bus::MessageInfo::publish_mono_ns,
                    "CLOCK_MONOTONIC at publish, ns")
      .def_readonly("publish_wall_ns", &bus::MessageInfo::publish_wall_ns,
                    "CLOCK_REALTIME at publish, ns")
      .def_readonly("size", &bus::MessageInfo::size, "payload bytes")
      .def_readonly("publisher_pid", &bus::MessageInfo::publisher_pid)
      .def_readonly("publisher_index", &bus::MessageInfo::publisher_index);

  py::class_<PySample>(m, "Sample",
                       "A received message: a read-only view of the publisher's shared-memory "
                       "slot, held until release() (or the end of a with block).")
      .def_property_readonly(
          "msg", [](const PySample& s) { return s.type->wrap(s.storage); },
          "The message object over the slot (fields and numpy views in place).")
      .def_property_readonly(
          "info", [](const PySample& s) { return s.storage->info(); }, "bus metadata")
      .def_property_readonly("topic", [](const PySample& s) { return s.storage->topic(); })
      .def_property_readonly("released", [](const PySample& s) { return s.storage->released(); })
      .def(
          "release", [](const PySample& s) { s.storage->Release(); },
          "Returns the slot to the publisher now. Raises BufferError while numpy views of it "
          "exist (del them or copy first); idempotent.")
      .def(
          "copy", [](const PySample& s) { return s.type->wrap(s.storage).attr("copy")(); },
          "An owned copy of the message (valid after release).")
      .def("__repr__",
           [](const PySample& s) {
             return "<probeless.Sample " + s.type->name + " #" +
                    std::to_string(s.storage->info().sequence) + " of " + s.storage->topic() +
                    (s.storage->released() ? " (released)>" : ">");
           })
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](const PySample& s, py::object type, py::object, py::object) {
        if (type.is_none()) {
          s.storage->Release();
        } else if (s.storage->views() == 0) {
          s.storage->Release();  // with an exception in flight: never mask it with BufferError
        }
        return false;
      });

  py::class_<PyLoan>(m, "Loan",
                     "A slot loaned from a publisher's shared-memory pool: fill msg in place, "
                     "then publish(); dropped (unpublished) by drop() or a with block's end.")
      .def_property_readonly(
          "msg", [](const PyLoan& l) { return l.type->wrap(l.storage); },
          "The message object over the slot (writable; the struct starts zeroed, the payload "
          "holds whatever the slot held)")
      .def_property_readonly("size", [](const PyLoan& l) { return l.storage->size(); })
      .def_property_readonly("released", [](const PyLoan& l) { return l.storage->released(); })
      .def(
          "publish", [](const PyLoan& l) { return l.storage->Publish(); },
          "Publishes the slot to every subscriber; returns its sequence number. Raises "
          "BufferError while numpy views of it exist.")
      .def(
          "drop", [](const PyLoan& l) { l.storage->Drop(); },
          "Returns the slot unpublished (idempotent).")
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](const PyLoan& l, py::object type, py::object, py::object) {
        if (type.is_none() || l.storage->views() == 0) l.storage->Drop();
        return false;
      });

  py::class_<PyPublisher>(m, "Publisher", "A bus publisher of one message type.")
      .def(py::init([](const std::string& topic, py::handle msg_type, size_t max_message_bytes,
                       uint32_t slot_count, uint32_t history, const std::string& node_name) {
             const MessageType& type = MessageTypeOf(msg_type);
             bus::PublisherOptions options;
             options.max_message_bytes = max_message_bytes ? max_message_bytes : type.struct_bytes;
             options.slot_count = slot_count;
             options.history = history;
             options.node_name = node_name;
             auto state = std::make_shared<PublisherState>(
                 bus::Publisher(topic, bus::TopicType{type.name, type.layout_hash}, options),
                 type.name, type.layout_hash);
             return PyPublisher{std::move(state), &type};
           }),
           py::arg("topic"), py::arg("msg_type"), py::arg("max_message_bytes") = 0,
           py::arg("slot_count") = 32, py::arg("history") = 0, py::arg("node_name") = "",
           "Joins absolute `topic` (no node: Node.create_publisher resolves names). "
           "max_message_bytes 0 = the struct size. Raises BusError on a bad name, a type "
           "mismatch or exhausted limits.")
      .def(
          "loan",
          [](const PyPublisher& p, size_t payload_bytes) {
            return Borrow(p, p.type->struct_bytes + payload_bytes);
          },
          py::arg("payload_bytes") = 0,
          "A zeroed struct with `payload_bytes` after it, in a slot of this publisher.")
      .def(
          "loan_image",
          [](const PyPublisher& p, uint32_t width, uint32_t height, const std::string& encoding) {
            if (p.type->name != msgs::Image::kTypeName) {
              throw py::type_error("probeless: loan_image on a publisher of " + p.type->name);
            }
            const msgs::Encoding e = msgs::EncodingFromName(encoding);
            PyLoan loan = Borrow(p, msgs::Image::MessageBytesFor(width, height, e));
            reinterpret_cast<msgs::Image*>(loan.storage->data())->Init(width, height, e);
            return loan;
          },
          py::arg("width"), py::arg("height"), py::arg("encoding"),
          "A packed image of this size and encoding: write loan.msg.pixels in place.")
      .def(
          "loan_geometry_buffer",
          [](const PyPublisher& p, uint32_t width, uint32_t height) {
            if (p.type->name != msgs::GeometryBuffer::kTypeName) {
              throw py::type_error("probeless: loan_geometry_buffer on a publisher of " +
                                   p.type->name);
            }
            PyLoan loan = Borrow(p, msgs::GeometryBuffer::MessageBytesFor(width, height));
            reinterpret_cast<msgs::GeometryBuffer*>(loan.storage->data())->Init(width, height);
            return loan;
          },
          py::arg("width"), py::arg("height"))
      .def(
          "loan_transfer_buffer",
          [](const PyPublisher& p, uint32_t width, uint32_t height, uint32_t count) {
            if (p.type->name != msgs::TransferBuffer::kTypeName) {
              throw py::type_error("probeless: loan_transfer_buffer on a publisher of " +
                                   p.type->name);
            }
            msgs::TransferBuffer probe;
            probe.Init(width, height, count);
            PyLoan loan = Borrow(p, msgs::TransferBuffer::MessageBytesFor(width, height, count));
            *reinterpret_cast<msgs::TransferBuffer*>(loan.storage->data()) = probe;
            return loan;
          },
          py::arg("width"), py::arg("height"), py::arg("coefficient_count"))
      .def(
          "publish",
          [](const PyPublisher& p, py::handle what) -> uint64_t {
            if (py::isinstance<PyLoan>(what)) {
              const PyLoan& loan = what.cast<const PyLoan&>();
              if (loan.storage->publisher() != p.state) {
                throw py::value_error("probeless: the loan belongs to another publisher (" +
                                      loan.storage->what() + ")");
              }
              return loan.storage->Publish();
            }
            return PublishCopy(p, AnyMsgOf(what));
          },
          py::arg("loan_or_message"),
          "Publishes a loan of this publisher (zero copy) or a copy of a message of its type; "
          "returns the sequence number. TypeError for another type.")
      .def_property_readonly(
          "subscriber_count",
          [](const PyPublisher& p) { return p.Get().publisher.SubscriberCount(); })
      .def_property_readonly("topic",
                             [](const PyPublisher& p) { return p.Get().publisher.topic(); })
      .def_property_readonly("msg_type", [](const PyPublisher& p) { return p.type->cls; })
      .def_property_readonly(
          "max_message_bytes",
          [](const PyPublisher& p) { return p.Get().publisher.max_message_bytes(); })
      .def(
          "close", [](PyPublisher& p) { p.closed = true; },
          "Stops using the publisher; it leaves the topic once its loans are gone.")
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](PyPublisher& p, py::object, py::object, py::object) {
        p.closed = true;
        return false;
      });

  py::class_<PySubscriber>(m, "Subscriber", "A bus subscriber of one message type.")
      .def(py::init([](const std::string& topic, py::handle msg_type, uint32_t queue_depth,
                       bool receive_history, const std::string& node_name) {
             const MessageType& type = MessageTypeOf(msg_type);
             bus::SubscriberOptions options;
             options.queue_depth = queue_depth;
             options.receive_history = receive_history;
             options.node_name = node_name;
             auto state = std::make_shared<SubscriberState>();
             state->subscriber.emplace(topic, bus::TopicType{type.name, type.layout_hash}, options);
             state->type = &type;
             return PySubscriber{std::move(state)};
           }),
           py::arg("topic"), py::arg("msg_type"), py::arg("queue_depth") = 2,
           py::arg("receive_history") = true, py::arg("node_name") = "",
           "Joins absolute `topic`. Raises BusError on a bad name, a type mismatch (naming both "
           "types) or exhausted limits.")
      .def(
          "take",
          [](const PySubscriber& s, std::optional<double> timeout) {
            return Take(*s.state, timeout);
          },
          py::arg("timeout") = py::none(),
          "The oldest queued sample, waiting up to `timeout` seconds (None: no limit); None "
          "after the timeout or on shutdown (SIGINT/SIGTERM). The GIL is released meanwhile.")
      .def(
          "try_take",
          [](const PySubscriber& s) -> std::optional<PySample> {
            std::optional<bus::Sample> sample;
            {
              std::lock_guard lock(*s.state->mutex);
              sample = s.state->Get().TryTake();
            }
            if (!sample) return std::nullopt;
            return Wrap(std::move(*sample), *s.state);
          },
          "The oldest queued sample or None, without waiting.")
      .def("__iter__", [](py::object self) { return self; })
      .def(
          "__next__",
          [](const PySubscriber& s) {
            std::optional<PySample> sample = Take(*s.state, std::nullopt);
            if (!sample) throw py::stop_iteration();
            return std::move(*sample);
          },
          "for sample in subscriber: the samples until shutdown (SIGINT/SIGTERM).")
      .def_property_readonly(
          "dropped", [](const PySubscriber& s) { return s.state->Get().dropped(); },
          "messages lost to drop-oldest so far")
      .def_property_readonly("queued",
                             [](const PySubscriber& s) { return s.state->Get().queued(); })
      .def_property_readonly("publisher_count",
                             [](const PySubscriber& s) { return s.state->Get().PublisherCount(); })
      .def_property_readonly("topic", [](const PySubscriber& s) { return s.state->Get().topic(); })
      .def_property_readonly("msg_type", [](const PySubscriber& s) { return s.state->type->cls; })
      .def(
          "close",
          [](const PySubscriber& s) {
            std::lock_guard lock(*s.state->mutex);
            s.state->subscriber.reset();
          },
          "Leaves the topic now (samples already taken stay valid).")
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](const PySubscriber& s, py::object, py::object, py::object) {
        std::lock_guard lock(*s.state->mutex);
        s.state->subscriber.reset();
        return false;
      });

  m.def("current_domain", &bus::CurrentDomain, "$PROBELESS_DOMAIN, or '0'.");
  m.def(
      "validate_topic_name", [](const std::string& t) { bus::ValidateTopicName(t); },
      py::arg("topic"), "Raises BusError unless `topic` is a valid absolute topic name.");
  m.def("list_topics", &ListTopics, py::arg("domain") = bus::CurrentDomain(),
        "Every topic of this user in `domain` with its publishers and subscribers (dicts), read "
        "without joining them.");
  m.def("clean_dead_segments", &bus::CleanDeadSegments, py::arg("domain") = bus::CurrentDomain(),
        "Removes segments of dead processes; returns the names removed.");
}

void BindNode(py::module_& m) {
  m.def("ok", &node::ok, "False once SIGINT/SIGTERM arrived or shutdown was requested.");
  m.def("request_shutdown", &node::RequestShutdown, "Makes ok() false and wakes every waiter.");
  m.def(
      "wait_for_shutdown",
      [](std::optional<double> timeout) {
        const auto t = TimeoutOf(timeout);
        py::gil_scoped_release unlocked;
        return node::WaitForShutdown(t);
      },
      py::arg("timeout") = py::none(),
      "Blocks until shutdown or `timeout` seconds; returns not ok().");
  m.def("install_signal_handlers", &node::InstallSignalHandlers,
        "The C++ runtime's SIGINT/SIGTERM handlers (every Node installs them).");

  py::class_<node::Rate>(m, "Rate", "Paces a loop: while rate.sleep(): ...")
      .def(py::init<double>(), py::arg("hz"), "Raises NodeError unless hz is finite and > 0.")
      .def(
          "sleep",
          [](node::Rate& r) {
            py::gil_scoped_release unlocked;
            return r.Sleep();
          },
          "Sleeps until the next deadline or shutdown; returns ok().")
      .def_property_readonly("period",
                             [](const node::Rate& r) { return r.period().count() * 1e-9; });

  py::class_<node::ParamInfo>(m, "ParamInfo", "A declared parameter.")
      .def_readonly("name", &node::ParamInfo::name)
      .def_readonly("type", &node::ParamInfo::type)
      .def_readonly("value", &node::ParamInfo::value)
      .def_readonly("source", &node::ParamInfo::source)
      .def_readonly("description", &node::ParamInfo::description)
      .def_readonly("unit", &node::ParamInfo::unit)
      .def_readonly("constraint", &node::ParamInfo::constraint)
      .def("__repr__", [](const node::ParamInfo& p) {
        return "<ParamInfo " + p.name + ": " + p.type + " = " + p.value + " (" + p.source + ")>";
      });

  py::class_<PyNode>(m, "Node", "The C++ node runtime (common/node) for a Python process.")
      .def(py::init([](const std::string& default_name,
                       const std::optional<std::vector<std::string>>& argv,
                       const std::string& usage) {
             const std::vector<std::string> args = ArgvOf(argv);
             PyNode self;
             self.node = std::make_unique<node::Node>(args, default_name, usage);
             return self;
           }),
           py::arg("default_name"), py::arg("argv") = py::none(), py::arg("usage") = "",
           "Parses argv (default sys.argv; argv[0] is the program) with ROS 2 conventions: own "
           "arguments, then --ros-args with -p name:=value, -r from:=to, __node, __ns, "
           "--params-file, --log-level. Installs the SIGINT/SIGTERM handlers. Raises NodeError "
           "on a malformed argument or file; --help prints usage and exits 0.")
      .def_property_readonly("name", [](const PyNode& n) { return n.Get().name(); })
      .def_property_readonly("namespace", [](const PyNode& n) { return n.Get().namespace_(); })
      .def_property_readonly("fully_qualified_name",
                             [](const PyNode& n) { return n.Get().fully_qualified_name(); })
      .def_property_readonly("program", [](const PyNode& n) { return n.Get().program(); })
      .def_property_readonly(
          "args", [](const PyNode& n) { return n.Get().args(); },
          "the node's own arguments (not the ROS ones)")
      .def(
          "param",
          [](PyNode& n, const std::string& name, py::object default_value,
             std::optional<py::object> type) {
            const std::string t = type ? ParamTypeName(*type) : ParamTypeOfValue(default_value);
            return Param(n.Get(), name, default_value, t, false);
          },
          py::arg("name"), py::arg("default"), py::arg("type") = py::none(),
          "The override (-p or params file) of parameter `name`, else `default`; the type is "
          "the default's (bool, int, float, str, list) or `type`. Raises NodeError if the "
          "override has another type.")
      .def(
          "require_param",
          [](PyNode& n, const std::string& name, py::object type) {
            return Param(n.Get(), name, py::none(), ParamTypeName(type), true);
          },
          py::arg("name"), py::arg("type"), "Like param, but NodeError without an override.")
      .def("has_param_override",
           [](const PyNode& n, const std::string& name) { return n.Get().HasParamOverride(name); })
      .def("declared_params", [](const PyNode& n) { return n.Get().DeclaredParams(); })
      .def("unused_param_overrides", [](const PyNode& n) { return n.Get().UnusedParamOverrides(); })
      .def(
          "check_param_overrides", [](const PyNode& n) { n.Get().CheckParamOverrides(); },
          "Raises NodeError for an override no param() call has read (wildcard params-file "
          "entries excepted), naming the nearest declared parameter.")
      .def(
          "resolve_topic_name",
          [](const PyNode& n, const std::string& name) { return n.Get().ResolveTopicName(name); },
          py::arg("name"), "Namespace, ~, substitutions and remaps applied; NodeError if invalid.")
      .def(
          "create_publisher",
          [](PyNode& n, py::handle msg_type, const std::string& topic, size_t max_message_bytes,
             uint32_t slot_count, uint32_t history) {
            const MessageType& type = MessageTypeOf(msg_type);
            bus::PublisherOptions options;
            options.max_message_bytes = max_message_bytes;
            options.slot_count = slot_count;
            options.history = history;
            auto state = std::make_shared<PublisherState>(
                type.create_publisher(n.Get(), topic, options), type.name, type.layout_hash);
            return PyPublisher{std::move(state), &type};
          },
          py::arg("msg_type"), py::arg("topic"), py::arg("max_message_bytes") = 0,
          py::arg("slot_count") = 32, py::arg("history") = 0,
          "A publisher on the resolved `topic` (node::Node::CreatePublisher). Types with a "
          "payload need max_message_bytes (e.g. msgs.Image.message_bytes_for(640, 480, 'rgb8')).")
      .def(
          "create_subscriber",
          [](PyNode& n, py::handle msg_type, const std::string& topic, uint32_t queue_depth,
             bool receive_history) {
            const MessageType& type = MessageTypeOf(msg_type);
            bus::SubscriberOptions options;
            options.queue_depth = queue_depth;
            options.receive_history = receive_history;
            auto state = std::make_shared<SubscriberState>();
            state->subscriber.emplace(type.create_subscriber(n.Get(), topic, options));
            state->type = &type;
            return PySubscriber{std::move(state)};
          },
          py::arg("msg_type"), py::arg("topic"), py::arg("queue_depth") = 2,
          py::arg("receive_history") = true,
          "A subscriber on the resolved `topic` (node::Node::CreateSubscriber), for take().")
      .def(
          "create_subscription",
          [](PyNode& n, py::handle msg_type, const std::string& topic, py::object callback,
             uint32_t queue_depth, bool receive_history) {
            const MessageType& type = MessageTypeOf(msg_type);
            bus::SubscriberOptions options;
            options.queue_depth = queue_depth;
            options.receive_history = receive_history;
            auto state = std::make_shared<SubscriberState>();
            state->subscriber.emplace(type.create_subscriber(n.Get(), topic, options));
            state->type = &type;
            n.subscriptions.push_back({state, std::move(callback)});
            return PySubscriber{std::move(state)};
          },
          py::arg("msg_type"), py::arg("topic"), py::arg("callback"), py::arg("queue_depth") = 2,
          py::arg("receive_history") = true,
          "A subscriber whose samples spin() passes to callback(sample); the sample is valid "
          "during the call only (copy what you keep).")
      .def("spin", &Spin,
           "node::Node::Spin over the subscriptions until shutdown: callbacks in arrival order, "
           "several ready topics in creation order, each input acknowledged on <node>/ack "
           "(lock-step replay). An exception in a callback stops spin and propagates.")
      .def(
          "ack",
          [](PyNode& n, const PySubscriber& from, const bus::MessageInfo& info) {
            n.Get().Ack(from.state->Get(), info);
          },
          py::arg("subscriber"), py::arg("info"),
          "Acknowledges an input taken from `subscriber` (sample.info) on <node>/ack, for nodes "
          "that take() instead of spin().")
      .def_property_readonly("ack_topic", [](const PyNode& n) { return n.Get().AckTopic(); })
      .def_property(
          "log_level",
          [](const PyNode& n) { return std::string(node::LogLevelName(n.Get().log_level())); },
          [](PyNode& n, const std::string& level) {
            n.Get().set_log_level(node::ParseLogLevel(level));
          },
          "debug, info, warn or error")
      .def(
          "log",
          [](const PyNode& n, const std::string& level, const std::string& message) {
            n.Get().Log(node::ParseLogLevel(level), message);
          },
          py::arg("level"), py::arg("message"),
          "Writes '[level] [fqn] message' to stderr if the level is enabled.")
      .def("debug",
           [](const PyNode& n, const std::string& s) { n.Get().Log(node::LogLevel::kDebug, s); })
      .def("info",
           [](const PyNode& n, const std::string& s) { n.Get().Log(node::LogLevel::kInfo, s); })
      .def("warn",
           [](const PyNode& n, const std::string& s) { n.Get().Log(node::LogLevel::kWarn, s); })
      .def("error",
           [](const PyNode& n, const std::string& s) { n.Get().Log(node::LogLevel::kError, s); })
      .def("ok", [](const PyNode&) { return node::ok(); });
}

}  // namespace probeless::python

PYBIND11_MODULE(_probeless, m) {
  using namespace probeless::python;
  m.doc() = "probeless C++ core (bus, node runtime, messages, logs, estimators)";
  BindErrors(m);
  BindMsgs(m);
  BindBus(m);
  BindNode(m);
  BindLog(m);
  BindEstimators(m);
}
