# One-call helpers for libraries and tests, with explicit file lists (no globbing).
#
#   handdb_add_library(NAME handdb_format SRCS a.cc b.cc DEPS PUBLIC x PRIVATE y)
#   handdb_add_test(NAME format/shard_reader_test SRCS format/shard_reader_test.cc DEPS handdb_format)
#   handdb_add_plugin(NAME handdb_fit SRCS fit.cc LOADED_BY handdb_pose)
#   (optional: LABELS a;b, TIMEOUT seconds, COST seconds of its longest run, under the sanitizers)
#
# Test names are "<module>/<file stem>" so `ctest -R format/` selects a module.
include_guard(GLOBAL)

function(handdb_add_library)
  cmake_parse_arguments(ARG "" "NAME" "SRCS;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(${ARG_NAME} STATIC ${ARG_SRCS})
  # Rooted at the repository in the build tree, at include/handdb/ when installed (cmake/
  # HanddbInstall.cmake), so `#include "format/shard_reader.h"` works in both. PIC: the Python
  # module (python/) is a shared object linking these archives.
  target_include_directories(${ARG_NAME} PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>
                                                $<INSTALL_INTERFACE:include/handdb>)
  set_target_properties(${ARG_NAME} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  target_link_libraries(${ARG_NAME} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  target_compile_options(${ARG_NAME} PRIVATE ${HANDDB_WARNINGS})
endfunction()

# A shared object handdb opens on first use (base/plugin.h, docs/decisions/0020): built beside
# the handdb binary, installed there, exporting only what it marks, and built before the library
# whose code opens it (LOADED_BY), so whatever links that library finds it. The caller links it.
function(handdb_add_plugin)
  cmake_parse_arguments(ARG "" "NAME;LOADED_BY" "SRCS" ${ARGN})
  add_library(${ARG_NAME} MODULE ${ARG_SRCS})
  target_include_directories(${ARG_NAME} PRIVATE ${PROJECT_SOURCE_DIR})
  target_compile_options(${ARG_NAME} PRIVATE ${HANDDB_WARNINGS})
  target_link_options(${ARG_NAME} PRIVATE -Wl,--as-needed)
  set_target_properties(${ARG_NAME} PROPERTIES
    CXX_VISIBILITY_PRESET hidden
    VISIBILITY_INLINES_HIDDEN ON
    LIBRARY_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/cli)
  include(GNUInstallDirs)
  install(TARGETS ${ARG_NAME} LIBRARY DESTINATION ${CMAKE_INSTALL_BINDIR})
  add_dependencies(${ARG_LOADED_BY} ${ARG_NAME})
endfunction()

function(handdb_add_test)
  cmake_parse_arguments(ARG "" "NAME;TIMEOUT;COST" "SRCS;DEPS;LABELS" ${ARGN})
  # A test the sanitizer run leaves out (no_sanitizer) is not built there either.
  if(NOT HANDDB_BUILD_TESTS OR (NOT HANDDB_INTEGRATION_TESTS AND "integration" IN_LIST ARG_LABELS)
     OR (HANDDB_SANITIZE AND "no_sanitizer" IN_LIST ARG_LABELS))
    return()
  endif()
  string(REPLACE "/" "_" target ${ARG_NAME})
  add_executable(${target} ${ARG_SRCS})
  target_link_libraries(${target} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_options(${target} PRIVATE ${HANDDB_WARNINGS})
  # A test's own code is not where it spends its time (the libraries it links are): -O1 compiles
  # a gtest file in half the time of -O2 in the optimised builds.
  if(CMAKE_BUILD_TYPE MATCHES "^Rel")
    target_compile_options(${target} PRIVATE -O1)
  endif()
  add_test(NAME ${ARG_NAME} COMMAND ${target})
  set_tests_properties(${ARG_NAME} PROPERTIES
    ENVIRONMENT "HANDDB_SOURCE_DIR=${PROJECT_SOURCE_DIR};HANDDB_BINARY_DIR=${PROJECT_BINARY_DIR}")
  if(ARG_TIMEOUT)
    set_tests_properties(${ARG_NAME} PROPERTIES TIMEOUT ${ARG_TIMEOUT})
  endif()
  if(ARG_LABELS)
    set_tests_properties(${ARG_NAME} PROPERTIES LABELS "${ARG_LABELS}")
  endif()
  # Seconds, the longest run (tests/CMakeLists.txt: `ctest -j` starts the long ones first).
  if(ARG_COST)
    set_tests_properties(${ARG_NAME} PROPERTIES COST ${ARG_COST})
  endif()
endfunction()
