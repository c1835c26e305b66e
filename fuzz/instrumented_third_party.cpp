// Fuzz builds only. Debian ships stb_image, tinyobjloader and tinygltf as shared libraries built without coverage
// or sanitizers: libFuzzer would see none of their branches and ASan none of their reads. Their implementations
// compiled here, instrumented like the rest, come ahead of the shared libraries' definitions at link time
// (io/mesh_io.cpp and io/image_io.cpp include the same headers for the declarations).
#define TINYGLTF_IMPLEMENTATION
#include <tiny_gltf.h>

#define TINYOBJLOADER_IMPLEMENTATION
#include <tiny_obj_loader.h>

// After tinygltf, which includes stb_image.h's declarations: a second inclusion adds only the implementation.
#define STB_IMAGE_IMPLEMENTATION
#include <stb/stb_image.h>
