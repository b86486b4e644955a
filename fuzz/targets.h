#pragma once
// One function per loader, taking a file's bytes: the libFuzzer harnesses
// (fuzz_entry.cpp) call them, and so does the regression test
// (tests/fuzz/regression_test.cpp) on every input that ever crashed
// (fuzz/regressions/<target>/). A function returns true when the input
// loads and false when it is refused as a UserError of one line; anything
// else (a crash, a sanitizer report, another exception, a UserError of
// several lines) is a finding. docs/fuzzing.md says how to run them.

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace phos::fuzz {

// The fixtures folder: scenes refer to meshes and materials by paths
// relative to fixtures/scenes, glTF files to buffers beside them.
void SetFixturesDir(const char* dir);

bool Material(std::string_view data);     // phos.material/1, then a simulation that must stay finite
bool Scene(std::string_view data);        // phos.scene/1 (meshes and materials from fixtures/scenes)
bool ObjMesh(std::string_view data);      // Wavefront OBJ
bool GltfMesh(std::string_view data);     // glTF 2.0, JSON or binary (.glb)
bool Constraints(std::string_view data);  // phos.constraints/1
bool LabConfig(std::string_view data);    // phos.lab/1 (LabConfigFromJson, as LoadLabConfig reads a file)
bool CurveCsv(std::string_view data);     // a curve table as fit decay-curve and charge-curve read it
// The session records (acquire/session_records.h): the same bytes as
// session.json, frames.jsonl, events.jsonl and stop.json of one session
// folder, each read by its reader (and every frame listed checked against
// its file). True when all four accept, false when any refuses.
bool SessionRecords(std::string_view data);
// One request to the editor's HTTP server (editor_target.cpp, not in
// kTargets: it needs the renderer and the editor, which the regression test
// does not link): the first byte picks the route, the rest is its JSON body.
bool EditorRequest(std::string_view data);

struct Target {
  const char* name;
  bool (*run)(std::string_view);
};
inline constexpr Target kTargets[] = {
    {"material", Material},       {"scene", Scene},   {"obj", ObjMesh},        {"gltf", GltfMesh},
    {"constraints", Constraints}, {"lab", LabConfig}, {"curve_csv", CurveCsv}, {"session", SessionRecords},
};

}  // namespace phos::fuzz
