#include "mining/http.h"

#include <curl/curl.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <thread>
#include <utility>

#include "core/error.h"
#include "io/files.h"
#include "io/image_io.h"

namespace sd::mining {
namespace {

void EnsureCurlGlobalInit() {
  // curl_global_init is not thread-safe and must run before any easy handle exists; clients may be created
  // from several threads at once (FetchImages), hence call_once. Never cleaned up: handles may outlive main's
  // static destructors, and the process exit reclaims everything.
  static std::once_flag once;
  std::call_once(once, [] {
    const CURLcode rc = curl_global_init(CURL_GLOBAL_DEFAULT);
    SD_CHECK(rc == CURLE_OK, << "curl_global_init failed: " << curl_easy_strerror(rc));
  });
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string Trim(std::string_view s) {
  size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return std::string(s.substr(b, e - b));
}

// Seconds for messages: "2 s", "0.5 s".
std::string Seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g s", s);
  return buf;
}

// libcurl messages are one line already; this guards the one-line contract of FetchResult::error.
std::string OneLine(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  return Trim(s);
}

enum class Abort { kNone, kHttpStatus, kContentType, kTooLarge, kStalled };

using Clock = std::chrono::steady_clock;

// Per-attempt state shared with the libcurl callbacks. Headers of every response in a redirect chain pass
// through the header callback; `status` and `content_type` always describe the latest one.
struct Transfer {
  const FetchOptions* options = nullptr;
  CURL* curl = nullptr;
  Clock::time_point last_data = Clock::now();
  long status = 0;
  std::string content_type;
  long long content_length = -1;
  std::string body;
  Abort abort = Abort::kNone;
};

bool ContentTypeAccepted(const FetchOptions& options, const std::string& content_type) {
  if (options.accept_content_types.empty()) return true;
  const std::string lower = Lower(content_type);
  for (const std::string& prefix : options.accept_content_types)
    if (lower.rfind(Lower(prefix), 0) == 0) return true;
  return false;
}

// Decides at the end of each response's headers, before any body byte is read: a refused status, type or
// announced size stops the transfer there instead of downloading a body we would throw away.
bool HeadersComplete(Transfer& t) {
  if (t.status < 200 || (t.status >= 300 && t.status < 400)) return true;  // 1xx interim, or a redirect to follow
  if (t.status >= 400) {
    t.abort = Abort::kHttpStatus;
    return false;
  }
  if (!ContentTypeAccepted(*t.options, t.content_type)) {
    t.abort = Abort::kContentType;
    return false;
  }
  if (t.content_length >= 0 && static_cast<unsigned long long>(t.content_length) > t.options->max_bytes) {
    t.abort = Abort::kTooLarge;
    return false;
  }
  return true;
}

size_t OnHeader(char* data, size_t size, size_t count, void* user) {
  Transfer& t = *static_cast<Transfer*>(user);
  t.last_data = Clock::now();
  const size_t n = size * count;
  const std::string line = Trim(std::string_view(data, n));
  if (line.empty()) return HeadersComplete(t) ? n : 0;  // 0 makes libcurl fail with CURLE_WRITE_ERROR
  if (line.rfind("HTTP/", 0) == 0) {  // status line: a new response starts (after a redirect or 1xx)
    t.status = 0;
    t.content_type.clear();
    t.content_length = -1;
    const size_t sp = line.find(' ');
    if (sp != std::string::npos) t.status = std::strtol(line.c_str() + sp + 1, nullptr, 10);
    return n;
  }
  const size_t colon = line.find(':');
  if (colon == std::string::npos) return n;
  const std::string name = Lower(Trim(std::string_view(line).substr(0, colon)));
  const std::string value = Trim(std::string_view(line).substr(colon + 1));
  if (name == "content-type") {
    t.content_type = value;
  } else if (name == "content-length") {
    char* end = nullptr;
    const long long v = std::strtoll(value.c_str(), &end, 10);
    if (end != value.c_str() && v >= 0) t.content_length = v;
  }
  return n;
}

size_t OnBody(char* data, size_t size, size_t count, void* user) {
  Transfer& t = *static_cast<Transfer*>(user);
  t.last_data = Clock::now();
  const size_t n = size * count;
  // Checked before appending so a body without Content-Length (chunked) never grows past the limit.
  if (t.body.size() + n > t.options->max_bytes) {
    t.abort = Abort::kTooLarge;
    return 0;
  }
  t.body.append(data, n);
  return n;
}

// The stall clock. libcurl's own low-speed check averages the rate over a window of several seconds, so after a
// burst of bytes a dead server is noticed only many seconds later; this measures the time since the last byte.
// The clock runs from connection establishment (connecting has its own timeout).
int OnProgress(void* user, curl_off_t, curl_off_t, curl_off_t, curl_off_t) {
  Transfer& t = *static_cast<Transfer*>(user);
  const Clock::time_point now = Clock::now();
  curl_off_t connect_us = 0;
  if (curl_easy_getinfo(t.curl, CURLINFO_CONNECT_TIME_T, &connect_us) != CURLE_OK || connect_us == 0) {
    t.last_data = now;
    return 0;
  }
  if (std::chrono::duration<double>(now - t.last_data).count() > t.options->stall_timeout_s) {
    t.abort = Abort::kStalled;
    return 1;  // CURLE_ABORTED_BY_CALLBACK
  }
  return 0;
}

long Millis(double seconds) { return static_cast<long>(std::llround(std::max(0.0, seconds) * 1000)); }

// libcurl's low-speed window is whole seconds; it is only the backstop of OnProgress.
long StallSeconds(const FetchOptions& o) { return std::max(1L, static_cast<long>(std::ceil(o.stall_timeout_s))); }

bool TransientCurlError(CURLcode rc) {
  switch (rc) {
    case CURLE_COULDNT_RESOLVE_HOST:
    case CURLE_COULDNT_RESOLVE_PROXY:
    case CURLE_COULDNT_CONNECT:
    case CURLE_OPERATION_TIMEDOUT:
    case CURLE_SEND_ERROR:
    case CURLE_RECV_ERROR:
    case CURLE_GOT_NOTHING:
    case CURLE_PARTIAL_FILE:
    case CURLE_SSL_CONNECT_ERROR:
    case CURLE_HTTP2:
    case CURLE_HTTP2_STREAM:
      return true;
    default:
      return false;
  }
}

bool TransientStatus(long status) { return status == 429 || (status >= 500 && status <= 599); }

}  // namespace

HttpClient::HttpClient(FetchOptions options) : options_(std::move(options)) {
  EnsureCurlGlobalInit();
  curl_ = curl_easy_init();
  SD_CHECK(curl_ != nullptr, << "curl_easy_init failed");
}

HttpClient::~HttpClient() { curl_easy_cleanup(static_cast<CURL*>(curl_)); }

FetchResult HttpClient::Fetch(const std::string& url) const {
  CURL* curl = static_cast<CURL*>(curl_);
  const FetchOptions& o = options_;
  FetchResult result;
  double backoff_s = o.retry_backoff_s;
  for (int attempt = 0;; ++attempt) {
    result = FetchResult{};
    result.attempts = attempt + 1;
    Transfer t;
    t.options = &o;
    t.curl = curl;
    char errbuf[CURL_ERROR_SIZE] = {0};

    // Reset keeps the connection cache, so consecutive fetches from one host reuse the keep-alive connection.
    curl_easy_reset(curl);
    curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
    curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, errbuf);
    curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);  // timeouts without SIGALRM: required with threads
#if LIBCURL_VERSION_NUM >= 0x075500  // 7.85: the string form; the bitmask one is deprecated
    curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(curl, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
#else
    curl_easy_setopt(curl, CURLOPT_PROTOCOLS, static_cast<long>(CURLPROTO_HTTP | CURLPROTO_HTTPS));
    curl_easy_setopt(curl, CURLOPT_REDIR_PROTOCOLS, static_cast<long>(CURLPROTO_HTTP | CURLPROTO_HTTPS));
#endif
    curl_easy_setopt(curl, CURLOPT_FOLLOWLOCATION, 1L);
    curl_easy_setopt(curl, CURLOPT_MAXREDIRS, 5L);
    curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, Millis(o.connect_timeout_s));
    curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, Millis(o.total_timeout_s));
    curl_easy_setopt(curl, CURLOPT_LOW_SPEED_LIMIT, 1L);
    curl_easy_setopt(curl, CURLOPT_LOW_SPEED_TIME, StallSeconds(o));
    curl_easy_setopt(curl, CURLOPT_USERAGENT, o.user_agent.c_str());
    curl_easy_setopt(curl, CURLOPT_HEADERFUNCTION, OnHeader);
    curl_easy_setopt(curl, CURLOPT_HEADERDATA, &t);
    curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, OnBody);
    curl_easy_setopt(curl, CURLOPT_WRITEDATA, &t);
    curl_easy_setopt(curl, CURLOPT_NOPROGRESS, 0L);
    curl_easy_setopt(curl, CURLOPT_XFERINFOFUNCTION, OnProgress);
    curl_easy_setopt(curl, CURLOPT_XFERINFODATA, &t);

    const CURLcode rc = curl_easy_perform(curl);
    curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, nullptr);  // errbuf dies with this iteration; the handle lives on
    long status = 0;
    curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
    if (status == 0) status = t.status;  // a transfer we aborted in the header callback may not record it
    result.http_status = status;
    result.content_type = t.content_type;
    const std::string detail = OneLine(errbuf[0] ? std::string(errbuf) : std::string(curl_easy_strerror(rc)));

    bool transient = false;
    if (t.abort == Abort::kHttpStatus || (rc == CURLE_OK && (status < 200 || status >= 300))) {
      result.error = "HTTP " + std::to_string(status);
      transient = TransientStatus(status);
    } else if (t.abort == Abort::kContentType) {
      result.error = "content type " + (t.content_type.empty() ? std::string("(none)") : t.content_type) +
                     " is not accepted";
    } else if (t.abort == Abort::kTooLarge) {
      result.error = "larger than " + std::to_string(o.max_bytes) + " bytes";
    } else if (t.abort == Abort::kStalled) {
      result.error = "no data for " + Seconds(o.stall_timeout_s);
      transient = true;
    } else if (rc == CURLE_OK) {
      result.ok = true;
      result.body = std::move(t.body);
      return result;
    } else if (rc == CURLE_OPERATION_TIMEDOUT) {
      // One libcurl code covers three limits; its message says which ("Operation too slow", "Connection timed
      // out"/"Resolving timed out", "Operation timed out").
      if (detail.rfind("Operation too slow", 0) == 0)
        result.error = "no data for " + Seconds(o.stall_timeout_s);
      else if (detail.find("onnection timed out") != std::string::npos ||
               detail.find("esolving timed out") != std::string::npos)
        result.error = "connect timed out after " + Seconds(o.connect_timeout_s);
      else
        result.error = "timed out after " + Seconds(o.total_timeout_s);
      transient = true;
    } else if (rc == CURLE_COULDNT_CONNECT || rc == CURLE_COULDNT_RESOLVE_HOST ||
               rc == CURLE_COULDNT_RESOLVE_PROXY) {
      result.error = "cannot connect: " + detail;
      transient = true;
    } else {
      result.error = detail;
      transient = TransientCurlError(rc);
    }
    if (!transient || attempt >= o.retries) return result;
    std::this_thread::sleep_for(std::chrono::duration<double>(std::max(0.0, backoff_s)));
    backoff_s *= 2;
  }
}

