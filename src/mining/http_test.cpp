#include "mining/http.h"

#include <gtest/gtest.h>

#include <atomic>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "core/error.h"
#include "io/files.h"
#include "io/image_io.h"
#include "testing/http_server.h"
#include "testing/testing.h"

namespace sd::mining {
namespace {

ImageU8 Pattern(int w, int h, int c) {
  ImageU8 img(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k) img.at(x, y, k) = static_cast<uint8_t>((x * 11 + y * 5 + k * 70) & 255);
  return img;
}

using sd::testing::LoopbackHttpServer;

int ClosedPort() { return sd::testing::ClosedLoopbackPort(); }

// The loopback server with one route per failure mode of a real crawl.
class TestServer {
 public:
  static constexpr size_t kBigBytes = 10u << 20;
  static constexpr size_t kChunkedCapBytes = 8u << 20;

  TestServer()
      : png_(EncodeImage(Pattern(23, 17, 3), "png")),
        jpg_(EncodeImage(Pattern(32, 24, 3), "jpg")),
        server_([this](LoopbackHttpServer& s, int fd, const std::string& target, int hit) {
          Route(s, fd, target, hit);
        }) {}

  std::string Url(const std::string& target) const { return server_.Url(target); }
  int Hits(const std::string& target) { return server_.Hits(target); }
  const std::string& png() const { return png_; }
  const std::string& jpg() const { return jpg_; }

 private:
  void Route(LoopbackHttpServer& s, int fd, const std::string& target, int hit) {
    using L = LoopbackHttpServer;
    const std::string path = target.substr(0, target.find('?'));
    if (path == "/ok.png") {
      L::SendAll(fd, L::Response(200, "OK", "image/png", png_));
    } else if (path == "/ok.jpg") {
      L::SendAll(fd, L::Response(200, "OK", "image/jpeg", jpg_));
    } else if (path == "/ok-upper") {
      L::SendAll(fd, L::Response(200, "OK", "Image/PNG; charset=binary", png_));
    } else if (path == "/html") {
      L::SendAll(fd, L::Response(200, "OK", "text/html; charset=utf-8", "<html><body>hello</body></html>"));
    } else if (path == "/big") {
      // Announces 10 MB and sends only a little: a client that did not refuse at the headers would stall.
      L::SendAll(fd, "HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nContent-Length: " + std::to_string(kBigBytes) +
                         "\r\nConnection: close\r\n\r\n" + std::string(1000, 'x'));
      L::WaitForClose(fd);
    } else if (path == "/big-chunked") {
      // No length announced; streams until the client hangs up (or a cap far above any test's max_bytes).
      if (!L::SendAll(fd, "HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nTransfer-Encoding: chunked\r\n"
                          "Connection: close\r\n\r\n"))
        return;
      const std::string chunk = "4000\r\n" + std::string(0x4000, 'y') + "\r\n";
      for (size_t sent = 0; sent < kChunkedCapBytes && !s.stopping(); sent += 0x4000)
        if (!L::SendAll(fd, chunk)) return;
      L::SendAll(fd, "0\r\n\r\n");
    } else if (path == "/hang") {
      L::WaitForClose(fd);
    } else if (path == "/stall") {
      L::SendAll(fd, "HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nContent-Length: 100000\r\n"
                     "Connection: close\r\n\r\n" + png_.substr(0, 100));
      L::WaitForClose(fd);
    } else if (path == "/flaky") {
      if (hit <= 2) L::SendAll(fd, L::Response(503, "Service Unavailable", "text/plain", "busy"));
      else L::SendAll(fd, L::Response(200, "OK", "image/png", png_));
    } else if (path == "/too-many") {
      L::SendAll(fd, L::Response(429, "Too Many Requests", "text/plain", "slow down"));
    } else if (path == "/redirect") {
      L::SendAll(fd, L::Response(302, "Found", "text/html", "moved", "Location: /ok.png\r\n"));
    } else if (path == "/loop") {
      L::SendAll(fd, L::Response(302, "Found", "text/html", "moved", "Location: /loop\r\n"));
    } else if (path == "/not-image") {
      L::SendAll(fd, L::Response(200, "OK", "image/png", "this is not a png at all, just text"));
    } else {
      L::SendAll(fd, L::Response(404, "Not Found", "text/plain", "no such thing"));
    }
  }

