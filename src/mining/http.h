#pragma once
// Fetching images over HTTP(S) for URL-list sources (libcurl, behind this header). Every failure mode of a
// real crawl is bounded and reported per URL, never fatal to the run: connect and total timeouts, a server that
// stops sending (stall timeout), a size limit enforced while downloading, content-type checks, and retries with
// backoff for transient failures (connection errors, timeouts, HTTP 429 and 5xx).
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/image.h"

namespace sd::mining {

struct FetchOptions {
  double connect_timeout_s = 10;
  double total_timeout_s = 60;
  double stall_timeout_s = 15;       // abort when no byte arrives for this long
  size_t max_bytes = 32u << 20;      // larger bodies are aborted as soon as they exceed it
  // Accepted Content-Type prefixes (case-insensitive); empty accepts anything.
  std::vector<std::string> accept_content_types = {"image/"};
  int retries = 2;                   // extra attempts after a transient failure
  double retry_backoff_s = 0.5;      // doubles after each attempt
  std::string user_agent = "synthdrive-mine/0.1";
};

struct FetchResult {
  bool ok = false;
  long http_status = 0;      // 0 when no response arrived
  std::string content_type;  // as the server sent it
  std::string body;          // only when ok
  std::string error;         // one line when !ok: "HTTP 404", "timed out after 2 s", "no data for 1 s",
                             // "content type text/html is not accepted", "larger than 1048576 bytes", ...
  int attempts = 0;
};

// One client per thread (a libcurl easy handle is reused across fetches; keep-alive).
class HttpClient {
 public:
  explicit HttpClient(FetchOptions options = {});
  ~HttpClient();
  HttpClient(const HttpClient&) = delete;
  HttpClient& operator=(const HttpClient&) = delete;

  FetchResult Fetch(const std::string& url) const;
  const FetchOptions& options() const { return options_; }

 private:
  FetchOptions options_;
  void* curl_ = nullptr;  // CURL*, kept out of the header
};

// Fetches and decodes many images with `concurrency` parallel clients. Never throws for a per-URL failure: each
// result carries either the decoded image (sRGB, the file's channel count) or a one-line error (the fetch
// error, or "not a decodable image"). Results are in the order of `urls`. `on_done` (may be null) is called
// once per URL as it finishes, from worker threads, for progress.
struct FetchedImage {
  std::string url;
  ImageU8 image;      // empty on failure
  std::string error;  // empty on success
  long http_status = 0;
  std::string content_type;
  int attempts = 0;
};
std::vector<FetchedImage> FetchImages(const std::vector<std::string>& urls, const FetchOptions& options,
                                      int concurrency = 8, const std::function<void()>& on_done = {});

// A URL list: one http:// or https:// URL per line; blank lines and lines starting with '#' are skipped.
// InputError naming the file and line for anything else.
std::vector<std::string> ReadUrlList(const std::filesystem::path& file);

}  // namespace sd::mining
