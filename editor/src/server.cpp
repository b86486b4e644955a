#include "phos/editor/server.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <list>
#include <memory>
#include <mutex>
#include <set>
#include <thread>

#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <httplib.h>
#include <nlohmann/json.hpp>

#include "phos/util/error.h"
#include "phos/util/format.h"
#include "phos/util/json.h"

namespace phos::editor {
namespace {

using Clock = std::chrono::steady_clock;

// Names (objects, presets) longer than this are refused before any lookup.
constexpr std::size_t kMaxNameBytes = 256;

// JSON for the wire. Bytes that are not UTF-8 become U+FFFD instead of an
// exception: a parse error's message quotes the request's own bytes, and
// encoding them threw inside the error handler, so a POST with a non-UTF-8
// string was answered 500 (found by fuzz-editor; fuzz/regressions/editor/).
std::string Dump(const nlohmann::json& value, int indent = -1) {
  return value.dump(indent, ' ', false, nlohmann::json::error_handler_t::replace);
}

void Error(httplib::Response& response, int status, const std::string& message) {
  response.status = status;
  response.set_content(Dump(nlohmann::json{{"error", message}}), "application/json");
}

// The request body as a JSON object. nlohmann refuses a number beyond
// double's range (1e400) with its own exception, not a syntax error: it is a
// bad value like any other, named with its field (the parser's callback
// follows the keys down to the one being read).
nlohmann::json ParseBody(const std::string& text) {
  std::vector<std::string> keys;
  const nlohmann::json::parser_callback_t follow = [&](int, nlohmann::json::parse_event_t event,
                                                       nlohmann::json& parsed) {
    if (event == nlohmann::json::parse_event_t::object_start) keys.emplace_back();
    if (event == nlohmann::json::parse_event_t::key) keys.back() = parsed.get<std::string>();
    if (event == nlohmann::json::parse_event_t::object_end) keys.pop_back();
    return true;
  };
  nlohmann::json body;
  try {
    body = nlohmann::json::parse(text, follow);
  } catch (const nlohmann::json::out_of_range& e) {
    std::string field;
    for (const std::string& key : keys)
      if (!key.empty()) field += (field.empty() ? "" : ".") + key;
    std::string what = e.what();  // "[json.exception.out_of_range.406] number overflow parsing '1e400'"
    if (auto close = what.find("] "); close != std::string::npos) what = what.substr(close + 2);
    ThrowUserError("request", field, "a number beyond the range of a double (" + what + ")");
  } catch (const nlohmann::json::exception& e) {
    std::string what = e.what();
    if (auto close = what.find("] "); close != std::string::npos) what = what.substr(close + 2);
    ThrowUserError("request", "", "malformed JSON: " + what);
  }
  if (!body.is_object()) ThrowUserError("request", "", "expected a JSON object, got " + DescribeJson(body));
  return body;
}

// A name field of a request: a string, not too long to look up.
std::string Name(const JsonField& field) {
  const std::string name = field.String();
  if (name.size() > kMaxNameBytes)
    field.Fail("has " + std::to_string(name.size()) + " characters, more than " + std::to_string(kMaxNameBytes));
  return name;
}

// A query parameter as a number: the whole text, finite.
double QueryNumber(const httplib::Request& request, const std::string& key) {
  const std::string text = request.get_param_value(key);
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v))
    ThrowUserError("request", key, "expected a number, got '" + text.substr(0, 40) + "'");
  return v;
}

// Every query parameter is one the route knows, given once.
void RejectUnknownParameters(const httplib::Request& request, std::initializer_list<std::string> known) {
  for (const auto& [key, value] : request.params) {
    if (std::find(known.begin(), known.end(), key) == known.end()) {
      const std::string list = JoinComma(known);
      ThrowUserError("request", key.substr(0, 40),
                     "unknown parameter (expected " + (list.empty() ? "none" : list) + ")");
    }
    if (request.get_param_value_count(key) > 1) ThrowUserError("request", key, "given more than once");
  }
}