  const std::string png_, jpg_;
  LoopbackHttpServer server_;  // last: its threads use the members above
};

// Small limits so every failure mode resolves in about a second.
FetchOptions Fast() {
  FetchOptions o;
  o.connect_timeout_s = 2;
  o.total_timeout_s = 5;
  o.stall_timeout_s = 0.5;
  o.max_bytes = 1u << 20;
  o.retries = 0;
  o.retry_backoff_s = 0.01;
  return o;
}

bool StartsWith(const std::string& s, const std::string& prefix) { return s.rfind(prefix, 0) == 0; }

TEST(Http, FetchesAndDecodesExactPixels) {
  TestServer server;
  HttpClient client(Fast());
  const FetchResult r = client.Fetch(server.Url("/ok.png"));
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.http_status, 200);
  EXPECT_EQ(r.content_type, "image/png");
  EXPECT_EQ(r.attempts, 1);
  EXPECT_TRUE(r.error.empty());
  EXPECT_EQ(r.body, server.png());
  const ImageU8 img = DecodeImage(r.body, "ok.png");
  EXPECT_EQ(img.width(), 23);
  EXPECT_EQ(img.height(), 17);
  EXPECT_EQ(img.vector(), Pattern(23, 17, 3).vector());

  // The same client again (the reset handle is reused), now a JPEG served byte for byte.
  const FetchResult j = client.Fetch(server.Url("/ok.jpg"));
  ASSERT_TRUE(j.ok) << j.error;
  EXPECT_EQ(j.content_type, "image/jpeg");
  EXPECT_EQ(j.body, server.jpg());

  // Content-type prefixes compare case-insensitively.
  const FetchResult u = client.Fetch(server.Url("/ok-upper"));
  ASSERT_TRUE(u.ok) << u.error;
  EXPECT_EQ(u.content_type, "Image/PNG; charset=binary");
}

TEST(Http, NotFoundIsNotRetried) {
  TestServer server;
  FetchOptions o = Fast();
  o.retries = 3;
  const FetchResult r = HttpClient(o).Fetch(server.Url("/missing"));
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.http_status, 404);
  EXPECT_EQ(r.error, "HTTP 404");
  EXPECT_EQ(r.attempts, 1);
  EXPECT_TRUE(r.body.empty());
  EXPECT_EQ(server.Hits("/missing"), 1);
}

TEST(Http, TransientStatusesAreRetried) {
  TestServer server;
  FetchOptions o = Fast();
  o.retries = 2;
  const FetchResult r = HttpClient(o).Fetch(server.Url("/flaky?a"));
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.attempts, 3);
  EXPECT_EQ(r.http_status, 200);
  EXPECT_EQ(r.body, server.png());
  EXPECT_EQ(server.Hits("/flaky?a"), 3);

  o.retries = 1;
  const FetchResult f = HttpClient(o).Fetch(server.Url("/flaky?b"));
  EXPECT_FALSE(f.ok);
  EXPECT_EQ(f.error, "HTTP 503");
  EXPECT_EQ(f.http_status, 503);
  EXPECT_EQ(f.attempts, 2);
  EXPECT_TRUE(f.body.empty());
  EXPECT_EQ(server.Hits("/flaky?b"), 2);

  const FetchResult t = HttpClient(o).Fetch(server.Url("/too-many"));
  EXPECT_EQ(t.error, "HTTP 429");
  EXPECT_EQ(t.attempts, 2);
}

TEST(Http, RefusesContentTypeAtTheHeaders) {
  TestServer server;
  FetchOptions o = Fast();
  o.retries = 2;
  const FetchResult r = HttpClient(o).Fetch(server.Url("/html"));
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.error, "content type text/html; charset=utf-8 is not accepted");
  EXPECT_EQ(r.content_type, "text/html; charset=utf-8");
  EXPECT_EQ(r.http_status, 200);
  EXPECT_EQ(r.attempts, 1);
  EXPECT_TRUE(r.body.empty());

  o.accept_content_types.clear();  // accepts anything
  const FetchResult any = HttpClient(o).Fetch(server.Url("/html"));
  ASSERT_TRUE(any.ok) << any.error;
  EXPECT_EQ(any.body, "<html><body>hello</body></html>");
}

