# cmake -D BUILD_DIR=... -D SOURCE_DIR=... -D WORK_DIR=... -D GENERATOR=... -D DOC=... -P run.cmake
# Installs the core (Development component) from BUILD_DIR into WORK_DIR/prefix, then
# configures, builds and runs the programs of SOURCE_DIR against it: main.cpp, and the example
# program of DOC (docs/cpp-api.md, the ```cpp block that starts "// Renders an emissive
# triangle"), as written. Any failure fails the test.
file(REMOVE_RECURSE "${WORK_DIR}")

function(step)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE result OUTPUT_VARIABLE out)
  message("${out}")
  if(NOT result EQUAL 0)
    string(REPLACE ";" " " command "${ARGN}")
    message(FATAL_ERROR "failed (${result}): ${command}")
  endif()
  set(step_output "${out}" PARENT_SCOPE)
endfunction()

file(READ "${DOC}" doc)
string(FIND "${doc}" "```cpp\n// Renders an emissive triangle" begin)
if(begin EQUAL -1)
  message(FATAL_ERROR "${DOC}: no example program (```cpp block starting '// Renders an emissive triangle')")
endif()
math(EXPR begin "${begin} + 7")
string(SUBSTRING "${doc}" ${begin} -1 rest)
string(FIND "${rest}" "\n```" end)
math(EXPR end "${end} + 1")
string(SUBSTRING "${rest}" 0 ${end} program)
file(WRITE "${WORK_DIR}/doc_example.cpp" "${program}")

step("${CMAKE_COMMAND}" --install "${BUILD_DIR}" --component Development
     --prefix "${WORK_DIR}/prefix")
step("${CMAKE_COMMAND}" -S "${SOURCE_DIR}" -B "${WORK_DIR}/build" -G "${GENERATOR}"
     -DCMAKE_BUILD_TYPE=Release "-DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix"
     "-DDOC_EXAMPLE=${WORK_DIR}/doc_example.cpp")
step("${CMAKE_COMMAND}" --build "${WORK_DIR}/build")
step("${WORK_DIR}/build/consumer")
step("${WORK_DIR}/build/doc_example")
if(NOT step_output MATCHES "derivative image sum")
  message(FATAL_ERROR "doc_example printed: ${step_output}")
endif()