// One connection's socket as httplib's Stream, with deadlines: the whole
// request must arrive by `read_deadline` however slowly its bytes trickle, and
// the response must leave by `write_deadline` (a client that sends or reads
// one byte a second cannot hold a worker; httplib's own read timeout restarts
// with every byte).
class DeadlineStream : public httplib::Stream {
 public:
  // The request line and headers may take kMaxHeaderBytes, the body
  // max_body_bytes: httplib bounds each header line but not their number.
  // The request must arrive within request_timeout of its first byte; a
  // connection that sends nothing waits up to `idle_deadline` (a browser
  // preconnects and may send its request many seconds later).
  DeadlineStream(int fd, Clock::time_point idle_deadline, Clock::duration request_timeout,
                 Clock::duration write_timeout, std::size_t max_body_bytes)
      : fd_(fd),
        read_deadline_(idle_deadline),
        request_timeout_(request_timeout),
        write_timeout_(write_timeout),
        max_body_bytes_(max_body_bytes) {}

  static constexpr std::size_t kMaxHeaderBytes = 64 * 1024;

  bool is_readable() const override { return begin_ < end_ || Wait(POLLIN, read_deadline_); }
  bool is_writable() const override { return Wait(POLLOUT, WriteDeadline()); }

  ssize_t read(char* ptr, size_t size) override {
    if (begin_ == end_) {
      if (left_to_read_ == 0 || !Wait(POLLIN, read_deadline_)) return -1;
      ssize_t n;
      do {  // a signal (the fuzz harness's SIGALRM, a debugger's) is not the end of the request
        n = ::recv(fd_, buffer_, std::min(sizeof buffer_, left_to_read_), 0);
      } while (n < 0 && errno == EINTR);
      if (n <= 0) return n;
      if (!started_) {
        started_ = true;
        read_deadline_ = std::min(read_deadline_, Clock::now() + request_timeout_);
      }
      left_to_read_ -= static_cast<std::size_t>(n);
      begin_ = 0;
      end_ = static_cast<std::size_t>(n);
      // The end of the headers (CRLF CRLF): from there on, the body's allowance.
      for (std::size_t i = 0; i < end_ && !in_body_; ++i) {
        const char c = buffer_[i];
        header_end_matched_ = c == "\r\n\r\n"[header_end_matched_] ? header_end_matched_ + 1 : (c == '\r' ? 1 : 0);
        if (header_end_matched_ == 4) {
          in_body_ = true;
          const std::size_t body_so_far = end_ - i - 1;
          left_to_read_ = max_body_bytes_ > body_so_far ? max_body_bytes_ - body_so_far : 0;
        }
      }
    }
    const std::size_t n = std::min(size, end_ - begin_);
    std::memcpy(ptr, buffer_ + begin_, n);
    begin_ += n;
    return static_cast<ssize_t>(n);
  }

  ssize_t write(const char* ptr, size_t size) override {
    if (!Wait(POLLOUT, WriteDeadline())) return -1;
    ssize_t n;
    do n = ::send(fd_, ptr, size, MSG_NOSIGNAL);
    while (n < 0 && errno == EINTR);
    return n;
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override { Address(::getpeername, ip, port); }
  void get_local_ip_and_port(std::string& ip, int& port) const override { Address(::getsockname, ip, port); }
  socket_t socket() const override { return fd_; }

 private:
  Clock::time_point WriteDeadline() const {
    if (!write_started_) {
      write_started_ = true;
      write_deadline_ = Clock::now() + write_timeout_;
    }
    return write_deadline_;
  }
  bool Wait(short events, Clock::time_point deadline) const {
    while (true) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left <= 0) return false;
      pollfd p{fd_, events, 0};
      const int n = ::poll(&p, 1, static_cast<int>(std::min<long long>(left, 1000)));
      if (n > 0) return true;
      if (n < 0 && errno != EINTR) return false;
    }
  }
  void Address(int (*get)(int, sockaddr*, socklen_t*), std::string& ip, int& port) const {
    sockaddr_storage address{};
    socklen_t length = sizeof address;
    char host[NI_MAXHOST] = "", service[NI_MAXSERV] = "";
    if (get(fd_, reinterpret_cast<sockaddr*>(&address), &length) == 0 &&
        ::getnameinfo(reinterpret_cast<sockaddr*>(&address), length, host, sizeof host, service, sizeof service,
                      NI_NUMERICHOST | NI_NUMERICSERV) == 0) {
      ip = host;
      port = std::atoi(service);
    }
  }

  int fd_;
  Clock::time_point read_deadline_;
  Clock::duration request_timeout_, write_timeout_;
  std::size_t max_body_bytes_;
  std::size_t left_to_read_ = kMaxHeaderBytes;
  bool started_ = false, in_body_ = false;
  int header_end_matched_ = 0;
  mutable bool write_started_ = false;
  mutable Clock::time_point write_deadline_;
  char buffer_[4096];
  std::size_t begin_ = 0, end_ = 0;
};

