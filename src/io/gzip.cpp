#include "io/gzip.h"

#include <zlib.h>

#include <algorithm>
#include <limits>

#include "core/error.h"
#include "io/files.h"

namespace sd {

bool IsGzip(std::string_view bytes) {
  return bytes.size() >= 2 && static_cast<unsigned char>(bytes[0]) == 0x1f && static_cast<unsigned char>(bytes[1]) == 0x8b;
}

std::string Gunzip(std::string_view compressed, const std::filesystem::path& file, size_t max_bytes) {
  if (!IsGzip(compressed)) throw InputError(file, "not gzip data (no 1f 8b magic)");
  std::string out;
  z_stream z{};
  // 16 + MAX_WBITS: gzip wrapper only (no raw deflate or zlib streams), with its CRC-32 and length checked.
  if (compressed.size() > std::numeric_limits<uInt>::max()) throw InputError(file, "gzip data over 4 GiB is not supported");
  if (inflateInit2(&z, 16 + MAX_WBITS) != Z_OK) throw InputError(file, "cannot start gzip decompression");
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(compressed.data()));
  z.avail_in = static_cast<uInt>(compressed.size());
  size_t done = 0;
  int rc = Z_OK;
  for (;;) {
    if (done == out.size()) {
      // One byte beyond the limit is room enough to tell "exactly max_bytes" from "more".
      out.resize(std::min(max_bytes + 1, std::max<size_t>(out.size() * 2, 1 << 20)));
    }
    z.next_out = reinterpret_cast<Bytef*>(out.data() + done);
    z.avail_out = static_cast<uInt>(std::min<size_t>(out.size() - done, 1u << 30));
    const uInt before = z.avail_out;
    rc = inflate(&z, Z_NO_FLUSH);
    done += before - z.avail_out;
    if (done > max_bytes) {
      inflateEnd(&z);
      throw InputError(file, Msg() << "decompresses to more than " << max_bytes << " bytes (the limit for this file)");
    }
    if (rc == Z_STREAM_END) {
      if (z.avail_in == 0) break;
      // Another member follows (gzip files may be concatenated); anything else after the end is corrupt.
      if (z.avail_in < 2 || z.next_in[0] != 0x1f || z.next_in[1] != 0x8b) {
        inflateEnd(&z);
        throw InputError(file, "trailing bytes after the gzip data");
      }
      inflateReset(&z);
      continue;
    }
    if (rc == Z_BUF_ERROR && z.avail_in == 0) {
      inflateEnd(&z);
      throw InputError(file, "truncated gzip data");
    }
    if (rc != Z_OK && rc != Z_BUF_ERROR) {
      const std::string why = z.msg ? z.msg : "corrupt data";
      inflateEnd(&z);
      throw InputError(file, "corrupt gzip data: " + why);
    }
  }
  inflateEnd(&z);
  out.resize(done);
  return out;
}

std::string ReadMaybeGzipFile(const std::filesystem::path& file, size_t max_bytes) {
  std::string bytes = ReadFileToString(file);
  if (!IsGzip(bytes)) {
    if (bytes.size() > max_bytes) throw InputError(file, Msg() << "is larger than " << max_bytes << " bytes (the limit for this file)");
    return bytes;
  }
  return Gunzip(bytes, file, max_bytes);
}

}  // namespace sd
