// phos editor: the page (docs/editor.md: binds 127.0.0.1). Apart from phos edit solve
// (cmd_edit.cpp), which links only the solver, not the renderer.

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.h"
#include "phos/editor/server.h"
#include "phos/util/error.h"

namespace phos::app {
namespace {

struct EditorArgs {
  std::string scene = DataFolder() + "/scenes/still-life.json";
  std::string presets = DataFolder() + "/materials";
  std::string bind = "127.0.0.1";
  int port = 8377;
  bool allow_remote = false;
};

void RunEditor(const EditorArgs& args) {
  const bool loopback = args.bind == "127.0.0.1" || args.bind == "localhost";
  if (!loopback && !args.allow_remote)
    ThrowUserError("", "--bind",
                   "'" + args.bind + "' would let other machines edit; add --allow-remote if you mean it");
  editor::EditSession session(args.scene, args.presets, std::filesystem::current_path());
  editor::ServerOptions options;
  options.bind = args.bind;
  options.port = args.port;
  editor::Serve(session, options, [&](int port) {
    std::printf("phos editor: %s on http://%s:%d/ (Ctrl-C to stop)\n", session.scene().name.c_str(), args.bind.c_str(),
                port);
    std::fflush(stdout);
  });
}

}  // namespace

void RegisterEditor(CLI::App& app) {
  auto args = std::make_shared<EditorArgs>();
  CLI::App* cmd =
      app.add_subcommand("editor",
                         "Serve the material editor page: the scene at any time, a timeline, and constraints placed\n"
                         "by clicking the image; every edit re-solves the material (Sec. 8.6). Listens on 127.0.0.1.");
  cmd->add_option("--scene", args->scene, "Scene file (phos.scene/1); default: the still life fixture");
  cmd->add_option("--presets", args->presets, "Folder of phos.material/1 presets")
      ->capture_default_str();
  cmd->add_option("--port", args->port, "Port (0: any free port)")->check(CLI::Range(0, 65535))->capture_default_str();
  cmd->add_option("--bind", args->bind, "Address to listen on (default 127.0.0.1)");
  cmd->add_flag("--allow-remote", args->allow_remote, "Allow --bind to an address other machines can reach");
  cmd->callback([args] { RunEditor(*args); });
}

}  // namespace phos::app
