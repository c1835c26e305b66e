#pragma once
// gzip (RFC 1952) data read into memory, bounded: the caller says how large the decompressed data may grow, so
// a small hostile file ("zip bomb") cannot exhaust memory. Concatenated members are read as one stream, as
// gzip(1) does.
#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>

namespace sd {

// True when `bytes` starts with the gzip magic (1f 8b).
bool IsGzip(std::string_view bytes);

// The decompressed bytes of `compressed` (one or more gzip members). InputError naming `file` when the data is
// not gzip, is truncated or corrupt (CRC or length mismatch), or would exceed `max_bytes` decompressed.
std::string Gunzip(std::string_view compressed, const std::filesystem::path& file, size_t max_bytes);

// The file's bytes, decompressed when they are gzip (by magic, not by name); InputError naming the file when it
// is missing, unreadable, corrupt, or larger than `max_bytes` once decompressed.
std::string ReadMaybeGzipFile(const std::filesystem::path& file, size_t max_bytes);

}  // namespace sd
