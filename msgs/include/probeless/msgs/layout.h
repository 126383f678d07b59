// Layout machinery shared by every probeless message type.
//
// A message is one plain struct (trivially copyable, standard layout, fixed-width fields, explicit
// padding) placed at the start of a bus slot, optionally followed in the same slot by a variable
// payload (pixels, planes, coefficients). The payload starts at byte sizeof(M) of the slot, which
// is a multiple of kPayloadAlignment (64) for every type with a payload, so pixel rows are
// cache-line aligned and no copy is ever needed.
//
// Every message type M provides
//   static constexpr std::string_view kTypeName;      e.g. "probeless_msgs/Image"
//   static constexpr bool kHasPayload;                 whether bytes follow the struct
//   static constexpr std::string LayoutDescription(); "<type>{field:type@offset;...}size=N,align=A"
//   static const uint64_t kLayoutHash;                 FNV-1a 64 of LayoutDescription(), defined
//                                                      constexpr right after the struct (it needs
//                                                      the complete type for offsetof), so it is a
//                                                      compile-time constant like a static
//                                                      constexpr.
// The description is derived from the real struct (offsetof, sizeof, member types) by
// LayoutBuilder, which also rejects (at compile time) any implicit padding or unlisted field: the
// fields listed must tile the struct exactly. Nested structs contribute their own full description,
// enums their underlying type and every enumerator value, so any layout change changes the hash.
#pragma once

#include <cstddef>
#include <cstdint>
#include <new>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>

#include "probeless/bus/bus.h"
#include "probeless/error/error.h"

namespace probeless::msgs {

// The exception for bad message contents or sizes at a boundary (payload too small, unknown
// encoding, string too long, ...). what() is one line naming the message type and the problem.
class MessageError : public InputError {
 public:
  using InputError::InputError;
};

// Byte alignment of a payload relative to the slot start (the bus aligns slots to 64 bytes).
inline constexpr size_t kPayloadAlignment = 64;

// Capacity of every frame-id field in bytes, including the terminating NUL (so 31 characters).
inline constexpr size_t kFrameIdCapacity = 32;

namespace layout {

// FNV-1a, 64-bit (offset basis 0xcbf29ce484222325, prime 0x100000001b3) over the bytes of `text`.
constexpr uint64_t Fnv1a64(std::string_view text) {
  uint64_t hash = 0xcbf29ce484222325ull;
  for (char c : text) {
    hash ^= static_cast<uint8_t>(c);
    hash *= 0x100000001b3ull;
  }
  return hash;
}

// Decimal text of `value` (usable in constant expressions).
constexpr std::string Decimal(uint64_t value) {
  std::string digits;
  do {
    digits.insert(digits.begin(), static_cast<char>('0' + value % 10));
    value /= 10;
  } while (value != 0);
  return digits;
}

template <class T>
constexpr std::string TypeDescription();

namespace internal {
// "[N1][N2]..." for an array type in declaration order, "" otherwise.
template <class T>
constexpr std::string Extents() {
  if constexpr (std::is_array_v<T>) {
    std::string text(1, '[');
    text += Decimal(std::extent_v<T>);
    text += ']';
    text += Extents<std::remove_extent_t<T>>();
    return text;
  } else {
    return "";
  }
}
template <class T>
concept HasLayoutDescription = requires {
  { T::LayoutDescription() } -> std::convertible_to<std::string>;
};
template <class T>
concept DescribedEnum = std::is_enum_v<T> && requires(T value) {
  { DescribeEnum(value) } -> std::convertible_to<std::string_view>;
};
}  // namespace internal

// Text naming a field type in layout descriptions: "u8".."u64", "i8".."i64", "f32", "f64", "char",
// arrays "<element>[N1][N2]" (C order), enums "<DescribeEnum(E{})>:<underlying>", nested message
// structs their full LayoutDescription(). Any other type is a compile error.
template <class T>
constexpr std::string TypeDescription() {
  if constexpr (std::is_array_v<T>) {
    return TypeDescription<std::remove_all_extents_t<T>>() + internal::Extents<T>();
  } else if constexpr (std::is_same_v<T, char>) {
    return "char";
  } else if constexpr (std::is_same_v<T, float>) {
    static_assert(sizeof(float) == 4);
    return "f32";
  } else if constexpr (std::is_same_v<T, double>) {
    static_assert(sizeof(double) == 8);
    return "f64";
  } else if constexpr (std::is_same_v<T, bool>) {
    static_assert(!std::is_same_v<T, bool>, "use uint8_t (0/1) instead of bool in messages");
    return "";
  } else if constexpr (std::is_integral_v<T>) {
    return std::string(std::is_signed_v<T> ? "i" : "u") + Decimal(sizeof(T) * 8);
  } else if constexpr (internal::DescribedEnum<T>) {
    return std::string(DescribeEnum(T{})) + ":" + TypeDescription<std::underlying_type_t<T>>();
  } else if constexpr (internal::HasLayoutDescription<T>) {
    return T::LayoutDescription();
  } else {
    static_assert(internal::HasLayoutDescription<T>,
                  "message fields must be fixed-width arithmetic, char, arrays, described enums or "
                  "message structs");
    return "";
  }
}

// Builds a layout description. Fields must be added in declaration order and tile the struct with
// no gap (an implicit padding byte is an error: declare explicit `reserved` fields instead). Any
// violation throws MessageError, which inside a constant expression is a compile error.
class LayoutBuilder {
 public:
  constexpr explicit LayoutBuilder(std::string_view type_name)
      : type_name_(type_name), text_(type_name) {
    text_ += '{';
  }

