// A Cyclone DDS sertype whose samples are already-encoded CDR buffers (encapsulation header
// included). Private: Cyclone headers only in src/.
#pragma once

#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>
#include <dds/ddsi/ddsi_sertype.h>

#include <cstddef>
#include <span>
#include <string>
#include <vector>

namespace probeless::dds_bridge::internal {

// The serdata: the bytes as they travel on the wire.
struct OpaqueSerdata : ddsi_serdata {
  std::vector<std::byte> bytes;
};

// A new sertype named `dds_type_name` (reference owned by the caller until a topic takes it).
ddsi_sertype* CreateOpaqueSertype(const std::string& dds_type_name);
// A serdata (refcount 1) holding a copy of `cdr`, for dds_writecdr (which takes the reference).
ddsi_serdata* MakeOpaqueSerdata(const ddsi_sertype* type, std::span<const std::byte> cdr);
// Same, taking the buffer without a copy.
ddsi_serdata* MakeOpaqueSerdata(const ddsi_sertype* type, std::vector<std::byte>&& cdr);
// The bytes of a serdata taken with dds_takecdr from a reader of an opaque sertype.
std::span<const std::byte> OpaqueBytes(const ddsi_serdata* serdata);

}  // namespace probeless::dds_bridge::internal