// httplib's routing and request parsing, fed by our own listener (below):
// process_request reads one request from a Stream, routes it and writes the
// response.
class Router : public httplib::Server {
 public:
  void HandleOne(httplib::Stream& stream) {
    bool closed = false;
    process_request(stream, /*close_connection=*/true, closed, nullptr);
  }
};

// The listening socket, bound without SO_REUSEPORT: httplib sets it, and with
// it a second editor on a port in use started anyway and the two shared the
// requests. SO_REUSEADDR only lets a restarted editor take its port back from
// connections in TIME_WAIT; Linux still refuses a second listener.
int Listen(const std::string& bind, int port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* found = nullptr;
  const std::string where = bind + ":" + std::to_string(port);
  if (const int e = ::getaddrinfo(bind.c_str(), std::to_string(port).c_str(), &hints, &found); e != 0)
    ThrowUserError("", "--bind", "cannot resolve '" + bind + "' (" + ::gai_strerror(e) + ")");
  int error = 0;
  int fd = -1;
  for (addrinfo* a = found; a && fd < 0; a = a->ai_next) {
    fd = ::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
    if (fd < 0) {
      error = errno;
      continue;
    }
    const int yes = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    if (::bind(fd, a->ai_addr, a->ai_addrlen) != 0 || ::listen(fd, 128) != 0) {
      error = errno;
      ::close(fd);
      fd = -1;
    }
  }
  ::freeaddrinfo(found);
  if (fd < 0 && error == EADDRINUSE)
    ThrowUserError("", "--port",
                   where + " is in use (another phos editor?); pick another port, or --port 0 for any free one");
  if (fd < 0) ThrowUserError("", "--bind", "cannot listen on " + where + " (" + std::strerror(error) + ")");
  return fd;
}

int BoundPort(int fd) {
  sockaddr_storage address{};
  socklen_t length = sizeof address;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length);
  if (address.ss_family == AF_INET6) return ntohs(reinterpret_cast<sockaddr_in6*>(&address)->sin6_port);
  return ntohs(reinterpret_cast<sockaddr_in*>(&address)->sin_port);
}

// A short response written straight to a socket we will not serve (too many
// connections), without waiting on the client.
void Refuse(int fd, int status, const std::string& reason, const std::string& message) {
  const std::string body = Dump(nlohmann::json{{"error", message}});
  const std::string response =
      "HTTP/1.1 " + std::to_string(status) + " " + reason +
      "\r\nContent-Type: application/json\r\nConnection: close\r\nContent-Length: " + std::to_string(body.size()) +
      "\r\n\r\n" + body;
  ::send(fd, response.data(), response.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
}

// Closes a served connection. A response sent before its request was read
// whole (a refused Origin, a body over the limit) would be lost to the reset
// that closing with unread input sends: what is left is read first, for a
// moment.
void LingerAndClose(int fd) {
  ::shutdown(fd, SHUT_WR);
  const Clock::time_point until = Clock::now() + std::chrono::milliseconds(200);
  char sink[4096];
  for (std::size_t drained = 0; drained < (1u << 20) && Clock::now() < until;) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const ssize_t n = ::recv(fd, sink, sizeof sink, 0);
    if (n <= 0) break;
    drained += static_cast<std::size_t>(n);
  }
  ::close(fd);
}

