# The one place where Carousel targets get their warnings, sanitizers, clang-tidy and include
# directories. (-Wno-missing-field-initializers: every struct has default member initialisers,
# so designated initialisers like `{.overwrite = false}` leave nothing uninitialised.) Every module uses these helpers instead of add_library/add_executable directly.
#
#   carousel_add_library(NAME
#       [SOURCES src...]            # none: an INTERFACE (header-only / contract) library
#       [INCLUDE_DIR dir]           # the public include root (default include/); the private
#                                   # one is the src/ beside it (rig's api/include, api/src)
#       [PUBLIC_LINKS targets...] [PRIVATE_LINKS targets...]
#       [LANGUAGE_C99])             # pure C99 library (firmware-protocol)
#   carousel_add_executable(NAME SOURCES src... [PRIVATE_LINKS targets...] [OUTPUT_NAME name])
#   carousel_add_test(NAME SOURCES src... [LINKS targets...] LABELS unit|integration|e2e
#       [TIMEOUT seconds])          # one GoogleTest binary, each test registered with CTest
include_guard(GLOBAL)
include(GoogleTest)

if(CAROUSEL_CLANG_TIDY)
  find_program(CAROUSEL_CLANG_TIDY_EXE NAMES clang-tidy clang-tidy-14 REQUIRED)
endif()

# Precompiled headers: the standard and third-party headers most sources include (OpenCV,
# Eigen, OpenMesh, JSON and, in tests, GoogleTest), parsed once per target instead of once per
# source; they were some 4 s of every source's compile on 2 cores. Every C++ target links
# carousel_core, which makes these available. Only third-party headers: an edit to Carousel's
# own headers rebuilds what includes them and no more. CAROUSEL_PCH=OFF builds without (and so
# checks that every source includes what it uses); CAROUSEL_CLANG_TIDY does too, as clang
# cannot read GCC's precompiled headers.
option(CAROUSEL_PCH "Precompile the common standard and third-party headers" ON)
set(_carousel_pch_headers
  <algorithm> <array> <atomic> <chrono> <cmath> <cstdint> <cstdio> <cstdlib> <filesystem>
  <functional> <map> <memory> <mutex> <numbers> <optional> <random> <sstream> <string>
  <thread> <utility> <vector>
  <Eigen/Core> <Eigen/Geometry> <opencv2/core.hpp> <opencv2/imgproc.hpp> <nlohmann/json.hpp>
  <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>)

# The header is compiled once per target, so a target of one or two sources gains nothing.
function(_carousel_precompile target)
  get_target_property(_sources ${target} SOURCES)
  list(LENGTH _sources _count)
  if(CAROUSEL_PCH AND NOT CAROUSEL_CLANG_TIDY AND _count GREATER_EQUAL 3)
    set(_headers ${_carousel_pch_headers} ${ARGN})
    list(TRANSFORM _headers PREPEND "$<$<COMPILE_LANGUAGE:CXX>:")
    list(TRANSFORM _headers APPEND ">")
    target_precompile_headers(${target} PRIVATE ${_headers})
  endif()
endfunction()

