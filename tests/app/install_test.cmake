# The install test (tests/CMakeLists.txt): cmake -DBUILD_DIR=.. -DPREFIX=..
# -DSOURCE_DIR=.. -P install_test.cmake. Fails (FATAL_ERROR) naming what went wrong.
file(REMOVE_RECURSE ${PREFIX})
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${PREFIX}
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cmake --install failed (${rc}): ${err}")
endif()

# Runs the installed phos from / (not the build or source tree); out/err/rc in <name>_*.
function(run_phos name)
  execute_process(COMMAND ${PREFIX}/bin/phos ${ARGN} WORKING_DIRECTORY /
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "installed 'phos ${ARGN}' exited with ${rc}: ${err}")
  endif()
  set(${name}_out "${out}" PARENT_SCOPE)
endfunction()

set(share ${PREFIX}/share/phos)
run_phos(simulate simulate --material ${share}/materials/green.json --charge-s 2 --irradiance 1,1,1,0,0,0,0,0
         --decay-s 2 --dt 1)
if(NOT simulate_out MATCHES "^t,r_1,L_1")
  message(FATAL_ERROR "installed phos simulate printed no CSV: ${simulate_out}")
endif()
run_phos(render render ${share}/scenes/still-life.json --out ${PREFIX}/frames --times 25 --width 16 --height 12)
if(NOT EXISTS ${PREFIX}/frames/frame-0000.png)
  message(FATAL_ERROR "installed phos render wrote no frame: ${render_out}")
endif()
# The editor's defaults are the installed data, not this machine's source tree.
run_phos(editor editor --help)
string(FIND "${editor_out}" "--presets TEXT=${share}/materials" installed)
string(FIND "${editor_out}" "${SOURCE_DIR}/fixtures" source)
if(installed EQUAL -1 OR NOT source EQUAL -1)
  message(FATAL_ERROR "installed phos editor --help does not name ${share}/materials as the presets' default: ${editor_out}")
endif()
file(REMOVE_RECURSE ${PREFIX})
