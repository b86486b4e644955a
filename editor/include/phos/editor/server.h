#pragma once
// The editor page's HTTP server (cpp-httplib): the page itself and a small
// JSON API over an EditSession. It listens on 127.0.0.1 unless told
// otherwise, and refuses what it should (DESIGN.md editor/, issue "editor"):
//  - requests whose Origin is not the page's own, or whose Host is not the
//    address it listens on (cross-site requests, DNS rebinding): 403;
//  - bodies over max_body_bytes: 413;
//  - malformed JSON or bad fields: 400 with {"error": one line}, nothing changed;
//  - export paths outside the working folder: 400 naming the path.
//
// API: GET / (the page), GET /api/state, GET /api/frame?t=S (PNG),
// POST /api/constraints {x, y, t_s}, POST /api/constraints/update {index, rgb?, t_s?, weight?, kind?},
// POST /api/constraints/remove {index}, POST /api/preset {object, preset},
// POST /api/settings {states?, falloff?}, GET /api/material?object=NAME (download),
// POST /api/export {object, path}.

#include <cstddef>
#include <functional>
#include <string>

#include "phos/editor/session.h"

namespace phos::editor {

struct ServerOptions {
  std::string bind = "127.0.0.1";
  int port = 8377;  // 0: any free port
  std::size_t max_body_bytes = 64 * 1024;
};

// The page's HTML (editor/web/index.html, compiled in).
const std::string& EditorPage();

// Serves until the process is stopped. on_listening(port) runs once the socket
// is bound. A port that cannot be bound is a UserError.
void Serve(EditSession& session, const ServerOptions& options, const std::function<void(int)>& on_listening);

}  // namespace phos::editor
