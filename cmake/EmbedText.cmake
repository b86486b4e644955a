# phos_embed_text(OUT INPUT NAMESPACE SYMBOL): generates OUT (a .cpp) that
# defines `extern const char SYMBOL[]` in NAMESPACE holding the text of INPUT,
# and reconfigures when INPUT changes. Used for render/data/transport-quality.json
# by render/CMakeLists.txt and by the fuzz harnesses' own project
# (fuzz/CMakeLists.txt), so the data is embedded one way.
function(phos_embed_text out input namespace symbol)
  file(READ ${input} PHOS_EMBED_TEXT)
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${input})
  set(PHOS_EMBED_INPUT ${input})
  set(PHOS_EMBED_NAMESPACE ${namespace})
  set(PHOS_EMBED_SYMBOL ${symbol})
  file(CONFIGURE OUTPUT ${out} CONTENT
"// Generated from @PHOS_EMBED_INPUT@ by cmake/EmbedText.cmake.
namespace @PHOS_EMBED_NAMESPACE@ {
extern const char @PHOS_EMBED_SYMBOL@[];
const char @PHOS_EMBED_SYMBOL@[] = R\"phos_embed(@PHOS_EMBED_TEXT@)phos_embed\";
}  // namespace @PHOS_EMBED_NAMESPACE@
" @ONLY)
endfunction()
