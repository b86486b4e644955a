#include "phos/editor/server.h"

#include <mutex>

#include <httplib.h>
#include <nlohmann/json.hpp>

#include "phos/util/error.h"

namespace phos::editor {
namespace {

void Error(httplib::Response& response, int status, const std::string& message) {
  response.status = status;
  response.set_content(nlohmann::json{{"error", message}}.dump(), "application/json");
}

nlohmann::json ParseBody(const httplib::Request& request) {
  try {
    nlohmann::json body = nlohmann::json::parse(request.body);
    if (!body.is_object()) throw UserError("request: expected a JSON object");
    return body;
  } catch (const nlohmann::json::parse_error& e) {
    throw UserError(std::string("request: malformed JSON: ") + e.what());
  }
}

}  // namespace

void Serve(EditSession& session, const ServerOptions& options, const std::function<void(int)>& on_listening) {
  httplib::Server server;
  std::mutex mutex;  // httplib runs handlers on a thread pool; the session is not thread-safe
  int port = options.port;
  server.set_payload_max_length(options.max_body_bytes);

  // Origin and Host: only the page itself, at the address it was served from.
  server.set_pre_routing_handler([&](const httplib::Request& request, httplib::Response& response) {
    const std::string here = ":" + std::to_string(port);
    const std::string host = request.get_header_value("Host");
    const bool loopback = options.bind == "127.0.0.1" || options.bind == "localhost";
    if (loopback && host != "127.0.0.1" + here && host != "localhost" + here) {
      Error(response, 403, "Host '" + host + "' is not this editor's address");
      return httplib::Server::HandlerResponse::Handled;
    }
    if (request.has_header("Origin")) {
      const std::string origin = request.get_header_value("Origin");
      if (origin != "http://" + host) {
        Error(response, 403, "requests from other origins are refused ('" + origin + "')");
        return httplib::Server::HandlerResponse::Handled;
      }
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });

  // Every handler: one lock, and user errors become 400 with nothing changed
  // (the session validates a request completely before it edits anything).
  auto handle = [&](std::function<void(const httplib::Request&, httplib::Response&)> body) {
    return [&, body](const httplib::Request& request, httplib::Response& response) {
      std::lock_guard<std::mutex> lock(mutex);
      try {
        body(request, response);
      } catch (const UserError& e) {
        Error(response, 400, e.what());
      } catch (const std::exception& e) {
        Error(response, 500, std::string("internal error: ") + e.what());
      }
    };
  };
  auto state = [&](httplib::Response& response) { response.set_content(session.State().dump(), "application/json"); };

  server.Get("/", handle([](const httplib::Request&, httplib::Response& response) {
    response.set_content(EditorPage(), "text/html; charset=utf-8");
  }));
  server.Get("/api/state", handle([&](const httplib::Request&, httplib::Response& response) { state(response); }));
  server.Get("/api/frame", handle([&](const httplib::Request& request, httplib::Response& response) {
    double t = session.scene().start_s;
    if (request.has_param("t")) {
      try {
        t = std::stod(request.get_param_value("t"));
      } catch (const std::exception&) {
        throw UserError("t: expected seconds, got '" + request.get_param_value("t") + "'");
      }
    }
    double exposure = session.scene().camera.exposure;
    if (request.has_param("exposure")) {
      try {
        exposure = std::stod(request.get_param_value("exposure"));
      } catch (const std::exception&) {
        exposure = -1;
      }
      if (!(exposure > 0 && exposure < 1e6))
        throw UserError("exposure: expected a number > 0, got '" + request.get_param_value("exposure") + "'");
    }
    const std::vector<unsigned char> png = session.FramePng(t, exposure);
    response.set_content(std::string(png.begin(), png.end()), "image/png");
  }));
  server.Post("/api/constraints", handle([&](const httplib::Request& request, httplib::Response& response) {
    const nlohmann::json body = ParseBody(request);
    if (!body.contains("x") || !body["x"].is_number() || !body.contains("y") || !body["y"].is_number() ||
        !body.contains("t_s") || !body["t_s"].is_number())
      throw UserError("request: expected {\"x\": pixel, \"y\": pixel, \"t_s\": seconds}");
    session.AddConstraint(body["x"].get<int>(), body["y"].get<int>(), body["t_s"].get<double>());
    state(response);
  }));
  server.Post("/api/constraints/update", handle([&](const httplib::Request& request, httplib::Response& response) {
    const nlohmann::json body = ParseBody(request);
    if (!body.contains("index") || !body["index"].is_number_unsigned()) throw UserError("index: expected a constraint number");
    session.UpdateConstraint(body["index"].get<std::size_t>(), body);
    state(response);
  }));
  server.Post("/api/constraints/remove", handle([&](const httplib::Request& request, httplib::Response& response) {
    const nlohmann::json body = ParseBody(request);
    if (!body.contains("index") || !body["index"].is_number_unsigned()) throw UserError("index: expected a constraint number");
    session.RemoveConstraint(body["index"].get<std::size_t>());
    state(response);
  }));
  server.Post("/api/preset", handle([&](const httplib::Request& request, httplib::Response& response) {
    const nlohmann::json body = ParseBody(request);
    if (!body.contains("object") || !body["object"].is_string() || !body.contains("preset") || !body["preset"].is_string())
      throw UserError("request: expected {\"object\": name, \"preset\": name}");
    session.SetPreset(body["object"].get<std::string>(), body["preset"].get<std::string>());
    state(response);
  }));
  server.Post("/api/settings", handle([&](const httplib::Request& request, httplib::Response& response) {
    const nlohmann::json body = ParseBody(request);
    if (body.contains("states") && !body["states"].is_number_integer()) throw UserError("states: expected 1, 2 or 3");
    if (body.contains("falloff") && !body["falloff"].is_number()) throw UserError("falloff: expected a number");
    if (body.contains("states")) session.SetStates(body["states"].get<int>());
    if (body.contains("falloff")) session.SetPropagation(body["falloff"].get<double>());
    state(response);
  }));
  server.Get("/api/material", handle([&](const httplib::Request& request, httplib::Response& response) {
    const std::string object = request.get_param_value("object");
    response.set_content(session.MaterialJson(object).dump(2) + "\n", "application/json");
    response.set_header("Content-Disposition", "attachment; filename=\"material.json\"");
  }));
  server.Post("/api/export", handle([&](const httplib::Request& request, httplib::Response& response) {
    const nlohmann::json body = ParseBody(request);
    if (!body.contains("object") || !body["object"].is_string() || !body.contains("path") || !body["path"].is_string())
      throw UserError("request: expected {\"object\": name, \"path\": relative path}");
    const std::filesystem::path written =
        session.ExportMaterial(body["object"].get<std::string>(), body["path"].get<std::string>());
    response.set_content(nlohmann::json{{"written", written.string()}}.dump(), "application/json");
  }));

  if (port == 0) {
    port = server.bind_to_any_port(options.bind);
    if (port < 0) ThrowUserError("--bind", "", "cannot listen on " + options.bind);
  } else if (!server.bind_to_port(options.bind, port)) {
    ThrowUserError("--port", "", "cannot listen on " + options.bind + ":" + std::to_string(port) + " (in use?)");
  }
  on_listening(port);
  server.listen_after_bind();
}

}  // namespace phos::editor
