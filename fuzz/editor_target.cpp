// The editor's request handling (fuzz/targets.h, EditorRequest): each input
// is one request to the editor's own HTTP server (editor/server.h, Serve),
// over a socket, as the page sends it. The server and its EditSession are
// made once per process: fixtures/scenes/cornell-phosphor.json, the presets
// of fixtures/materials, one constraint placed on a lit phosphorescent wall,
// exports written under a scratch folder.
//
// The first byte picks the route; the rest is the JSON body (or, for GET
// /api/material, the object's name, percent-encoded into the query):
//   0 POST /api/constraints          {x, y, t_s}
//   1 POST /api/constraints/update   {index, rgb?, t_s?, weight?, kind?}
//   2 POST /api/constraints/remove   {index}
//   3 POST /api/preset               {object, preset}
//   4 POST /api/settings             {states?, falloff?}
//   5 POST /api/export               {object, path}
//   6 GET  /api/material?object=...
// A 400 whose error is one line is a refusal; a 200 is accepted, and what it
// changed is put back through the same API (the constraint removed or
// restored, the preset, states and falloff reset, the export deleted), so
// every input meets the same session; the harness checks that it does. Any
// other status (500 is the server's "internal error"), a response that is
// not JSON, an error of several lines, a crash or a hang is a finding.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <condition_variable>
#include <stdexcept>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "phos/editor/server.h"
#include "phos/editor/session.h"
#include "phos/util/error.h"
#include "targets.h"

namespace phos::fuzz {
namespace {

struct Editor {
  std::filesystem::path root;  // exports go here
  editor::EditSession* session = nullptr;
  std::atomic<bool> stop{false};
  std::thread thread;
  int port = 0;
  // The constraint every input starts from, and the session's state then.
  nlohmann::json constraint;  // {x, y, t_s}
  nlohmann::json start_state;
};

struct Response {
  int status = 0;
  std::string body;
};

Response Send(int port, const std::string& request) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) throw std::runtime_error("socket failed");
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  // A connect interrupted by a signal goes on in the background: wait for it.
  bool connected = ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
  if (!connected && errno == EINTR) {
    pollfd p{fd, POLLOUT, 0};
    while (::poll(&p, 1, 5000) < 0 && errno == EINTR) {}
    int error = 0;
    socklen_t length = sizeof error;
    connected = (p.revents & POLLOUT) && ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &error, &length) == 0 && error == 0;
  }
  if (!connected) {
    ::close(fd);
    throw std::runtime_error("cannot connect to the editor");
  }
  for (std::size_t sent = 0; sent < request.size();) {
    const ssize_t n = ::send(fd, request.data() + sent, request.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;  // libFuzzer's SIGALRM (its -timeout clock) interrupts calls
    if (n <= 0) break;                      // the server may answer (and close) before the whole body is read
    sent += static_cast<std::size_t>(n);
  }
  std::string text;
  char buffer[65536];
  for (;;) {
    const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    text.append(buffer, static_cast<std::size_t>(n));
  }
  ::close(fd);
  Response response;
  if (text.rfind("HTTP/1.1 ", 0) != 0 || text.size() < 12)
    throw std::logic_error("the editor answered no HTTP response: '" + text.substr(0, 80) + "'");
  response.status = std::atoi(text.c_str() + 9);
  const std::size_t body = text.find("\r\n\r\n");
  if (body != std::string::npos) response.body = text.substr(body + 4);
  return response;
}

std::string Post(int port, const std::string& route, std::string_view body) {
  return "POST " + route + " HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(port) +
         "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) + "\r\n\r\n" +
         std::string(body);
}

std::string Get(int port, const std::string& target) {
  return "GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(port) + "\r\n\r\n";
}

// What an input may change, and must leave as it found it.
nlohmann::json Snapshot(const editor::EditSession& session) {
  const nlohmann::json state = session.State();
  nlohmann::json s = {
      {"states", state["states"]}, {"falloff", state["falloff"]}, {"constraints", nlohmann::json::array()}};
  for (const auto& c : state["constraints"])
    s["constraints"].push_back(
        {{"object", c["object"]}, {"t_s", c["t_s"]}, {"rgb", c["rgb"]}, {"weight", c["weight"]}, {"kind", c["kind"]}});
  for (const auto& o : state["objects"]) s["materials"].push_back(o["material"]);
  return s;
}

// A request the harness makes itself (setting up, putting back): must succeed.
nlohmann::json Must(int port, const std::string& request) {
  const Response r = Send(port, request);
  if (r.status != 200)
    throw std::logic_error("the editor refused the harness's own request (" + std::to_string(r.status) +
                           "): " + r.body + "; request: " + request.substr(0, 200));
  return nlohmann::json::parse(r.body);
}

