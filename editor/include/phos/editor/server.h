#pragma once
// The editor page's HTTP server (cpp-httplib): the page itself and a small
// JSON API over an EditSession. It listens on 127.0.0.1 unless told
// otherwise, and refuses what it should (docs/editor.md, "The page"):
//  - requests whose Origin is not the page's own, or whose Host is not the
//    address it listens on (cross-site requests, DNS rebinding): 403;
//  - a Host or Origin header given twice: 400;
//  - bodies over max_body_bytes: 413; bodies with a Transfer-Encoding: 411
//    (httplib does not hold chunked bodies to the limit); more than 64 KiB
//    of request line and headers: the request fails (400);
//  - malformed JSON, bad or unknown fields or query parameters, numbers beyond
//    a double (1e400), over-long names: 400 with {"error": one line naming the
//    field}, nothing changed;
//  - export paths outside the working folder, with control characters, or
//    through a symbolic link: 400 naming the path;
//  - unknown routes: 404; a route with the wrong method: 405;
//  - more than max_connections at once: 503; a request slower than
//    request_timeout_s from its first byte, or a connection silent for
//    read_timeout_s: the connection is closed.
//
// API: GET / (the page), GET /api/state, GET /api/frame?t=S (PNG),
// POST /api/constraints {x, y, t_s}, POST /api/constraints/update {index, rgb?, t_s?, weight?, kind?},
// POST /api/constraints/remove {index}, POST /api/preset {object, preset},
// POST /api/settings {states?, falloff?}, GET /api/material?object=NAME (download),
// POST /api/export {object, path}.

#include <atomic>
#include <cstddef>
#include <functional>
#include <string>

#include "phos/editor/session.h"

namespace phos::editor {

struct ServerOptions {
  std::string bind = "127.0.0.1";
  int port = 8377;  // 0: any free port; a port in use is refused (no SO_REUSEPORT)
  std::size_t max_body_bytes = 64 * 1024;
  // A request (line, headers, body) must arrive within request_timeout_s of
  // its first byte, however slowly its bytes come; a connection that sends
  // nothing is closed after read_timeout_s; its response must leave within
  // write_timeout_s. One request per connection.
  double read_timeout_s = 30;  // a browser preconnects and may send its request many seconds later (seen under ASan)
  double request_timeout_s = 5;
  double write_timeout_s = 5;
  // Connections served at once, each on a thread of its own; more are answered
  // 503 at once. Slow clients hold only their own, up to the timeouts.
  std::size_t max_connections = 64;
  // When set, Serve returns once *stop is true (within 0.1 s), after the
  // connections in flight are done. Tests run the server on a thread this way.
  const std::atomic<bool>* stop = nullptr;
};

// The page's HTML (editor/web/index.html, compiled in).
const std::string& EditorPage();

// Serves until the process is stopped (or options.stop). on_listening(port)
// runs once the socket is bound. A port that cannot be bound is a UserError
// ("--port: 127.0.0.1:P is in use ...").
void Serve(EditSession& session, const ServerOptions& options, const std::function<void(int)>& on_listening);

}  // namespace phos::editor
