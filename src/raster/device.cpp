// The raster ops' side of the device switch (core/device.h): whether CUDA can run them, checked once per
// choice of device.
#include <string>

#include "core/error.h"
#include "raster/internal.h"
#include "raster/raster.h"

namespace sd::raster {

bool CudaAvailable() {
#if SYNTHDRIVE_WITH_CUDA
  return cuda::Available();
#else
  return false;
#endif
}

std::string CudaDeviceDescription() {
#if SYNTHDRIVE_WITH_CUDA
  return cuda::DeviceDescription();
#else
  return {};
#endif
}

bool UseCuda() {
  if (CurrentDevice() != Device::kCuda) return false;
  if (!CudaAvailable()) {
#if SYNTHDRIVE_WITH_CUDA
    throw InputError({}, "device cuda asked for, but no CUDA GPU is visible to this process");
#else
    throw InputError({}, "device cuda asked for, but the raster ops were built without CUDA "
                         "(configure with -DSYNTHDRIVE_WITH_CUDA=ON)");
#endif
  }
  return true;
}

}  // namespace sd::raster
