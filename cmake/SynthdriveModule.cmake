# synthdrive_add_module(<name> SOURCES ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
#   One library target per module: synthdrive_<name>, alias synthdrive::<name>.
#   Public headers are included as "<module>/<header>.h" from src/.
function(synthdrive_add_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(synthdrive_${name} STATIC ${ARG_SOURCES})
  add_library(synthdrive::${name} ALIAS synthdrive_${name})
  target_include_directories(synthdrive_${name} PUBLIC ${PROJECT_SOURCE_DIR}/src)
  target_link_libraries(synthdrive_${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS}
                        synthdrive_warnings synthdrive_sanitizers)
  set_target_properties(synthdrive_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON)
endfunction()

# synthdrive_add_test(<file_test.cpp> DEPS ...): one executable and one CTest name per test file.
# Tests get SYNTHDRIVE_SOURCE_DIR so they find data/ and the optional ../shared/data.
function(synthdrive_add_test file)
  if(NOT SYNTHDRIVE_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "" "DEPS" ${ARGN})
  get_filename_component(stem ${file} NAME_WE)
  get_filename_component(dir ${CMAKE_CURRENT_SOURCE_DIR} NAME)
  set(target ${dir}_${stem})
  add_executable(${target} ${file})
  target_link_libraries(${target} PRIVATE ${ARG_DEPS} synthdrive_testing GTest::gtest_main
                        synthdrive_warnings synthdrive_sanitizers)
  set_target_properties(${target} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
  add_test(NAME ${target} COMMAND ${target})
  set_tests_properties(${target} PROPERTIES ENVIRONMENT "SYNTHDRIVE_SOURCE_DIR=${PROJECT_SOURCE_DIR}"
                       WORKING_DIRECTORY ${CMAKE_BINARY_DIR})
endfunction()
