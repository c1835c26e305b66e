#pragma once
// A loopback HTTP/1.1 server for tests of code that downloads: requests never leave 127.0.0.1, and each test
// decides what every path answers — including the failure modes of a real crawl (errors, wrong types, huge or
// endless bodies, servers that hang). One thread per connection and "Connection: close" keep it simple; the
// destructor unblocks and joins every thread, so a handler may block until the client gives up.
#include <atomic>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace sd::testing {

class LoopbackHttpServer {
 public:
  // Answers one request: `fd` is the connection, `target` the request target ("/a.png?x=1"), `hit` how many
  // times this target has been requested so far (1 for the first).
  using Handler = std::function<void(LoopbackHttpServer& server, int fd, const std::string& target, int hit)>;

  explicit LoopbackHttpServer(Handler handler);
  ~LoopbackHttpServer();
  LoopbackHttpServer(const LoopbackHttpServer&) = delete;
  LoopbackHttpServer& operator=(const LoopbackHttpServer&) = delete;

  std::string Url(const std::string& target) const;
  int Hits(const std::string& target);
  bool stopping() const { return stopping_; }

  // For handlers: a complete response with Content-Length; sending everything; blocking until the peer
  // closes (how a handler "hangs").
  static std::string Response(int status, const std::string& reason, const std::string& content_type,
                              const std::string& body, const std::string& extra_headers = "");
  static bool SendAll(int fd, std::string_view data);
  static void WaitForClose(int fd);

 private:
  void AcceptLoop();
  void Handle(int fd);

  Handler handler_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stopping_{false};
  std::thread accept_thread_;
  std::mutex mutex_;
  std::set<int> open_fds_;
  std::vector<std::thread> connection_threads_;
  std::map<std::string, int> hits_;
};

// A loopback port nothing listens on (bound, read back and closed again).
int ClosedLoopbackPort();

}  // namespace sd::testing
