// Device memory behind raster/buffer.h: CUDA when built with it, else a refusal that names the build.
#include "raster/buffer.h"

#include <cstring>

#include "core/error.h"
#include "raster/raster.h"
#if SYNTHDRIVE_WITH_CUDA
#include "raster/cuda/raster_cuda.h"
#endif

namespace sd::raster {

namespace detail {

void* DeviceAllocate(size_t bytes) {
  if (!CudaAvailable())
    throw InputError({}, "a device buffer was asked for, but CUDA cannot run here (built without it, or no GPU "
                         "is visible to this process)");
#if SYNTHDRIVE_WITH_CUDA
  return cuda::Allocate(bytes);
#else
  (void)bytes;
  return nullptr;
#endif
}

void DeviceFree(void* ptr) {
#if SYNTHDRIVE_WITH_CUDA
  cuda::Free(ptr);
#else
  (void)ptr;
#endif
}

void Copy(void* dst, Memory dst_where, const void* src, Memory src_where, size_t bytes) {
  if (bytes == 0) return;
  if (dst_where == Memory::kHost && src_where == Memory::kHost) {
    std::memcpy(dst, src, bytes);
    return;
  }
#if SYNTHDRIVE_WITH_CUDA
  cuda::Copy(dst, dst_where == Memory::kDevice, src, src_where == Memory::kDevice, bytes);
#else
  SD_CHECK(false, << "device memory in a build without CUDA");
#endif
}

void DeviceFill32(void* ptr, uint32_t pattern, size_t count) {
#if SYNTHDRIVE_WITH_CUDA
  cuda::Fill32(ptr, pattern, count);
#else
  SD_CHECK(ptr == nullptr || count == 0, << "device memory in a build without CUDA");
  (void)pattern;
#endif
}

void DeviceFill64(void* ptr, uint64_t pattern, size_t count) {
#if SYNTHDRIVE_WITH_CUDA
  cuda::Fill64(ptr, pattern, count);
#else
  SD_CHECK(ptr == nullptr || count == 0, << "device memory in a build without CUDA");
  (void)pattern;
#endif
}

}  // namespace detail

void CheckDeviceContracts() {
#if SYNTHDRIVE_WITH_CUDA
  if (!CudaAvailable()) return;
  const int violation = cuda::TakeContractViolation();
  SD_CHECK(violation != cuda::kVertexIndex, << "a raster op on the device was given a triangle naming a vertex past "
                                               "its vertices");
  SD_CHECK(violation != cuda::kRasterTriangle, << "a raster op on the device was given a raster buffer whose "
                                                  "triangle ids lie past its triangles (a buffer of another mesh?)");
  SD_CHECK(violation != cuda::kVertexFaces, << "a raster op on the device was given a vertex-face incidence that "
                                               "does not fit its triangles (one of another mesh?)");
#endif
}

}  // namespace sd::raster
