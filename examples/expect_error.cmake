# Runs COMMAND (a list), expects exit code EXPECT_CODE and stderr matching EXPECT_REGEX, and no
# crash or sanitizer report.
execute_process(COMMAND ${COMMAND} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc STREQUAL "${EXPECT_CODE}")
  message(FATAL_ERROR "expected exit code ${EXPECT_CODE}, got '${rc}'\nstdout: ${out}\nstderr: ${err}")
endif()
if(NOT err MATCHES "${EXPECT_REGEX}")
  message(FATAL_ERROR "stderr does not match '${EXPECT_REGEX}':\n${err}")
endif()
if(err MATCHES "Sanitizer|runtime error|unexpected error")
  message(FATAL_ERROR "not a clean error:\n${err}")
endif()
