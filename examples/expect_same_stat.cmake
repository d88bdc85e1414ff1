# A statistic of a hierarchy survives its file: builds INPUT with METHOD into LOD through PBRLOD
# (`build --json`), reads LOD back (`stats --json`) and fails unless KEY is a number, the same in
# both, and at least MIN.
execute_process(COMMAND ${PBRLOD} build --method ${METHOD} ${INPUT} -o ${LOD} --json
                RESULT_VARIABLE rc OUTPUT_VARIABLE built ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "build failed (${rc}): ${err}")
endif()
execute_process(COMMAND ${PBRLOD} stats ${LOD} --json
                RESULT_VARIABLE rc OUTPUT_VARIABLE loaded ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "stats failed (${rc}): ${err}")
endif()
string(JSON at_build GET "${built}" ${KEY})
string(JSON at_load GET "${loaded}" ${KEY})
message(STATUS "${KEY}: build ${at_build}, stats of the file ${at_load}")
if(NOT at_build MATCHES "^[0-9]+$" OR NOT at_load MATCHES "^[0-9]+$")
  message(FATAL_ERROR "${KEY} is not a count: build '${at_build}', stats '${at_load}'")
endif()
if(NOT at_build EQUAL at_load)
  message(FATAL_ERROR "${KEY}: build reports ${at_build}, stats of its file ${at_load}")
endif()
if(at_build LESS MIN)
  message(FATAL_ERROR "${KEY} = ${at_build}, expected at least ${MIN}")
endif()
