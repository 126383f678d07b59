// The memory behind every Python message object and numpy view of the probeless extension, and
// the rules that keep those views safe.
//
// A Storage is one message's bytes: a received bus sample (read-only, the publisher's shared-memory
// slot), a loaned slot (writable until published) or memory owned by the extension (a message made
// in Python, a copy, a message decoded from an MCAP log). Message objects (MsgRef) and numpy arrays
// point straight into it; every numpy view holds the Storage alive and is counted, so
// Release() of a sample or loan refuses (BufferError) while a view still exists instead of leaving
// an array that points at a slot another message may reuse. Accessing a released storage raises
// ValueError. All of it runs with the GIL held.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/log/ros2.h"
#include "probeless/node/node.h"

namespace probeless::python {

namespace py = pybind11;

// One message's bytes (the struct at byte 0, 64-byte aligned, then its payload).
class Storage {
 public:
  virtual ~Storage() = default;

  // The bytes; throws ValueError if released.
  std::byte* data() const;
  size_t size() const { return size_; }
  bool writable() const { return writable_; }
  bool released() const { return released_; }
  // Throws ValueError (naming `what()`) once released.
  void CheckAlive() const;
  // CheckAlive, then throws ValueError unless writable (a received sample is read-only).
  void CheckWritable() const;
  // "sample of /camera/image", "loan on /annotated", "probeless_msgs/Image".
  const std::string& what() const { return what_; }
  // Numpy views alive into this storage.
  int views() const { return views_; }
  // Throws BufferError naming `action` when views are alive ("cannot release ...").
  void CheckNoViews(const char* action) const;

  // A numpy array of `shape` / `strides` (bytes) of T at `ptr` (inside data()), read-only unless
  // the storage is writable; it keeps the storage alive and counts as a view until collected.
  template <class T>
  static py::array View(const std::shared_ptr<Storage>& storage, const void* ptr,
                        std::vector<py::ssize_t> shape, std::vector<py::ssize_t> strides);

 protected:
  Storage(std::string what, std::byte* data, size_t size, bool writable)
      : what_(std::move(what)), data_(data), size_(size), writable_(writable) {}
  void MarkReleased() {
    released_ = true;
    data_ = nullptr;
  }

 private:
  static py::array MakeView(const std::shared_ptr<Storage>& storage, py::dtype dtype,
                            const void* ptr, std::vector<py::ssize_t> shape,
                            std::vector<py::ssize_t> strides);
  std::string what_;
  std::byte* data_;
  size_t size_;
  bool writable_;
  bool released_ = false;
  int views_ = 0;
};

template <class T>
py::array Storage::View(const std::shared_ptr<Storage>& storage, const void* ptr,
                        std::vector<py::ssize_t> shape, std::vector<py::ssize_t> strides) {
  return MakeView(storage, py::dtype::of<T>(), ptr, std::move(shape), std::move(strides));
}

// Memory owned by the extension (zeroed, 64-byte aligned): messages made in Python, copies,
// messages decoded from logs. Writable.
class OwnedStorage : public Storage {
 public:
  // `bytes` zeroed bytes described as `what`.
  OwnedStorage(std::string what, size_t bytes);
  // Takes over a decoded message.
  OwnedStorage(std::string what, log::MessageBuffer buffer);

 private:
  log::MessageBuffer buffer_;
};

// A received sample: the publisher's slot, read-only; released by Release() or when the last
// reference (message object or view) goes.
class SampleStorage : public Storage {
 public:
  // `subscriber_mutex` serialises the release with the subscriber's own calls.
  SampleStorage(bus::Sample sample, std::string topic,
                std::shared_ptr<std::mutex> subscriber_mutex);
  ~SampleStorage() override;
  const bus::MessageInfo& info() const { return info_; }
  const std::string& topic() const { return topic_; }
  // Returns the slot to the publisher now. Throws BufferError while numpy views exist
  // (idempotent once released).
  void Release();

