# The installable package: `cmake --install build --prefix P` puts
#   P/bin/handdb                                the tool
#   P/bin/libhanddb_*.so                        its plugins, opened on first use (base/plugin.h)
#   P/lib/libhanddb_<module>.a                  one archive per module
#   P/include/handdb/<module>/...h              each module's door headers only (below)
#   P/include/handdb/handdb_version.h
#   P/share/handdb/schemas/*.schema.json        the JSON schemas of every file read or written
#   P/lib/cmake/handdb/handdbConfig.cmake       find_package(handdb): handdb::base, handdb::format,
#                      handdbConfigVersion.cmake  handdb::cluster, handdb::edges, handdb::generator,
#                      handdbTargets.cmake        handdb::query, handdb::evaluate
#   P/${HANDDB_PYTHON_INSTALL_DIR}/handdb/      the Python module and the plugins (python/CMakeLists.txt)
# A consumer writes `#include "query/searcher.h"` as inside this repository (include/handdb/ is
# the targets' include directory). tests/install/ builds a consumer against an installed tree.
include_guard(GLOBAL)
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(HANDDB_CMAKE_INSTALL_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/handdb)
set(HANDDB_INCLUDE_INSTALL_DIR ${CMAKE_INSTALL_INCLUDEDIR}/handdb)
set(HANDDB_SCHEMA_INSTALL_DIR ${CMAKE_INSTALL_DATADIR}/handdb/schemas)

# The doors: the headers a user of each library includes, and every header they include (the
# closure is checked below, so an installed header never includes one that is not installed).
# Internals stay out: the shard byte layout (format/shard_layout.h), the chamfer terms, distance
# transforms and SIMD kernels of query/, the samplers of generator/, and every *_testing.h.
# query/kdtree.h and query/coarse_bound.h are doors because query/searcher.h needs their types
# (SearchOptions::kdtree, the Searcher's coarse fields), query/index/view_index.h for
# SearchOptions::index and Searcher::SetIndex (and index/embedding.h for the index's grid);
# format/coarse_field.h and base/huge_pages.h because coarse_bound.h does.
set(HANDDB_DOORS_base status.h atomic_file.h json_schema.h thread_pool.h progress.h subprocess.h
                      repo_root.h huge_pages.h)
set(HANDDB_DOORS_format view.h roll.h shard_reader.h shard_writer.h manifest.h validator.h
                        coarse_field.h)
set(HANDDB_DOORS_cluster slurm.h)
set(HANDDB_DOORS_edges edges.h normalise.h exr_io.h view_conversion.h)
set(HANDDB_DOORS_generator plan/plan.h hand/hand_model.h render/blender.h render/render_driver.h
                           convert/converter.h testset/testset.h hand/camera.h
                           hand/kinematics.h hand/database_rig.h)
set(HANDDB_DOORS_query database.h searcher.h kdtree.h coarse_bound.h index/view_index.h
                       index/embedding.h)
set(HANDDB_DOORS_nn tflite.h)
set(HANDDB_DOORS_photo image_edges.h hand_landmarks.h)
set(HANDDB_DOORS_pose fit.h fit_matches.h fit_silhouette.h landmark_rank.h match_json.h picture_search.h sheet.h)
set(HANDDB_DOORS_evaluate evaluate.h metrics.h plots.h parts.h photos.h photo_keypoints.h)
set(HANDDB_DOORS_track frames.h neighbourhood.h smoothing.h tracker.h track_json.h)
set(HANDDB_MODULES base nn format cluster edges generator query photo pose track evaluate)

# Every door's `#include "x/y.h"` must be a door too (or the generated version header).
set(_handdb_all_doors handdb_version.h)
foreach(module IN LISTS HANDDB_MODULES)
  foreach(h IN LISTS HANDDB_DOORS_${module})
    list(APPEND _handdb_all_doors ${module}/${h})
  endforeach()
endforeach()
foreach(door IN LISTS _handdb_all_doors)
  if(door STREQUAL "handdb_version.h")
    continue()
  endif()
  if(NOT EXISTS ${PROJECT_SOURCE_DIR}/${door})
    message(FATAL_ERROR "cmake/HanddbInstall.cmake: door header ${door} does not exist")
  endif()
  file(STRINGS ${PROJECT_SOURCE_DIR}/${door} _includes REGEX "^#include \"[^\"]+\"")
  foreach(line IN LISTS _includes)
    string(REGEX REPLACE "^#include \"([^\"]+)\".*" "\\1" inc "${line}")
    if(NOT inc IN_LIST _handdb_all_doors)
      message(FATAL_ERROR "cmake/HanddbInstall.cmake: the installed header ${door} includes "
                          "${inc}, which is not installed: add it to the doors of its module or "
                          "keep it out of ${door}")
    endif()
  endforeach()
endforeach()

foreach(module IN LISTS HANDDB_MODULES)
  set_target_properties(handdb_${module} PROPERTIES EXPORT_NAME ${module})
  foreach(h IN LISTS HANDDB_DOORS_${module})
    get_filename_component(sub ${h} DIRECTORY)
    install(FILES ${PROJECT_SOURCE_DIR}/${module}/${h}
            DESTINATION ${HANDDB_INCLUDE_INSTALL_DIR}/${module}/${sub})
  endforeach()
  install(TARGETS handdb_${module} EXPORT handdbTargets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
endforeach()
install(FILES ${PROJECT_BINARY_DIR}/generated/handdb_version.h
        DESTINATION ${HANDDB_INCLUDE_INSTALL_DIR})
install(TARGETS handdb RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/schemas/ DESTINATION ${HANDDB_SCHEMA_INSTALL_DIR}
        FILES_MATCHING PATTERN "*.schema.json")

install(EXPORT handdbTargets NAMESPACE handdb:: DESTINATION ${HANDDB_CMAKE_INSTALL_DIR})
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/handdbConfig.cmake.in
  ${PROJECT_BINARY_DIR}/generated/handdbConfig.cmake
  INSTALL_DESTINATION ${HANDDB_CMAKE_INSTALL_DIR}
  PATH_VARS HANDDB_INCLUDE_INSTALL_DIR HANDDB_SCHEMA_INSTALL_DIR)
# 0.x: a minor version may change the API, so only the same major.minor is compatible.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/generated/handdbConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/generated/handdbConfig.cmake
              ${PROJECT_BINARY_DIR}/generated/handdbConfigVersion.cmake
              ${PROJECT_SOURCE_DIR}/cmake/FindXNNPACK.cmake
        DESTINATION ${HANDDB_CMAKE_INSTALL_DIR})