  // Adds field `name` of type T at byte `offset`.
  template <class T>
  constexpr void Field(std::string_view name, size_t offset) {
    if (offset != end_) {
      throw MessageError("layout of " + std::string(type_name_) + ": field '" + std::string(name) +
                         "' at offset " + Decimal(offset) + ", expected " + Decimal(end_) +
                         " (implicit padding or a field missing from the description)");
    }
    text_ += name;
    text_ += ':';
    text_ += TypeDescription<T>();
    text_ += '@';
    text_ += Decimal(offset);
    text_ += ';';
    end_ = offset + sizeof(T);
  }

  // Completes the description of struct M ("}size=<sizeof>,align=<alignof>").
  template <class M>
  constexpr std::string Finish() {
    if (end_ != sizeof(M)) {
      throw MessageError("layout of " + std::string(type_name_) + ": fields end at byte " +
                         Decimal(end_) + " but sizeof is " + Decimal(sizeof(M)) +
                         " (implicit tail padding or a field missing from the description)");
    }
    text_ += "}size=";
    text_ += Decimal(sizeof(M));
    text_ += ",align=";
    text_ += Decimal(alignof(M));
    return text_;
  }

 private:
  std::string_view type_name_;
  std::string text_;
  size_t end_ = 0;
};

}  // namespace layout

// Adds member `member` of struct `Type` to LayoutBuilder `builder` (name, type and offset).
#define PROBELESS_MSGS_FIELD(builder, Type, member) \
  (builder).template Field<decltype(Type::member)>(#member, offsetof(Type, member))

// What every message type satisfies (checked by static_asserts next to each type).
template <class M>
concept Message = std::is_trivially_copyable_v<M> && std::is_standard_layout_v<M> &&
    std::is_default_constructible_v<M> && requires {
  { M::kTypeName } -> std::convertible_to<std::string_view>;
  { M::kLayoutHash } -> std::convertible_to<uint64_t>;
  { M::kHasPayload } -> std::convertible_to<bool>;
} &&(!M::kHasPayload || sizeof(M) % kPayloadAlignment == 0);

// The bus type of a topic carrying M: {M::kTypeName, M::kLayoutHash}.
template <Message M>
probeless::bus::TopicType TopicTypeOf() {
  return probeless::bus::TopicType{std::string(M::kTypeName), M::kLayoutHash};
}

// Bytes of a whole bus message of type M with `payload_bytes` after the struct.
template <Message M>
constexpr size_t MessageBytes(size_t payload_bytes = 0) {
  return sizeof(M) + payload_bytes;
}

// A received message: the struct at the start of a bus sample and the payload bytes after it.
template <Message M>
struct ReadView {
  const M* message = nullptr;
  std::span<const std::byte> payload;
  const M& operator*() const { return *message; }
  const M* operator->() const { return message; }
};

// A message being written into a loaned slot: the struct (value-initialised, i.e. zeroed) and the
// payload bytes after it (left untouched).
template <Message M>
struct WriteView {
  M* message = nullptr;
  std::span<std::byte> payload;
  M& operator*() const { return *message; }
  M* operator->() const { return message; }
};

namespace internal {
[[noreturn]] inline void ThrowTooSmall(std::string_view type_name, size_t got, size_t need) {
  throw MessageError(std::string(type_name) + ": message of " + std::to_string(got) +
                     " bytes is smaller than its fixed part (" + std::to_string(need) + " bytes)");
}
[[noreturn]] inline void ThrowMisaligned(std::string_view type_name) {
  throw MessageError(std::string(type_name) + ": message bytes are not " +
                     std::to_string(kPayloadAlignment) + "-byte aligned");
}
}  // namespace internal

// Views `bytes` (a whole bus sample, e.g. Sample::data()) as an M followed by its payload. Throws
// MessageError if the bytes are fewer than sizeof(M) or not 64-byte aligned. The view is valid as
// long as the bytes are (i.e. while the Sample is held). Does not validate the contents: call the
// type's Validate()/accessors for that.
template <Message M>
ReadView<M> ReadMessage(std::span<const std::byte> bytes) {
  if (bytes.size() < sizeof(M)) internal::ThrowTooSmall(M::kTypeName, bytes.size(), sizeof(M));
  if (reinterpret_cast<uintptr_t>(bytes.data()) % kPayloadAlignment != 0) {
    internal::ThrowMisaligned(M::kTypeName);
  }
  return {std::launder(reinterpret_cast<const M*>(bytes.data())), bytes.subspan(sizeof(M))};
}

// Starts an M (value-initialised: all fields zero) at the front of `bytes` (a whole loaned slot,
// e.g. Loan::data()) and returns it with the payload bytes after it. Same checks as ReadMessage.
template <Message M>
WriteView<M> WriteMessage(std::span<std::byte> bytes) {
  if (bytes.size() < sizeof(M)) internal::ThrowTooSmall(M::kTypeName, bytes.size(), sizeof(M));
  if (reinterpret_cast<uintptr_t>(bytes.data()) % kPayloadAlignment != 0) {
    internal::ThrowMisaligned(M::kTypeName);
  }
  M* message = ::new (static_cast<void*>(bytes.data())) M{};
  return {message, bytes.subspan(sizeof(M))};
}

// Text of a NUL-terminated fixed-capacity string field (never reads past the array).
template <size_t N>
std::string_view FixedString(const char (&field)[N]) {
  size_t length = 0;
  while (length < N && field[length] != '\0') ++length;
  return {field, length};
}

// `text` (a string field of a received message: any bytes) fit for a one-line message: printable
// ASCII as is, every other byte, and the backslash, as \xNN.
inline std::string PrintableText(std::string_view text) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte >= 0x20 && byte < 0x7f && c != '\\') {
      out += c;
    } else {
      out += "\\x";
      out += kHex[byte >> 4];
      out += kHex[byte & 15];
    }
  }
  return out;
}

// Stores `value` NUL-terminated (and NUL-padded) in `field`. Throws MessageError naming
// `field_name` if value has N or more characters or contains a NUL.
template <size_t N>
void SetFixedString(char (&field)[N], std::string_view value, std::string_view field_name) {
  if (value.size() >= N) {
    throw MessageError(std::string(field_name) + " '" + std::string(value) + "' has " +
                       std::to_string(value.size()) + " characters, at most " +
                       std::to_string(N - 1) + " fit");
  }
  if (value.find('\0') != std::string_view::npos) {
    throw MessageError(std::string(field_name) + " contains a NUL character");
  }
  for (size_t i = 0; i < N; ++i) field[i] = i < value.size() ? value[i] : '\0';
}

}  // namespace probeless::msgs
