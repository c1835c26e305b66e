#pragma once
// The compute device of the process: one switch for every backend that can use a GPU (the raster ops in
// raster/, the model runtime in models/). Chosen by SetDevice (the CLI's --device) or, before the first use,
// by $SYNTHDRIVE_DEVICE (cpu | cuda); the CPU otherwise. Each backend checks on its first use that it can
// run on the chosen device and refuses with an InputError otherwise: never a silent fall back to the CPU,
// since a user who asked for the GPU wants to know that the GPU is not used.
#include <string>

namespace sd {

enum class Device { kCpu, kCuda };

const char* ToString(Device device);
Device ParseDevice(const std::string& name);  // "cpu" | "cuda"; InputError otherwise
void SetDevice(Device device);
// SetDevice's choice, else $SYNTHDRIVE_DEVICE (InputError when it names no device), else kCpu.
Device CurrentDevice();

}  // namespace sd