// Origin and Host: only the page itself, at the address it was served from.
// Each exactly once (Origin at most once): with two, a check of the first
// let a bad second one through to whatever reads the other.
httplib::Server::HandlerResponse CheckHeaders(const httplib::Request& request, httplib::Response& response,
                                              const ServerOptions& options, int port) {
  for (const char* header : {"Host", "Origin"})
    if (request.get_header_value_count(header) > 1) {
      Error(response, 400,
            std::string("request: ") + header + ": given " + std::to_string(request.get_header_value_count(header)) +
                " times; expected once");
      return httplib::Server::HandlerResponse::Handled;
    }
  // cpp-httplib 0.11 applies max_body_bytes to Content-Length only: a
  // chunked body of 13 MB was read whole. The page always sends a length.
  if (request.has_header("Transfer-Encoding")) {
    Error(response, 411, "request: Transfer-Encoding is not accepted; send the body with a Content-Length");
    return httplib::Server::HandlerResponse::Handled;
  }
  // A length over the limit is answered before the body is read: httplib
  // reads (and drops) the whole body first, and a Content-Length of 1e12
  // without a body got its 413 only at the read deadline.
  if (request.has_header("Content-Length")) {
    const std::string length = request.get_header_value("Content-Length");
    const bool digits = !length.empty() && length.size() <= 19 &&
                        std::all_of(length.begin(), length.end(), [](char c) { return c >= '0' && c <= '9'; });
    if (!digits || std::stoull(length) > options.max_body_bytes) {
      Error(response, 413, "request: the body is larger than " + std::to_string(options.max_body_bytes) + " bytes");
      return httplib::Server::HandlerResponse::Handled;
    }
  }
  const std::string here = ":" + std::to_string(port);
  const std::string host = request.get_header_value("Host");
  const bool loopback = options.bind == "127.0.0.1" || options.bind == "localhost";
  if (loopback && host != "127.0.0.1" + here && host != "localhost" + here) {
    Error(response, 403, "Host '" + host.substr(0, 80) + "' is not this editor's address");
    return httplib::Server::HandlerResponse::Handled;
  }
  if (request.has_header("Origin")) {
    const std::string origin = request.get_header_value("Origin");
    if (origin != "http://" + host) {
      Error(response, 403, "requests from other origins are refused ('" + origin.substr(0, 80) + "')");
      return httplib::Server::HandlerResponse::Handled;
    }
  }
  return httplib::Server::HandlerResponse::Unhandled;
}

// What httplib answers by itself (a body over the limit, a malformed
// request line, a URI too long) gets the same one-line JSON as ours.
httplib::Server::HandlerResponse AnswerHttplibError(httplib::Response& response, const ServerOptions& options) {
  if (!response.body.empty()) return httplib::Server::HandlerResponse::Unhandled;
  std::string message = "request: malformed HTTP request";
  if (response.status == 413)
    message = "request: the body is larger than " + std::to_string(options.max_body_bytes) + " bytes";
  if (response.status == 414) message = "request: the URI is too long";
  if (response.status == 404) message = "request: no such route";
  Error(response, response.status, message);
  return httplib::Server::HandlerResponse::Handled;
}

// ---- The routes: each answers one request with the session locked ----------

void ReplyState(EditSession& session, httplib::Response& response) {
  response.set_content(Dump(session.State()), "application/json");
}

void GetPage(EditSession&, const httplib::Request& request, httplib::Response& response) {
  RejectUnknownParameters(request, {});
  response.set_content(EditorPage(), "text/html; charset=utf-8");
}

void GetState(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  RejectUnknownParameters(request, {});
  ReplyState(session, response);
}

void GetFrame(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  RejectUnknownParameters(request, {"t", "exposure", "v"});  // v: the page's cache breaker
  const double t = request.has_param("t") ? QueryNumber(request, "t") : session.scene().start_s;
  double exposure = session.scene().camera.exposure;
  if (request.has_param("exposure")) {
    exposure = QueryNumber(request, "exposure");
    if (!(exposure > 0 && exposure < 1e6))
      ThrowUserError("request", "exposure",
                     "expected a number > 0 and < 1e6, got " + request.get_param_value("exposure"));
  }
  const std::vector<unsigned char> png = session.FramePng(t, exposure);
  response.set_content(std::string(png.begin(), png.end()), "image/png");
  response.set_header("Cache-Control", "no-store");  // a frame changes with every edit
}

void PostConstraint(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  const nlohmann::json body = ParseBody(request.body);
  const JsonField f(body, "request");
  f.RejectUnknownKeys({"x", "y", "t_s"});
  const int x = f["x"].Integer(-1000000, 1000000), y = f["y"].Integer(-1000000, 1000000);
  session.AddConstraint(x, y, f["t_s"].Number());
  ReplyState(session, response);
}

