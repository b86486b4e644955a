# phos_editor_page(OUT): generates OUT (a .cpp) that compiles editor/web/index.html
# into phos::editor::EditorPage(), and reconfigures when the page changes.
# Used by editor/CMakeLists.txt and by the fuzz harnesses' own project
# (fuzz/CMakeLists.txt), so the page is embedded one way.
get_filename_component(PHOS_EDITOR_PAGE_HTML ${CMAKE_CURRENT_LIST_DIR}/../editor/web/index.html ABSOLUTE)
function(phos_editor_page out)
  set(page ${PHOS_EDITOR_PAGE_HTML})
  file(READ ${page} PHOS_EDITOR_PAGE)
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${page})
  file(CONFIGURE OUTPUT ${out} CONTENT
"// Generated from editor/web/index.html by cmake/EditorPage.cmake.
#include \"phos/editor/server.h\"
namespace phos::editor {
const std::string& EditorPage() {
  static const std::string page = R\"phos_page(@PHOS_EDITOR_PAGE@)phos_page\";
  return page;
}
}  // namespace phos::editor
" @ONLY)
endfunction()
