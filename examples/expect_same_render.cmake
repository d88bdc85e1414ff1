# Two hierarchies draw the same image: renders A and B through PBRLOD with the same --view,
# --size and --tolerance and fails unless `compare` finds no pixel different (RMSE 0) and the
# image is not empty. Used for a chunked folder against the in-memory build of the same input.
# With MIN_PSNR set, images that differ pass when compare's PSNR is at least that (a chunked
# build whose estimation differs from the in-memory one by design; the caller says why).
foreach(which A B)
  execute_process(COMMAND ${PBRLOD} render ${${which}} --view ${VIEW} --size 256x256
                          --tolerance ${TOLERANCE} -o ${OUT}_${which}.png --json
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "render ${${which}} failed (${rc}): ${err}")
  endif()
endforeach()
execute_process(COMMAND ${PBRLOD} compare ${OUT}_A.png ${OUT}_B.png --json
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "compare failed (${rc}): ${err}")
endif()
string(JSON rmse GET "${out}" rmse)
string(JSON covered GET "${out}" reference_covered)
message(STATUS "${A} vs ${B} at ${VIEW}, tolerance ${TOLERANCE}: ${out}")
if(covered EQUAL 0)
  message(FATAL_ERROR "nothing drawn: ${out}")
endif()
if(NOT rmse EQUAL 0)
  if(DEFINED MIN_PSNR)
    string(JSON psnr GET "${out}" psnr)
    if(psnr LESS MIN_PSNR)
      message(FATAL_ERROR "the images differ by more than ${MIN_PSNR} dB allows: ${out}")
    endif()
  else()
    message(FATAL_ERROR "the images differ: ${out}")
  endif()
endif()
