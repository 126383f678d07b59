# Shared build helpers for probeless targets.

add_compile_options(-Wall -Wextra -Wno-unused-parameter -Wno-missing-field-initializers)

if(PROBELESS_SANITIZE)
  add_compile_options(-fsanitize=${PROBELESS_SANITIZE} -fno-omit-frame-pointer -g)
  add_link_options(-fsanitize=${PROBELESS_SANITIZE})
endif()

# Where tests find the shared data set (skipped with a message when absent).
if(DEFINED ENV{PROBELESS_DATA})
  set(PROBELESS_DATA_DIR "$ENV{PROBELESS_DATA}")
else()
  set(PROBELESS_DATA_DIR "${CMAKE_SOURCE_DIR}/../shared/data")
endif()

# probeless_add_test(NAME <name> SOURCES <files...> LIBS <targets...> [LABELS <labels...>]
#                    [TIMEOUT <seconds>] [INCLUDES <dirs...>])
# One GoogleTest executable registered with ctest under its own name; INCLUDES adds private include
# directories (a library's src/ for tests of its private kernels). Nothing when tests are off.
function(probeless_add_test)
  cmake_parse_arguments(T "" "NAME;TIMEOUT" "SOURCES;LIBS;LABELS;INCLUDES" ${ARGN})
  if(NOT PROBELESS_BUILD_TESTS)
    return()
  endif()
  add_executable(${T_NAME} ${T_SOURCES})
  if(T_INCLUDES)
    target_include_directories(${T_NAME} PRIVATE ${T_INCLUDES})
  endif()
  set_target_properties(${T_NAME} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
  target_link_libraries(${T_NAME} PRIVATE ${T_LIBS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${T_NAME} PRIVATE
    PROBELESS_BIN_DIR="${CMAKE_BINARY_DIR}/bin"
    PROBELESS_TEST_BIN_DIR="${CMAKE_BINARY_DIR}/tests"
    PROBELESS_SOURCE_DIR="${CMAKE_SOURCE_DIR}")
  add_test(NAME ${T_NAME} COMMAND ${T_NAME})
  if(NOT T_TIMEOUT)
    set(T_TIMEOUT 120)
  endif()
  set_tests_properties(${T_NAME} PROPERTIES TIMEOUT ${T_TIMEOUT} LABELS "${T_LABELS}"
    ENVIRONMENT "PROBELESS_DOMAIN=ctest_${T_NAME}")
  if("sanitize" IN_LIST T_LABELS)
    add_dependencies(sanitize_targets ${T_NAME})
  endif()
  if("tsan" IN_LIST T_LABELS)
    add_dependencies(tsan_targets ${T_NAME})
  endif()
endfunction()

# probeless_add_tool(NAME <name> SOURCES <files...> LIBS <targets...>)
# An executable that lands in build/bin/<name>.
function(probeless_add_tool)
  cmake_parse_arguments(T "" "NAME" "SOURCES;LIBS" ${ARGN})
  add_executable(${T_NAME} ${T_SOURCES})
  target_link_libraries(${T_NAME} PRIVATE ${T_LIBS})
endfunction()

# Aggregate targets for tools/test: what the address/undefined sanitizer build (tests labelled
# "sanitize"), the thread sanitizer build (tests labelled "tsan") and the fuzz build compile.
add_custom_target(sanitize_targets)
add_custom_target(tsan_targets)
add_custom_target(fuzz_targets)

# probeless_sanitize_depends(<targets...>): build these in both sanitizer builds too (tests
# labelled "sanitize" or "tsan" are added automatically; add the executables such tests run).
function(probeless_sanitize_depends)
  add_dependencies(sanitize_targets ${ARGN})
  add_dependencies(tsan_targets ${ARGN})
endfunction()

# The fuzz build instruments every library, not only the fuzz targets: libFuzzer's coverage
# feedback then reaches the parsers' own branches, and ASan/UBSan catch a bad access or undefined
# behaviour inside a library where it happens (UBSan aborts, so libFuzzer keeps the input).
if(PROBELESS_BUILD_FUZZERS)
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined
                      -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined)
endif()

# probeless_add_fuzzer(NAME <name> SOURCES <files...> LIBS <targets...> [CORPUS <dir>]
#                      [LABELS <labels...>])
# With -DPROBELESS_BUILD_FUZZERS=ON (clang): a libFuzzer target in <build>/fuzz/<name>. With a
# CORPUS, ctest replays every file of it once as <name>_seeds (labels fuzz + LABELS) in every
# build: in a test build through tests/fuzz/replay_main.cpp (no libFuzzer needed), so a committed
# regression input fails the ordinary ctest run if its bug comes back.
function(probeless_add_fuzzer)
  cmake_parse_arguments(F "" "NAME;CORPUS" "SOURCES;LIBS;LABELS" ${ARGN})
  if(PROBELESS_BUILD_FUZZERS)
    add_executable(${F_NAME} ${F_SOURCES})
    target_compile_options(${F_NAME} PRIVATE -fsanitize=fuzzer,address,undefined)
    target_link_options(${F_NAME} PRIVATE -fsanitize=fuzzer,address,undefined)
    target_link_libraries(${F_NAME} PRIVATE ${F_LIBS})
    set_target_properties(${F_NAME} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/fuzz)
    add_dependencies(fuzz_targets ${F_NAME})
    set(_command ${F_NAME} -runs=0 ${F_CORPUS})
  elseif(PROBELESS_BUILD_TESTS AND F_CORPUS)
    add_executable(${F_NAME}_replay ${F_SOURCES} ${PROJECT_SOURCE_DIR}/tests/fuzz/replay_main.cpp)
    target_link_libraries(${F_NAME}_replay PRIVATE ${F_LIBS} probeless_parse)
    set_target_properties(${F_NAME}_replay PROPERTIES RUNTIME_OUTPUT_DIRECTORY
                                                      ${CMAKE_BINARY_DIR}/tests)
    set(_command ${F_NAME}_replay ${F_CORPUS})
    if("sanitize" IN_LIST F_LABELS)
      add_dependencies(sanitize_targets ${F_NAME}_replay)  # its seeds replayed under ASan/UBSan
    endif()
  else()
    return()
  endif()
  if(F_CORPUS)
    add_test(NAME ${F_NAME}_seeds COMMAND ${_command})
    set_tests_properties(${F_NAME}_seeds PROPERTIES TIMEOUT 60 LABELS "fuzz;${F_LABELS}")
  endif()
endfunction()