std::vector<FetchedImage> FetchImages(const std::vector<std::string>& urls, const FetchOptions& options,
                                      int concurrency, const std::function<void()>& on_done) {
  std::vector<FetchedImage> results(urls.size());
  if (urls.empty()) return results;
  const size_t workers = std::min(urls.size(), static_cast<size_t>(std::max(1, concurrency)));
  std::atomic<size_t> next{0};
  std::mutex callback_mutex;
  std::exception_ptr callback_error;

  auto work = [&] {
    HttpClient client(options);
    for (size_t i = next++; i < urls.size(); i = next++) {
      FetchedImage& out = results[i];
      out.url = urls[i];
      try {
        FetchResult r = client.Fetch(urls[i]);
        out.http_status = r.http_status;
        out.content_type = r.content_type;
        out.attempts = r.attempts;
        if (!r.ok) {
          out.error = r.error;
        } else {
          try {
            out.image = DecodeImage(r.body, urls[i]);
          } catch (const InputError&) {
            out.error = "not a decodable image";
          }
        }
      } catch (const std::exception& e) {  // e.g. bad_alloc on a huge decode: this URL fails, the run goes on
        out.image = ImageU8();
        out.error = OneLine(e.what());
      }
      if (on_done) {
        // A throwing progress callback must not terminate a worker thread; the first error is rethrown below.
        try {
          on_done();
        } catch (...) {
          std::lock_guard<std::mutex> lock(callback_mutex);
          if (!callback_error) callback_error = std::current_exception();
        }
      }
    }
  };

  std::vector<std::thread> threads;
  threads.reserve(workers - 1);
  for (size_t w = 1; w < workers; ++w) threads.emplace_back(work);
  work();  // the calling thread is one of the workers
  for (std::thread& th : threads) th.join();
  if (callback_error) std::rethrow_exception(callback_error);
  return results;
}

std::vector<std::string> ReadUrlList(const std::filesystem::path& file) {
  const std::string text = ReadFileToString(file);
  std::vector<std::string> urls;
  size_t line_no = 0;
  for (size_t pos = 0; pos <= text.size();) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    ++line_no;
    const std::string line = Trim(std::string_view(text).substr(pos, end - pos));
    pos = end + 1;
    if (line.empty() || line[0] == '#') continue;
    const std::string lower = Lower(line);
    const size_t scheme = lower.rfind("http://", 0) == 0 ? 7 : lower.rfind("https://", 0) == 0 ? 8 : 0;
    const bool has_space = std::any_of(line.begin(), line.end(), [](unsigned char c) { return std::isspace(c); });
    const bool has_host = scheme && line.size() > scheme && line[scheme] != '/';
    if (!scheme || has_space || !has_host) {
      const std::string shown = line.size() > 80 ? line.substr(0, 77) + "..." : line;
      throw InputError(file.string() + ":" + std::to_string(line_no),
                       Msg() << "not an http:// or https:// URL: '" << shown << "'");
    }
    urls.push_back(line);
  }
  return urls;
}

}  // namespace sd::mining