 private:
  bus::Sample sample_;
  bus::MessageInfo info_;
  std::string topic_;
  std::shared_ptr<std::mutex> mutex_;
};

// What a Python Publisher wraps: the bus publisher, its message type and a mutex for its calls.
struct PublisherState {
  PublisherState(bus::Publisher p, std::string name, uint64_t hash)
      : publisher(std::move(p)), type_name(std::move(name)), layout_hash(hash) {}
  bus::Publisher publisher;
  std::string type_name;
  uint64_t layout_hash = 0;
  std::mutex mutex;
};

// A loaned slot of a publisher: writable until published or dropped.
class LoanStorage : public Storage {
 public:
  LoanStorage(bus::Loan loan, std::shared_ptr<PublisherState> publisher);
  ~LoanStorage() override;
  // Publishes the slot (its first `bytes` bytes; 0 = the whole loan) and returns the sequence.
  // Throws BufferError while numpy views exist, ValueError once published or dropped.
  uint64_t Publish();
  // Returns the slot unpublished (idempotent). Throws BufferError while numpy views exist.
  void Drop();
  const std::shared_ptr<PublisherState>& publisher() const { return publisher_; }

 private:
  bus::Loan loan_;
  std::shared_ptr<PublisherState> publisher_;
};

// A message object of type M: the struct at `offset` of `storage` (offset 0 and `top` for a whole
// message, whose payload follows the struct; nested structs such as a header have top false).
template <class M>
struct MsgRef {
  std::shared_ptr<Storage> storage;
  size_t offset = 0;
  bool top = true;

  // The struct for reading (throws ValueError once released).
  const M* get() const { return reinterpret_cast<const M*>(storage->data() + offset); }
  // The struct for writing (throws ValueError when read-only or released).
  M* mut() const {
    storage->CheckWritable();
    return reinterpret_cast<M*>(storage->data() + offset);
  }
  // The payload after a whole message; throws ValueError for a nested struct.
  std::span<std::byte> payload() const {
    if (!top) throw py::value_error("a nested " + std::string(M::kTypeName) + " has no payload");
    std::byte* bytes = storage->data();
    return {bytes + sizeof(M), storage->size() - sizeof(M)};
  }
};

struct AnyMsg;

// Describes a bound message class: what subscribers, publishers and readers need of it.
struct MessageType {
  std::string name;  // "probeless_msgs/Image"
  uint64_t layout_hash = 0;
  size_t struct_bytes = 0;
  bool has_payload = false;
  py::handle cls;  // the Python class (kept alive by the module: no reference held at exit)
  // The Python message object over a whole message in `storage` (throws MessageError if the
  // bytes are fewer than the struct).
  std::function<py::object(std::shared_ptr<Storage>)> wrap;
  // Fills `out` and returns true if `object` is a message object of this type.
  std::function<bool(py::handle object, AnyMsg* out)> unwrap;
  // node::Node::CreatePublisher<M> / CreateSubscriber<M> of the C++ runtime.
  std::function<bus::Publisher(node::Node&, std::string_view, bus::PublisherOptions)>
      create_publisher;
  std::function<bus::Subscriber(node::Node&, std::string_view, bus::SubscriberOptions)>
      create_subscriber;
};

// The storage and offset behind a message object of any bound type.
struct AnyMsg {
  const MessageType* type = nullptr;
  std::shared_ptr<Storage> storage;
  size_t offset = 0;
  bool top = true;
};

// The registered message type of a Python class (e.g. probeless.msgs.Image) or a type name;
// throws TypeError for anything else.
const MessageType& MessageTypeOf(py::handle cls_or_name);
// The registered type of this name, or null.
const MessageType* FindMessageType(const std::string& name);
// The storage and offset behind a message object of any bound type; throws TypeError otherwise.
AnyMsg AnyMsgOf(py::handle message);

// Registration of each part of the module.
void BindErrors(py::module_& m);
void BindMsgs(py::module_& m);
void BindBus(py::module_& m);
void BindNode(py::module_& m);
void BindLog(py::module_& m);
void BindEstimators(py::module_& m);

}  // namespace probeless::python