function(_carousel_apply_defaults target)
  get_target_property(_type ${target} TYPE)
  if(_type STREQUAL "INTERFACE_LIBRARY")
    return()
  endif()
  target_compile_options(${target} PRIVATE
    $<$<OR:$<COMPILE_LANGUAGE:CXX>,$<COMPILE_LANGUAGE:C>>:-Wall -Wextra -Wpedantic -Wshadow=local
      -Wno-missing-field-initializers>
    $<$<COMPILE_LANGUAGE:CXX>:-Wnon-virtual-dtor -Woverloaded-virtual>)
  if(CAROUSEL_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  # GCC's -Wmaybe-uninitialized gives false positives under -fsanitize (seen in OpenMesh's
  # property containers at -O1); the Release build keeps the warning.
  target_compile_options(${target} PRIVATE $<$<CONFIG:Sanitize>:-Wno-maybe-uninitialized>)
  # Lets tests assert that a Sanitize build really is instrumented.
  target_compile_definitions(${target} PRIVATE $<$<CONFIG:Sanitize>:CAROUSEL_SANITIZE_BUILD=1>)
  if(CAROUSEL_CLANG_TIDY)
    set_target_properties(${target} PROPERTIES
      CXX_CLANG_TIDY "${CAROUSEL_CLANG_TIDY_EXE};--quiet"
      C_CLANG_TIDY "${CAROUSEL_CLANG_TIDY_EXE};--quiet")
  endif()
endfunction()

function(carousel_add_library name)
  cmake_parse_arguments(ARG "LANGUAGE_C99" "INCLUDE_DIR" "SOURCES;PUBLIC_LINKS;PRIVATE_LINKS"
    ${ARGN})
  if(NOT ARG_INCLUDE_DIR)
    set(ARG_INCLUDE_DIR include)
  endif()
  get_filename_component(_include_dir "${ARG_INCLUDE_DIR}" ABSOLUTE
    BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
  get_filename_component(_source_dir "${_include_dir}/../src" ABSOLUTE)
  if(ARG_SOURCES)
    add_library(${name} ${ARG_SOURCES})
    target_include_directories(${name}
      PUBLIC $<BUILD_INTERFACE:${_include_dir}>
      PRIVATE ${_source_dir})
    target_link_libraries(${name} PUBLIC ${ARG_PUBLIC_LINKS} PRIVATE ${ARG_PRIVATE_LINKS})
    if(ARG_LANGUAGE_C99)
      set_target_properties(${name} PROPERTIES C_STANDARD 99 C_STANDARD_REQUIRED ON C_EXTENSIONS OFF)
    else()
      _carousel_precompile(${name})
    endif()
  else()
    add_library(${name} INTERFACE)
    target_include_directories(${name} INTERFACE $<BUILD_INTERFACE:${_include_dir}>)
    target_link_libraries(${name} INTERFACE ${ARG_PUBLIC_LINKS})
  endif()
  _carousel_apply_defaults(${name})
endfunction()

function(carousel_add_executable name)
  cmake_parse_arguments(ARG "" "OUTPUT_NAME" "SOURCES;PRIVATE_LINKS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_PRIVATE_LINKS})
  if(ARG_OUTPUT_NAME)
    set_target_properties(${name} PROPERTIES OUTPUT_NAME ${ARG_OUTPUT_NAME})
  endif()
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY "${CMAKE_BINARY_DIR}/bin")
  _carousel_apply_defaults(${name})
  _carousel_precompile(${name})
endfunction()

function(carousel_add_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;LINKS;LABELS" ${ARGN})
  if(NOT ARG_LABELS)
    message(FATAL_ERROR "carousel_add_test(${name}): LABELS unit|integration|e2e is required")
  endif()
  foreach(_label IN LISTS ARG_LABELS)
    if(NOT _label MATCHES "^(unit|integration|e2e)$")
      message(FATAL_ERROR "carousel_add_test(${name}): unknown label '${_label}'")
    endif()
  endforeach()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE carousel_testing ${ARG_LINKS} GTest::gmock GTest::gtest_main)
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY "${CMAKE_BINARY_DIR}/tests")
  _carousel_apply_defaults(${name})
  _carousel_precompile(${name} <gtest/gtest.h> <gmock/gmock.h>)
  # Under the sanitizers, unit tests also catch a use of a stack frame after its function
  # returned (fake stacks: ~16 % slower, too slow for the integration tests' whole sessions).
  set(_extra_properties)
  if(CMAKE_BUILD_TYPE STREQUAL "Sanitize" AND "unit" IN_LIST ARG_LABELS)
    set(_extra_properties ENVIRONMENT_MODIFICATION
      "ASAN_OPTIONS=string_append::detect_stack_use_after_return=1")
  endif()
  gtest_discover_tests(${name}
    DISCOVERY_MODE PRE_TEST
    # Listing takes 0.4 s, but a loaded 2-core CI machine once exceeded CMake's 5 s default.
    DISCOVERY_TIMEOUT 60
    TEST_PREFIX "${name}."
    # The folder testing::SharedFixture shares between the test processes of one CTest run;
    # the fixture carousel_test_cache empties it before any test starts.
    PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
      ENVIRONMENT "CAROUSEL_TEST_CACHE_DIR=${CMAKE_BINARY_DIR}/test-cache"
      FIXTURES_REQUIRED carousel_test_cache ${_extra_properties})
endfunction()