Editor& TheEditor() {
  static Editor* editor = [] {
    auto* e = new Editor;
    std::string pattern = (std::filesystem::temp_directory_path() / "phos-fuzz-editor-XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    e->root = pattern;
    const std::filesystem::path fixtures = std::filesystem::path(PHOS_FUZZ_FIXTURES_DIR);
    e->session = new editor::EditSession(fixtures / "scenes/cornell-phosphor.json", fixtures / "materials", e->root);
    std::mutex mutex;
    std::condition_variable listening;
    editor::ServerOptions options;
    options.port = 0;
    options.read_timeout_s = 5;
    options.stop = &e->stop;
    e->thread = std::thread([e, options, &mutex, &listening] {
      editor::Serve(*e->session, options, [&](int port) {
        std::lock_guard<std::mutex> lock(mutex);
        e->port = port;
        listening.notify_one();
      });
    });
    {
      std::unique_lock<std::mutex> lock(mutex);
      listening.wait(lock, [&] { return e->port != 0; });
    }
    std::atexit([] {
      Editor& ed = TheEditor();
      ed.stop = true;
      if (ed.thread.joinable()) ed.thread.join();
      std::error_code ec;
      std::filesystem::remove_all(ed.root, ec);
    });
    // One constraint on a lit phosphorescent wall, at 10 s (charging): the
    // first pixel of a few that the session takes.
    for (const auto& [x, y] : {std::pair{128, 40}, {40, 128}, {216, 128}, {128, 128}, {60, 60}, {196, 60}}) {
      const nlohmann::json c = {{"x", x}, {"y", y}, {"t_s", 10}};
      if (Send(e->port, Post(e->port, "/api/constraints", c.dump())).status == 200) {
        e->constraint = c;
        break;
      }
    }
    if (e->constraint.is_null()) throw std::logic_error("no pixel of the harness's takes a constraint");
    e->start_state = Snapshot(*e->session);
    std::fprintf(stderr, "fuzz-editor: port %d, constraint %s, exports under %s\n", e->port,
                 e->constraint.dump().c_str(), e->root.c_str());
    return e;
  }();
  return *editor;
}

// The preset each phosphorescent object of cornell-phosphor.json starts with.
const std::map<std::string, std::string> kStartPresets = {
    {"back wall", "green"}, {"left wall", "blue"}, {"right wall", "green"}};

// Puts back what an accepted request changed.
void PutBack(Editor& e, int route, std::string_view body, const Response& response) {
  const int port = e.port;
  const nlohmann::json start = e.start_state["constraints"][0];
  switch (route) {
    case 0:  // a second constraint: remove it
      Must(port, Post(port, "/api/constraints/remove", R"({"index": 1})"));
      break;
    case 1:  // constraint 0 changed: its fields back
      Must(port, Post(port, "/api/constraints/update",
                      nlohmann::json{{"index", 0},
                                     {"rgb", start["rgb"]},
                                     {"t_s", start["t_s"]},
                                     {"weight", start["weight"]},
                                     {"kind", start["kind"]}}
                          .dump()));
      break;
    case 2:  // constraint 0 removed: placed again (its target is what the point shows, as at the start)
      Must(port, Post(port, "/api/constraints", e.constraint.dump()));
      break;
    case 3: {  // a preset: the object's own back
      const std::string object = nlohmann::json::parse(body)["object"].get<std::string>();
      const auto it = kStartPresets.find(object);
      if (it == kStartPresets.end()) throw std::logic_error("a preset was set on '" + object + "', which has none");
      Must(port, Post(port, "/api/preset", nlohmann::json{{"object", object}, {"preset", it->second}}.dump()));
      break;
    }
    case 4: Must(port, Post(port, "/api/settings", R"({"states": null, "falloff": 0})")); break;
    case 5: {  // an export: what it wrote must be under the root; then the root is emptied
      const std::filesystem::path written = nlohmann::json::parse(response.body)["written"].get<std::string>();
      const std::string root = std::filesystem::weakly_canonical(e.root).string() + "/";
      if (written.string().rfind(root, 0) != 0 || !std::filesystem::is_regular_file(written))
        throw std::logic_error("an export wrote '" + written.string() + "', not a file under " + root);
      for (const auto& entry : std::filesystem::directory_iterator(e.root)) std::filesystem::remove_all(entry.path());
      return;  // nothing of the session changed
    }
    default: return;
  }
  if (Snapshot(*e.session) != e.start_state)
    throw std::logic_error("the session did not come back to its start: " + Snapshot(*e.session).dump());
}

std::string PercentEncoded(std::string_view text) {
  static const char* hex = "0123456789ABCDEF";
  std::string out;
  for (unsigned char ch : text) {
    out += '%';
    out += hex[ch >> 4];
    out += hex[ch & 15];
  }
  return out;
}

}  // namespace

bool EditorRequest(std::string_view data) {
  if (data.empty()) return false;
  Editor& e = TheEditor();
  static const char* const kRoutes[] = {"/api/constraints", "/api/constraints/update", "/api/constraints/remove",
                                        "/api/preset",      "/api/settings",           "/api/export"};
  const int route = static_cast<unsigned char>(data[0]) % 7;
  const std::string_view body = data.substr(1);
  const Response response = Send(e.port, route < 6 ? Post(e.port, kRoutes[route], body)
                                                   : Get(e.port, "/api/material?object=" + PercentEncoded(body)));
  if (response.status == 200) {
    PutBack(e, route, body, response);
    return true;
  }
  if (response.status != 400)
    throw std::logic_error("the editor answered " + std::to_string(response.status) + ": " +
                           response.body.substr(0, 400));
  nlohmann::json error;
  try {
    error = nlohmann::json::parse(response.body);
  } catch (const nlohmann::json::exception&) {
    throw std::logic_error("a 400 whose body is not JSON: " + response.body.substr(0, 400));
  }
  if (!error.is_object() || !error.contains("error") || !error["error"].is_string())
    throw std::logic_error("a 400 without an error: " + response.body.substr(0, 400));
  const std::string message = error["error"].get<std::string>();
  if (message.empty() || message.find_first_of("\r\n") != std::string::npos)
    throw std::logic_error("a refusal that is not one line: " + message);
  return false;
}

}  // namespace phos::fuzz
