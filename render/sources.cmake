# phos_render's sources, relative to render/. One list for the library
# (render/CMakeLists.txt) and the fuzz harnesses (fuzz/CMakeLists.txt), so
# that a new source cannot be missing from the harnesses' link (a hand-kept
# copy of this list once missed one).
set(PHOS_RENDER_SOURCES
  src/scene.cpp
  src/light_units.cpp
  src/mesh.cpp
  src/spectral_upsampling.cpp
  src/surface_textures.cpp
  src/phosphor_map.cpp
  src/bsdf.cpp
  src/geometry.cpp
  src/texel_count.cpp
  src/solver.cpp
  src/renderer.cpp
  src/shading.cpp
  src/alias_table.cpp
  src/transport_direct.cpp
  src/transport_path.cpp
  src/transport_dss.cpp
  src/glassner.cpp
  src/night_vision.cpp
  src/exposure.cpp
  src/dss.cpp
  src/volume.cpp
  src/transport_quality.cpp)
