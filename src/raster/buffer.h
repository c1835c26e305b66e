#pragma once
// Buffers that say where their data lives, so that the raster ops chain on the GPU without a round trip per
// call (raster.h): an op given device buffers runs its kernels on them and leaves its outputs there; an op
// given host buffers runs on the CPU (or, when the process's device is CUDA, uploads, runs and downloads, as
// it always did). A caller keeps a chain on one side and crosses the bus only where it wants to, once.
//
//  - Buffer<T>: owns `size()` elements on the host (a std::vector) or on the device (CUDA memory, grown and
//    never shrunk, so a buffer reused across iterations allocates only when it grows). On the host it reads
//    like the vector it wraps; a device buffer's elements are reached only through the ops, `ToHost` /
//    `CopyTo` and `CopyFrom`. Copies are deep, on the buffer's own side.
//  - Span<T>: a located view of someone else's elements (a Buffer, a std::vector, a std::span), what the ops'
//    inputs structs hold. Host containers convert implicitly, so host callers did not change.
//
// Device work is queued on the calling host thread's stream (per-thread default streams): ops and copies
// from one thread run in the order they were called, and only a download to the host waits for them. A
// buffer's device memory is the thread's that made it: use it from that thread.
//
// Contracts on device buffers: the index checks an op makes on the host (raster.h) are made by its kernels as
// they read each index. One out of range is not used and raises a flag of the calling thread; the kernels that
// index do nothing once it is up, and the next download to the host aborts naming the contract
// (CheckDeviceContracts).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/error.h"

namespace sd::raster {

enum class Memory { kHost, kDevice };

namespace detail {
// Device memory and copies (buffer.cpp; CUDA in raster_cuda.cu). Without CUDA, device allocation is an
// InputError naming the build.
void* DeviceAllocate(size_t bytes);
void DeviceFree(void* ptr);
// Copies `bytes` between any two sides, in the calling thread's stream order; a copy to the host waits.
void Copy(void* dst, Memory dst_where, const void* src, Memory src_where, size_t bytes);
// Sets `count` 4-byte words (or `count` 8-byte words) at a device address to `pattern`.
void DeviceFill32(void* ptr, uint32_t pattern, size_t count);
void DeviceFill64(void* ptr, uint64_t pattern, size_t count);
}  // namespace detail

// Aborts (SD_CHECK) when a device op of this thread found an index out of its contract since the last
// check; downloads call it after they wait.
void CheckDeviceContracts();

template <typename T>
class Buffer {
  static_assert(std::is_trivially_copyable_v<T>, "device buffers hold plain values");

 public:
  Buffer() = default;  // empty, on the host
  explicit Buffer(Memory where, size_t size = 0) : where_(where) { resize(size); }
  // A host buffer holding `values` (implicit: host code hands vectors to the ops).
  Buffer(std::vector<T> values) : host_(std::move(values)) {}  // NOLINT(google-explicit-constructor)

  Buffer(const Buffer& other) : where_(other.where_) {
    if (where_ == Memory::kHost) {
      host_ = other.host_;
    } else {
      resize(other.size_);
      detail::Copy(device_, Memory::kDevice, other.device_, Memory::kDevice, size_ * sizeof(T));
    }
  }
  Buffer& operator=(const Buffer& other) {
    if (this != &other) {
      Buffer copy(other);
      swap(copy);
    }
    return *this;
  }
  Buffer(Buffer&& other) noexcept { swap(other); }
  Buffer& operator=(Buffer&& other) noexcept {
    swap(other);
    return *this;
  }
  ~Buffer() {
    if (device_ != nullptr) detail::DeviceFree(device_);
  }
  void swap(Buffer& other) noexcept {
    std::swap(where_, other.where_);
    host_.swap(other.host_);
    std::swap(device_, other.device_);
    std::swap(size_, other.size_);
    std::swap(capacity_, other.capacity_);
  }

  Memory where() const { return where_; }
  size_t size() const { return where_ == Memory::kHost ? host_.size() : size_; }
  bool empty() const { return size() == 0; }
  T* data() { return where_ == Memory::kHost ? host_.data() : device_; }
  const T* data() const { return where_ == Memory::kHost ? host_.data() : device_; }

