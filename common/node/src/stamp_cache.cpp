#include "probeless/node/stamp_cache.h"

#include <algorithm>

#include "probeless/msgs/layout.h"
#include "probeless/node/node.h"

namespace probeless::node {

namespace stamp_cache_detail {

void ThrowZeroCapacity() { throw NodeError("StampCache: capacity must be >= 1"); }

bool WithinTolerance(int64_t stamp_ns, int64_t at_ns, int64_t tolerance_ns) {
  if (tolerance_ns < 0 || stamp_ns > at_ns) return false;
  if (tolerance_ns == kAnyAge) return true;  // also ages beyond INT64_MAX
  // at_ns - stamp_ns in unsigned arithmetic: exact for every pair with stamp_ns <= at_ns.
  const uint64_t age = static_cast<uint64_t>(at_ns) - static_cast<uint64_t>(stamp_ns);
  return age <= static_cast<uint64_t>(tolerance_ns);
}

}  // namespace stamp_cache_detail

HeldMessage::HeldMessage(std::span<const std::byte> bytes) {
  storage_.resize(bytes.size() + msgs::kPayloadAlignment);
  const auto address = reinterpret_cast<uintptr_t>(storage_.data());
  offset_ = (msgs::kPayloadAlignment - address % msgs::kPayloadAlignment) % msgs::kPayloadAlignment;
  size_ = bytes.size();
  std::copy(bytes.begin(), bytes.end(), storage_.begin() + static_cast<std::ptrdiff_t>(offset_));
}

}  // namespace probeless::node