void PostConstraintUpdate(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  const nlohmann::json body = ParseBody(request.body);
  const JsonField f(body, "request");
  f.RejectUnknownKeys({"index", "rgb", "t_s", "weight", "kind"});
  session.UpdateConstraint(static_cast<std::size_t>(f["index"].Integer(0, 1000000)), body);
  ReplyState(session, response);
}

void PostConstraintRemove(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  const nlohmann::json body = ParseBody(request.body);
  const JsonField f(body, "request");
  f.RejectUnknownKeys({"index"});
  session.RemoveConstraint(static_cast<std::size_t>(f["index"].Integer(0, 1000000)));
  ReplyState(session, response);
}

void PostPreset(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  const nlohmann::json body = ParseBody(request.body);
  const JsonField f(body, "request");
  f.RejectUnknownKeys({"object", "preset"});
  session.SetPreset(Name(f["object"]), Name(f["preset"]));
  ReplyState(session, response);
}

void PostSettings(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  const nlohmann::json body = ParseBody(request.body);
  const JsonField f(body, "request");
  f.RejectUnknownKeys({"states", "falloff"});
  // Both read before either is applied: a bad falloff leaves the states as they were.
  // states null: each object's own count again (what a session starts with).
  const bool own_states = f.Has("states") && body["states"].is_null();
  const std::optional<int> states =
      f.Has("states") && !own_states ? std::optional<int>(f["states"].Integer(1, 3)) : std::nullopt;
  const std::optional<double> falloff =
      f.Has("falloff") ? std::optional<double>(f["falloff"].NumberInRange(0, 10)) : std::nullopt;
  if (own_states) session.SetStates(std::nullopt);
  if (states) session.SetStates(*states);
  if (falloff) session.SetPropagation(*falloff);
  ReplyState(session, response);
}

void GetMaterial(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  RejectUnknownParameters(request, {"object"});
  const std::string object = request.get_param_value("object");
  if (object.size() > kMaxNameBytes)
    ThrowUserError("request", "object", "longer than " + std::to_string(kMaxNameBytes) + " characters");
  const nlohmann::json material = session.MaterialJson(object);
  response.set_content(Dump(material, 2) + "\n", "application/json");
  // Named after the object (lower case, '-' for the rest): no quote or
  // control character reaches the header.
  response.set_header("Content-Disposition", "attachment; filename=\"" + session.ExportFileName(object) + "\"");
}

void PostExport(EditSession& session, const httplib::Request& request, httplib::Response& response) {
  const nlohmann::json body = ParseBody(request.body);
  const JsonField f(body, "request");
  f.RejectUnknownKeys({"object", "path"});
  const std::string object = Name(f["object"]);
  const std::filesystem::path written = session.ExportMaterial(object, f["path"].String());
  response.set_content(Dump(nlohmann::json{{"written", written.string()}}), "application/json");
}

using RouteHandler = void (*)(EditSession&, const httplib::Request&, httplib::Response&);
struct Route {
  bool post;  // else GET
  const char* path;
  RouteHandler handler;
};
// The routes, by method (also for 404 and 405: RegisterUnrouted).
constexpr Route kRoutes[] = {
    {false, "/", GetPage},
    {false, "/api/state", GetState},
    {false, "/api/frame", GetFrame},
    {true, "/api/constraints", PostConstraint},
    {true, "/api/constraints/update", PostConstraintUpdate},
    {true, "/api/constraints/remove", PostConstraintRemove},
    {true, "/api/preset", PostPreset},
    {true, "/api/settings", PostSettings},
    {false, "/api/material", GetMaterial},
    {true, "/api/export", PostExport},
};

// Every handler: one lock, and user errors become 400 with nothing changed
// (the session validates a request completely before it edits anything).
void RegisterRoutes(Router& server, EditSession& session, std::mutex& mutex) {
  for (const Route& route : kRoutes) {
    auto handle = [&session, &mutex, body = route.handler](const httplib::Request& request,
                                                           httplib::Response& response) {
      std::lock_guard<std::mutex> lock(mutex);
      try {
        body(session, request, response);
      } catch (const UserError& e) {
        Error(response, 400, e.what());
      } catch (const std::exception& e) {
        Error(response, 500, std::string("internal error: ") + e.what());
      }
    };
    if (route.post)
      server.Post(route.path, handle);
    else
      server.Get(route.path, handle);
  }
}

