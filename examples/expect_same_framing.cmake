# A hierarchy frames like its input: renders INPUT and LOD with the same --view/--size through
# PBRLOD, compares them, and fails when more than MAX_MISSING_PPM (parts per million) of the
# input's pixels are not covered by the hierarchy (compare's holes / reference_covered) or when
# the hierarchy covers pixels the input does not, more than MAX_EXTRA_PPM of the input's count.
# A camera placed around other bounds than the input's shows the model at another size, so
# both fractions grow with the mismatch.
foreach(image input lod)
  set(_in ${INPUT})
  if(image STREQUAL "lod")
    set(_in ${LOD})
  endif()
  execute_process(COMMAND ${PBRLOD} render ${_in} --view ${VIEW} --size ${SIZE} --tolerance 1
                          -o ${OUT}_${image}.png --json
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "render ${_in} failed (${rc}): ${err}")
  endif()
endforeach()
execute_process(COMMAND ${PBRLOD} compare ${OUT}_input.png ${OUT}_lod.png --json
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "compare failed (${rc}): ${err}")
endif()
string(JSON holes GET "${out}" holes)
string(JSON either GET "${out}" covered_either)
string(JSON reference GET "${out}" reference_covered)
if(reference EQUAL 0)
  message(FATAL_ERROR "the input covers no pixel: ${out}")
endif()
# CMake's math() is integer-only: fractions in parts per million.
math(EXPR missing_ppm "${holes} * 1000000 / ${reference}")
math(EXPR extra_px "${either} - ${reference}")
math(EXPR extra_ppm "${extra_px} * 1000000 / ${reference}")
message(STATUS "framing: ${holes} of ${reference} input pixels missing (${missing_ppm} ppm), "
               "${extra_px} extra (${extra_ppm} ppm)")
if(missing_ppm GREATER MAX_MISSING_PPM)
  message(FATAL_ERROR "the hierarchy leaves ${missing_ppm} ppm of the input's pixels uncovered "
                      "(allowed ${MAX_MISSING_PPM}): framed differently?")
endif()
if(extra_ppm GREATER MAX_EXTRA_PPM)
  message(FATAL_ERROR "the hierarchy covers ${extra_ppm} ppm extra pixels "
                      "(allowed ${MAX_EXTRA_PPM}): framed differently?")
endif()
