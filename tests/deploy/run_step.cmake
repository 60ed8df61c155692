# run(WHAT COMMAND...): one step of a deploy test's script. Fails the test naming WHAT, with the
# command's output, unless it exits 0; otherwise prints it and leaves it in `out`.
function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}\n${err}")
  endif()
  message(STATUS "${what}: ${out}")
  set(out "${out}" PARENT_SCOPE)
endfunction()