// Anything else: 405 naming the methods of a route that exists, else 404.
void RegisterUnrouted(Router& server) {
  std::set<std::string> get_routes, post_routes;
  for (const Route& route : kRoutes) (route.post ? post_routes : get_routes).insert(route.path);
  const auto unrouted = [get_routes, post_routes](const httplib::Request& request, httplib::Response& response) {
    const bool get = get_routes.count(request.path) > 0, post = post_routes.count(request.path) > 0;
    if (get || post) {
      response.set_header("Allow", get ? "GET" : "POST");
      Error(response, 405,
            "request: " + request.method + " " + request.path + ": method not allowed (use " + (get ? "GET" : "POST") +
                ")");
    } else {
      Error(response, 404, "request: " + request.path.substr(0, 80) + ": no such route");
    }
  };
  server.Get(".*", unrouted);
  server.Post(".*", unrouted);
  server.Put(".*", unrouted);
  server.Patch(".*", unrouted);
  server.Delete(".*", unrouted);
  server.Options(".*", unrouted);
}

// Our own listener: a thread per connection, at most max_connections of
// them (more are answered 503 at once), each request read under a deadline
// and the connection closed after its response. So slow clients hold only
// their own threads, for at most the deadline, and the page is answered
// beside them.
void ServeConnections(Router& server, int listener, const ServerOptions& options) {
  struct Connection {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done = std::make_shared<std::atomic<bool>>(false);
  };
  std::list<Connection> connections;
  const auto read_timeout =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options.read_timeout_s));
  const auto write_timeout =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options.write_timeout_s));
  const auto request_timeout =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options.request_timeout_s));
  const auto reap = [&] {
    for (auto it = connections.begin(); it != connections.end();) {
      if (*it->done) {
        it->thread.join();
        it = connections.erase(it);
      } else {
        ++it;
      }
    }
  };
  while (!(options.stop && options.stop->load())) {
    pollfd p{listener, POLLIN, 0};
    const int ready = ::poll(&p, 1, 100);
    reap();
    if (ready <= 0) continue;
    const int fd = ::accept4(listener, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) continue;
    if (connections.size() >= options.max_connections) {
      Refuse(fd, 503, "Service Unavailable",
             "request: the editor already has " + std::to_string(connections.size()) + " connections open; try again");
      ::close(fd);
      continue;
    }
    const int yes = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
    Connection& connection = connections.emplace_back();
    // The request line and headers in at most 64 KiB (the page sends under 1 KiB), then the body.
    const std::size_t max_body_bytes = options.max_body_bytes;
    connection.thread = std::thread(
        [&server, fd, read_timeout, request_timeout, write_timeout, max_body_bytes, done = connection.done] {
          {
            DeadlineStream stream(fd, Clock::now() + read_timeout, request_timeout, write_timeout, max_body_bytes);
            server.HandleOne(stream);
          }
          LingerAndClose(fd);
          *done = true;
        });
  }
  for (Connection& connection : connections) connection.thread.join();
}

}  // namespace

void Serve(EditSession& session, const ServerOptions& options, const std::function<void(int)>& on_listening) {
  Router server;
  std::mutex mutex;  // connections run on threads of their own; the session is not thread-safe
  const int listener = Listen(options.bind, options.port);
  const int port = BoundPort(listener);
  server.set_payload_max_length(options.max_body_bytes);
  server.set_pre_routing_handler([&](const httplib::Request& request, httplib::Response& response) {
    return CheckHeaders(request, response, options, port);
  });
  server.set_error_handler(httplib::Server::HandlerWithResponse(
      [&](const httplib::Request&, httplib::Response& response) { return AnswerHttplibError(response, options); }));
  RegisterRoutes(server, session, mutex);
  RegisterUnrouted(server);
  on_listening(port);
  ServeConnections(server, listener, options);
  ::close(listener);
}

}  // namespace phos::editor