TEST(Http, EnforcesTheSizeLimit) {
  TestServer server;
  FetchOptions o = Fast();
  o.retries = 2;
  // Content-Length 10 MB: refused at the headers (reading the 1000 bytes sent would end in a stall instead).
  const FetchResult big = HttpClient(o).Fetch(server.Url("/big"));
  EXPECT_FALSE(big.ok);
  EXPECT_EQ(big.error, "larger than 1048576 bytes");
  EXPECT_EQ(big.attempts, 1);
  EXPECT_TRUE(big.body.empty());
  // No length announced: cut while streaming, well before the server's 8 MB.
  const FetchResult chunked = HttpClient(o).Fetch(server.Url("/big-chunked"));
  EXPECT_FALSE(chunked.ok);
  EXPECT_EQ(chunked.error, "larger than 1048576 bytes");
  EXPECT_EQ(chunked.attempts, 1);
  EXPECT_TRUE(chunked.body.empty());
  // The limit is inclusive: a body of exactly max_bytes passes.
  o.max_bytes = server.png().size();
  EXPECT_TRUE(HttpClient(o).Fetch(server.Url("/ok.png")).ok);
  o.max_bytes = server.png().size() - 1;
  EXPECT_EQ(HttpClient(o).Fetch(server.Url("/ok.png")).error,
            "larger than " + std::to_string(server.png().size() - 1) + " bytes");
}

TEST(Http, SilentServersEndInStallOrTotalTimeout) {
  TestServer server;
  FetchOptions o = Fast();
  // Never answers: the stall timeout (0.5 s) ends it before the 5 s total.
  const FetchResult hang = HttpClient(o).Fetch(server.Url("/hang"));
  EXPECT_FALSE(hang.ok);
  EXPECT_EQ(hang.error, "no data for 0.5 s");
  EXPECT_EQ(hang.http_status, 0);
  EXPECT_EQ(hang.attempts, 1);
  // Headers and 100 bytes, then silence.
  const FetchResult stall = HttpClient(o).Fetch(server.Url("/stall"));
  EXPECT_FALSE(stall.ok);
  EXPECT_EQ(stall.error, "no data for 0.5 s");
  EXPECT_EQ(stall.http_status, 200);
  EXPECT_TRUE(stall.body.empty());
  // With a long stall window the total timeout fires; timeouts are transient, so it is retried once.
  o.stall_timeout_s = 30;
  o.total_timeout_s = 1;
  o.retries = 1;
  const FetchResult total = HttpClient(o).Fetch(server.Url("/hang"));
  EXPECT_FALSE(total.ok);
  EXPECT_EQ(total.error, "timed out after 1 s");
  EXPECT_EQ(total.attempts, 2);
  EXPECT_EQ(server.Hits("/hang"), 3);
}

TEST(Http, FollowsRedirects) {
  TestServer server;
  HttpClient client(Fast());
  const FetchResult r = client.Fetch(server.Url("/redirect"));
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.http_status, 200);
  EXPECT_EQ(r.content_type, "image/png");
  EXPECT_EQ(r.body, server.png());
  EXPECT_EQ(server.Hits("/ok.png"), 1);
  // A redirect loop stops after 5 follows: 6 requests, not retried.
  const FetchResult loop = client.Fetch(server.Url("/loop"));
  EXPECT_FALSE(loop.ok);
  EXPECT_EQ(loop.attempts, 1);
  EXPECT_EQ(server.Hits("/loop"), 6);
}

TEST(Http, ConnectionErrorsAreRetriedAndOtherSchemesRefused) {
  FetchOptions o = Fast();
  o.retries = 2;
  HttpClient client(o);
  const FetchResult r = client.Fetch("http://127.0.0.1:" + std::to_string(ClosedPort()) + "/x.png");
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.http_status, 0);
  EXPECT_EQ(r.attempts, 3);
  EXPECT_TRUE(StartsWith(r.error, "cannot connect: ")) << r.error;
  EXPECT_EQ(r.error.find('\n'), std::string::npos);

  const FetchResult file = client.Fetch("file:///etc/passwd");
  EXPECT_FALSE(file.ok);
  EXPECT_EQ(file.attempts, 1);
  EXPECT_TRUE(file.body.empty());
}

