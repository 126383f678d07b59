#include "opaque_cdr.h"

#include <dds/ddsi/q_radmin.h>

#include <cstdio>
#include <cstring>

#include "probeless/error/error.h"

namespace probeless::dds_bridge::internal {
namespace {

// What dds_write/dds_take would see as a sample: a byte vector (unused by the bridge, which
// writes and takes serdata directly; implemented for completeness).
using Sample = std::vector<std::byte>;

OpaqueSerdata* NewSerdata(const ddsi_sertype* type, ddsi_serdata_kind kind) {
  auto* d = new OpaqueSerdata();
  ddsi_serdata_init(d, type, kind);
  d->hash = type->serdata_basehash;  // keyless: every sample is the one instance
  return d;
}

const OpaqueSerdata* Cast(const ddsi_serdata* d) { return static_cast<const OpaqueSerdata*>(d); }

bool EqKey(const ddsi_serdata*, const ddsi_serdata*) { return true; }
uint32_t GetSize(const ddsi_serdata* d) { return static_cast<uint32_t>(Cast(d)->bytes.size()); }

ddsi_serdata* FromSer(const ddsi_sertype* type, ddsi_serdata_kind kind, const nn_rdata* fragchain,
                      size_t size) {
  OpaqueSerdata* d = NewSerdata(type, kind);
  d->bytes.resize(size);
  uint32_t off = 0;
  while (fragchain != nullptr) {
    if (fragchain->maxp1 > off) {
      const unsigned char* payload =
          NN_RMSG_PAYLOADOFF(fragchain->rmsg, NN_RDATA_PAYLOAD_OFF(fragchain));
      const unsigned char* src = payload + off - fragchain->min;
      const uint32_t n = fragchain->maxp1 - off;
      PROBELESS_DEMAND(off + n <= size, "DDS fragment chain past the sample size");
      std::memcpy(d->bytes.data() + off, src, n);
      off = fragchain->maxp1;
    }
    fragchain = fragchain->nextfrag;
  }
  return d;
}

ddsi_serdata* FromSerIov(const ddsi_sertype* type, ddsi_serdata_kind kind, ddsrt_msg_iovlen_t niov,
                         const ddsrt_iovec_t* iov, size_t size) {
  OpaqueSerdata* d = NewSerdata(type, kind);
  d->bytes.reserve(size);
  for (ddsrt_msg_iovlen_t i = 0; i < niov; ++i) {
    const auto* p = static_cast<const std::byte*>(iov[i].iov_base);
    d->bytes.insert(d->bytes.end(), p, p + iov[i].iov_len);
  }
  d->bytes.resize(size);
  return d;
}

ddsi_serdata* FromKeyhash(const ddsi_sertype* type, const ddsi_keyhash*) {
  OpaqueSerdata* d = NewSerdata(type, SDK_KEY);
  d->bytes = {std::byte{0}, std::byte{1}, std::byte{0}, std::byte{0}};
  return d;
}

ddsi_serdata* FromSample(const ddsi_sertype* type, ddsi_serdata_kind kind, const void* sample) {
  OpaqueSerdata* d = NewSerdata(type, kind);
  if (kind == SDK_DATA) {
    d->bytes = *static_cast<const Sample*>(sample);
  } else {
    d->bytes = {std::byte{0}, std::byte{1}, std::byte{0}, std::byte{0}};
  }
  return d;
}

void ToSer(const ddsi_serdata* d, size_t off, size_t sz, void* buf) {
  std::memcpy(buf, Cast(d)->bytes.data() + off, sz);
}

ddsi_serdata* ToSerRef(const ddsi_serdata* d, size_t off, size_t sz, ddsrt_iovec_t* ref) {
  ref->iov_base = const_cast<std::byte*>(Cast(d)->bytes.data() + off);
  ref->iov_len = static_cast<ddsrt_iov_len_t>(sz);
  return ddsi_serdata_ref(d);
}

void ToSerUnref(ddsi_serdata* d, const ddsrt_iovec_t*) { ddsi_serdata_unref(d); }

bool ToSample(const ddsi_serdata* d, void* sample, void**, void*) {
  *static_cast<Sample*>(sample) = Cast(d)->bytes;
  return true;
}

ddsi_serdata* ToUntyped(const ddsi_serdata* d) {
  OpaqueSerdata* u = NewSerdata(d->type, SDK_KEY);
  u->bytes = {std::byte{0}, std::byte{1}, std::byte{0}, std::byte{0}};
  u->type = nullptr;
  return u;
}

bool UntypedToSample(const ddsi_sertype*, const ddsi_serdata*, void*, void**, void*) {
  return true;  // keyless: no key fields to fill
}

void FreeSerdata(ddsi_serdata* d) { delete static_cast<OpaqueSerdata*>(d); }

size_t Print(const ddsi_sertype*, const ddsi_serdata* d, char* buf, size_t size) {
  return static_cast<size_t>(std::snprintf(buf, size, "opaque CDR, %zu bytes", Cast(d)->bytes.size()));
}

void GetKeyhash(const ddsi_serdata*, ddsi_keyhash* buf, bool) { std::memset(buf, 0, sizeof(*buf)); }

const ddsi_serdata_ops kSerdataOps = {
    &EqKey,  &GetSize, &FromSer,    &FromSerIov,      &FromKeyhash, &FromSample,
    &ToSer,  &ToSerRef, &ToSerUnref, &ToSample,       &ToUntyped,   &UntypedToSample,
    &FreeSerdata, &Print, &GetKeyhash,
#ifdef DDS_HAS_SHM
    nullptr, nullptr,
#endif
};

void FreeSertype(ddsi_sertype* tp) {
  ddsi_sertype_fini(tp);
  delete tp;
}
void ZeroSamples(const ddsi_sertype*, void* samples, size_t count) {
  auto* s = static_cast<Sample*>(samples);
  for (size_t i = 0; i < count; ++i) s[i].clear();
}
void ReallocSamples(void** ptrs, const ddsi_sertype*, void* old, size_t oldcount, size_t count) {
  auto* fresh = new Sample[count];
  auto* previous = static_cast<Sample*>(old);
  for (size_t i = 0; i < oldcount && i < count; ++i) fresh[i] = std::move(previous[i]);
  delete[] previous;
  for (size_t i = 0; i < count; ++i) ptrs[i] = &fresh[i];
}
void FreeSamples(const ddsi_sertype*, void** ptrs, size_t count, dds_free_op_t op) {
  if (count == 0) return;
  auto* s = static_cast<Sample*>(ptrs[0]);
  if (op & DDS_FREE_ALL_BIT) {
    delete[] s;
  } else {
    for (size_t i = 0; i < count; ++i) static_cast<Sample*>(ptrs[i])->clear();
  }
}
bool Equal(const ddsi_sertype*, const ddsi_sertype*) { return true; }
uint32_t Hash(const ddsi_sertype*) { return 0; }
size_t SerializedSize(const ddsi_sertype*, const void* sample) {
  return static_cast<const Sample*>(sample)->size();
}
bool SerializeInto(const ddsi_sertype*, const void* sample, void* dst, size_t dst_size) {
  const auto* s = static_cast<const Sample*>(sample);
  if (dst_size < s->size()) return false;
  std::memcpy(dst, s->data(), s->size());
  return true;
}

const ddsi_sertype_ops kSertypeOps = {
    ddsi_sertype_v0, nullptr, &FreeSertype, &ZeroSamples, &ReallocSamples, &FreeSamples, &Equal,
    &Hash, nullptr /*type_id*/, nullptr /*type_map*/, nullptr /*type_info*/,
    nullptr /*derive_sertype*/, &SerializedSize, &SerializeInto,
};

}  // namespace

ddsi_sertype* CreateOpaqueSertype(const std::string& dds_type_name) {
  auto* tp = new ddsi_sertype();
  ddsi_sertype_init(tp, dds_type_name.c_str(), &kSertypeOps, &kSerdataOps, true);
  tp->allowed_data_representation = DDS_DATA_REPRESENTATION_FLAG_XCDR1;
  return tp;
}

ddsi_serdata* MakeOpaqueSerdata(const ddsi_sertype* type, std::span<const std::byte> cdr) {
  OpaqueSerdata* d = NewSerdata(type, SDK_DATA);
  d->bytes.assign(cdr.begin(), cdr.end());
  return d;
}

ddsi_serdata* MakeOpaqueSerdata(const ddsi_sertype* type, std::vector<std::byte>&& cdr) {
  OpaqueSerdata* d = NewSerdata(type, SDK_DATA);
  d->bytes = std::move(cdr);
  return d;
}

std::span<const std::byte> OpaqueBytes(const ddsi_serdata* serdata) {
  return Cast(serdata)->bytes;
}

}  // namespace probeless::dds_bridge::internal
