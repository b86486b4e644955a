# One line registers a test (after Ceres' CERES_TEST macro):
#   phos_test(model material)  ->  tests/model/material_test.cpp, target model_material_test,
# linked with the part's library phos_<part> (when there is one) and any extra
# libraries given after the name.
find_package(GTest REQUIRED)
include(GoogleTest)

function(phos_test part name)
  set(target ${part}_${name}_test)
  add_executable(${target} ${CMAKE_SOURCE_DIR}/tests/${part}/${name}_test.cpp)
  if(TARGET phos_${part})
    target_link_libraries(${target} PRIVATE phos_${part})
  endif()
  target_link_libraries(${target} PRIVATE GTest::gtest GTest::gtest_main ${ARGN})
  target_include_directories(${target} PRIVATE ${CMAKE_SOURCE_DIR}/tests)
  target_compile_definitions(${target} PRIVATE
    PHOS_FIXTURES_DIR="${PHOS_FIXTURES_DIR}"
    PHOS_BINARY="$<TARGET_FILE:phos>")
  # Under the sanitizers, test code is built with AddressSanitizer only: the
  # code under test (the libraries and commands) keeps UBSan, and the test
  # files, 40% of what CI compiles, build about a third faster (the CI run
  # must fit in 30 minutes on 2 cores). They stay at -O1: at -O0 they compile
  # about a quarter faster, but tests that integrate in their own code run
  # slower than that saves (AreaLight.TiltedLights...Quadrature: 129 s
  # instead of 11 s). Precompiled headers (gtest, json, Eigen, OpenImageIO,
  # Ceres, CLI11 per part) saved 5% of the build's CPU time; not kept.
  if(PHOS_SANITIZE)
    target_compile_options(${target} PRIVATE -fno-sanitize=undefined)
  endif()
  add_dependencies(${target} phos)
  # A GTEST_SKIP shows as skipped in ctest's output (and says why in the
  # test's log), not as passed: the Slurm test skips where no cluster can start.
  # PHOS_TEST_COST_<target> (seconds, tests/CMakeLists.txt): ctest -j starts
  # the costliest tests first; a clean clone has no timings of its own, and a
  # four-minute test started last would run alone at the end of CI.
  set(cost 0)
  if(DEFINED PHOS_TEST_COST_${target})
    set(cost ${PHOS_TEST_COST_${target}})
  endif()
  # PHOS_TEST_RUN_SERIAL_<target>: run alone. The GigE fake camera over
  # loopback answers resend requests within Aravis's millisecond packet
  # timeouts only when it gets a core: run beside busy tests on 2 cores,
  # all 31 tries of one frame timed out once (CI, 4 December; it passed in
  # the runs before). A real camera has its own CPU.
  set(serial FALSE)
  if(PHOS_TEST_RUN_SERIAL_${target})
    set(serial TRUE)
  endif()
  gtest_discover_tests(${target} DISCOVERY_TIMEOUT 60
                       PROPERTIES TIMEOUT 600 COST ${cost} RUN_SERIAL ${serial}
                                  SKIP_REGULAR_EXPRESSION "\\[  SKIPPED \\]")
endfunction()