TEST(Http, FetchImagesReportsEveryUrlInOrder) {
  TestServer server;
  const std::string closed = "http://127.0.0.1:" + std::to_string(ClosedPort()) + "/x.png";
  struct Case {
    std::string url;
    std::string error;  // expected prefix; empty = a good image
  };
  const std::vector<Case> cases = {
      {server.Url("/ok.png"), ""},
      {server.Url("/missing"), "HTTP 404"},
      {server.Url("/ok.jpg"), ""},
      {server.Url("/html"), "content type text/html"},
      {server.Url("/big"), "larger than 1048576 bytes"},
      {server.Url("/redirect"), ""},
      {server.Url("/not-image"), "not a decodable image"},
      {server.Url("/big-chunked"), "larger than 1048576 bytes"},
      {server.Url("/flaky"), ""},
      {closed, "cannot connect: "},
      {server.Url("/hang"), "no data for 0.5 s"},
      {server.Url("/stall"), "no data for 0.5 s"},
      {server.Url("/ok.png?again"), ""},
  };
  std::vector<std::string> urls;
  for (const Case& c : cases) urls.push_back(c.url);
  FetchOptions o = Fast();
  o.retries = 2;
  std::atomic<int> done{0};
  const std::vector<FetchedImage> got = FetchImages(urls, o, 4, [&] { ++done; });
  ASSERT_EQ(got.size(), cases.size());
  EXPECT_EQ(done.load(), static_cast<int>(cases.size()));
  const ImageU8 png = Pattern(23, 17, 3);
  const ImageU8 jpg = DecodeImage(server.jpg(), "jpg");
  for (size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE(cases[i].url);
    EXPECT_EQ(got[i].url, cases[i].url);
    if (cases[i].error.empty()) {
      EXPECT_TRUE(got[i].error.empty()) << got[i].error;
      const ImageU8& want = cases[i].url == server.Url("/ok.jpg") ? jpg : png;
      EXPECT_EQ(got[i].image.width(), want.width());
      EXPECT_EQ(got[i].image.height(), want.height());
      EXPECT_EQ(got[i].image.vector(), want.vector());
      EXPECT_EQ(got[i].http_status, 200);
    } else {
      EXPECT_TRUE(StartsWith(got[i].error, cases[i].error)) << got[i].error;
      EXPECT_TRUE(got[i].image.empty());
    }
  }
  EXPECT_EQ(got[8].attempts, 3);  // flaky
  EXPECT_EQ(got[9].attempts, 3);  // closed port
  EXPECT_EQ(got[1].attempts, 1);  // 404
  EXPECT_TRUE(FetchImages({}, o).empty());
}

TEST(Http, ReadsUrlLists) {
  testing::TempDir tmp;
  WriteFileAtomic(tmp / "urls.txt",
                  "# cars from the web\n"
                  "https://example.com/a.jpg\n"
                  "\n"
                  "   http://example.com/b.png?size=large  \r\n"
                  "  # indented comment\n"
                  "HTTPS://EXAMPLE.COM/C.PNG");
  EXPECT_EQ(ReadUrlList(tmp / "urls.txt"),
            (std::vector<std::string>{"https://example.com/a.jpg", "http://example.com/b.png?size=large",
                                      "HTTPS://EXAMPLE.COM/C.PNG"}));

  WriteFileAtomic(tmp / "empty.txt", "");
  EXPECT_TRUE(ReadUrlList(tmp / "empty.txt").empty());

  const std::vector<std::pair<std::string, int>> bad = {
      {"https://ok.example/a.png\n\n# fine\nftp://example.com/a.png\n", 4},
      {"example.com/a.png\n", 1},
      {"http://\n", 1},
      {"https://ok.example/a.png\nhttps://ex ample.com/a.png\n", 2},
  };
  for (const auto& [text, line] : bad) {
    WriteFileAtomic(tmp / "bad.txt", text);
    try {
      ReadUrlList(tmp / "bad.txt");
      FAIL() << text;
    } catch (const InputError& e) {
      const std::string want = (tmp / "bad.txt").string() + ":" + std::to_string(line) + ": ";
      EXPECT_TRUE(StartsWith(e.what(), want)) << e.what();
    }
  }
  try {
    ReadUrlList(tmp / "missing.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.txt"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace sd::mining
