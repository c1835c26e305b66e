#include "core/device.h"

#include <atomic>
#include <cstdlib>

#include "core/error.h"

namespace sd {
namespace {

std::atomic<int> current_device{-1};  // -1: not chosen yet, read $SYNTHDRIVE_DEVICE at the first use

}  // namespace

const char* ToString(Device device) { return device == Device::kCuda ? "cuda" : "cpu"; }

Device ParseDevice(const std::string& name) {
  if (name == "cpu") return Device::kCpu;
  if (name == "cuda") return Device::kCuda;
  throw InputError({}, Msg() << "unknown device '" << name << "' (expected cpu or cuda)");
}

void SetDevice(Device device) { current_device.store(static_cast<int>(device)); }

Device CurrentDevice() {
  int device = current_device.load();
  if (device < 0) {
    const char* env = std::getenv("SYNTHDRIVE_DEVICE");
    Device chosen = Device::kCpu;
    if (env != nullptr && *env != '\0') {
      try {
        chosen = ParseDevice(env);
      } catch (const InputError& e) {
        throw InputError("$SYNTHDRIVE_DEVICE", e.what());
      }
    }
    device = static_cast<int>(chosen);
    current_device.store(device);
  }
  return static_cast<Device>(device);
}

}  // namespace sd