  // On the host as std::vector::resize. On the device the first min(old, new) elements are kept and the
  // rest are unspecified; memory grows by a quarter beyond what is asked and is never given back.
  void resize(size_t size) {
    if (where_ == Memory::kHost) return host_.resize(size);
    if (size > capacity_) {
      const size_t grown = size + size / 4;
      T* fresh = static_cast<T*>(detail::DeviceAllocate(grown * sizeof(T)));
      if (size_ > 0) detail::Copy(fresh, Memory::kDevice, device_, Memory::kDevice, size_ * sizeof(T));
      if (device_ != nullptr) detail::DeviceFree(device_);
      device_ = fresh;
      capacity_ = grown;
    }
    size_ = size;
  }
  // size() elements, each `value`. Device buffers take values of 4 or 8 bytes that repeat one word.
  void assign(size_t size, const T& value) {
    if (where_ == Memory::kHost) return host_.assign(size, value);
    resize(size);
    if constexpr (sizeof(T) == 4) {
      uint32_t word;
      std::memcpy(&word, &value, 4);
      detail::DeviceFill32(device_, word, size);
    } else if constexpr (sizeof(T) == 8) {
      uint64_t word;
      std::memcpy(&word, &value, 8);
      detail::DeviceFill64(device_, word, size);
    } else {
      static_assert(sizeof(T) == 4 || sizeof(T) == 8, "device fill of 4- or 8-byte values");
    }
  }
  // This buffer's side keeps; its contents become `from`'s, wherever those live.
  void CopyFrom(std::span<const T> from, Memory from_where = Memory::kHost) {
    resize(from.size());
    if (from.empty()) return;
    if (where_ == Memory::kHost && from_where == Memory::kHost)
      std::copy(from.begin(), from.end(), host_.begin());
    else
      detail::Copy(data(), where_, from.data(), from_where, from.size() * sizeof(T));
  }
  // The elements on the host: a copy, after the device work queued before it (and CheckDeviceContracts).
  std::vector<T> ToHost() const {
    std::vector<T> out(size());
    CopyTo(out);
    return out;
  }
  // The same into the caller's memory of size() elements (a gradient downloaded where it is summed).
  void CopyTo(std::span<T> to) const {
    SD_CHECK(to.size() == size(), << "a buffer of " << size() << " elements copied into " << to.size());
    if (where_ == Memory::kHost) {
      std::copy(host_.begin(), host_.end(), to.begin());
      return;
    }
    if (size_ > 0) detail::Copy(to.data(), Memory::kHost, device_, Memory::kDevice, size_ * sizeof(T));
    CheckDeviceContracts();
  }

  // Host buffers only (SD_CHECK): the wrapped vector and its element access.
  std::vector<T>& host() {
    CheckHost();
    return host_;
  }
  const std::vector<T>& host() const {
    CheckHost();
    return host_;
  }
  T& operator[](size_t i) { return host_[i]; }  // unchecked, as a vector's
  const T& operator[](size_t i) const { return host_[i]; }
  auto begin() { return host().begin(); }
  auto end() { return host().end(); }
  auto begin() const { return host().begin(); }
  auto end() const { return host().end(); }
  operator std::span<T>() { return host(); }  // NOLINT(google-explicit-constructor)
  operator std::span<const T>() const { return host(); }  // NOLINT(google-explicit-constructor)
  friend bool operator==(const Buffer& a, const Buffer& b) { return a.host() == b.host(); }

 private:
  void CheckHost() const { SD_CHECK(where_ == Memory::kHost, << "a device buffer read as host memory"); }

  Memory where_ = Memory::kHost;
  std::vector<T> host_;
  T* device_ = nullptr;
  size_t size_ = 0, capacity_ = 0;  // device only
};

template <typename T>
class Span {
 public:
  using Element = std::remove_const_t<T>;
  Span() = default;
  Span(T* data, size_t size, Memory where = Memory::kHost) : data_(data), size_(size), where_(where) {}
  // Host containers (implicit, so host callers hand their vectors and spans to the ops unchanged).
  Span(std::span<T> host) : data_(host.data()), size_(host.size()) {}  // NOLINT(google-explicit-constructor)
  template <typename U = T, typename = std::enable_if_t<std::is_const_v<U>>>
  Span(std::span<Element> host) : data_(host.data()), size_(host.size()) {}  // NOLINT(google-explicit-constructor)
  Span(std::vector<Element>& host) : data_(host.data()), size_(host.size()) {}  // NOLINT(google-explicit-constructor)
  template <typename U = T, typename = std::enable_if_t<std::is_const_v<U>>>
  Span(const std::vector<Element>& host) : data_(host.data()), size_(host.size()) {}  // NOLINT
  // A buffer, on its side.
  Span(Buffer<Element>& b) : data_(b.data()), size_(b.size()), where_(b.where()) {}  // NOLINT
  template <typename U = T, typename = std::enable_if_t<std::is_const_v<U>>>
  Span(const Buffer<Element>& b) : data_(b.data()), size_(b.size()), where_(b.where()) {}  // NOLINT
  template <typename U = T, typename = std::enable_if_t<std::is_const_v<U>>>
  Span(const Span<Element>& s) : data_(s.data()), size_(s.size()), where_(s.where()) {}  // NOLINT

  T* data() const { return data_; }
  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  Memory where() const { return where_; }
  // The elements as a host span (SD_CHECK that they are on the host).
  std::span<T> host() const {
    SD_CHECK(where_ == Memory::kHost, << "a device span read as host memory");
    return {data_, size_};
  }

 private:
  T* data_ = nullptr;
  size_t size_ = 0;
  Memory where_ = Memory::kHost;
};

}  // namespace sd::raster
