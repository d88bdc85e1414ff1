# The OpenGL image of a cut against the CPU rasteriser's image of the same cut: runs
# `GL_VIEWER ARGS --headless -o OUT_gl.png --cpu OUT_cpu.png --json` and fails when
#  - the PSNR over the pixels either image covers is below MIN_PSNR (dB),
#  - more than MAX_HOLES_PPM of the CPU image's covered pixels are background in the GL image,
#  - the GL image covers more than MAX_EXTRA_PPM (of the CPU's count) pixels the CPU does not.
# The two rasterisers take pixel centres by the same rules, but not in the same arithmetic
# (llvmpipe's fixed-point edges and float interpolation against the CPU's double edge functions
# and conic), so pixels whose centre lies on an ellipse or triangle edge, or whose two front-most
# surfaces are within rounding of each other, may differ; docs/gl_viewer.md gives the measured
# numbers these bounds leave a margin above.
# With SAME_AS_PBRLOD_RENDER=ON (ARGS then hold no --method), also `PBRLOD render ARGS` must give
# the same CPU image: --view, --tolerance and FILE mean the same to both tools.
execute_process(COMMAND ${GL_VIEWER} ${ARGS} --headless -o ${OUT}_gl.png --cpu ${OUT}_cpu.png --json
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "gl_viewer failed (${rc}): ${err}")
endif()
message(STATUS "${out}")
string(JSON psnr GET "${out}" vs_cpu psnr)
string(JSON ssim GET "${out}" vs_cpu ssim)
string(JSON holes GET "${out}" vs_cpu holes)
string(JSON extra GET "${out}" vs_cpu extra)
string(JSON covered GET "${out}" vs_cpu cpu_covered)
if(covered LESS 1000)
  message(FATAL_ERROR "the CPU image covers only ${covered} pixels: not a useful comparison")
endif()
if(psnr STREQUAL "" OR psnr STREQUAL "null")  # identical images: +inf (JSON null)
  set(psnr 1000)
endif()
math(EXPR holes_ppm "${holes} * 1000000 / ${covered}")
math(EXPR extra_ppm "${extra} * 1000000 / ${covered}")
message(STATUS "GL vs CPU: PSNR ${psnr} dB (min ${MIN_PSNR}), SSIM ${ssim}, holes ${holes} "
               "(${holes_ppm} ppm, max ${MAX_HOLES_PPM}), extra ${extra} (${extra_ppm} ppm, max "
               "${MAX_EXTRA_PPM}) of ${covered} pixels")
if(psnr LESS MIN_PSNR)
  message(FATAL_ERROR "PSNR ${psnr} dB < ${MIN_PSNR} dB")
endif()
if(holes_ppm GREATER MAX_HOLES_PPM)
  message(FATAL_ERROR "${holes_ppm} ppm of the CPU's pixels are uncovered in the GL image")
endif()
if(extra_ppm GREATER MAX_EXTRA_PPM)
  message(FATAL_ERROR "the GL image covers ${extra_ppm} ppm extra pixels")
endif()
if(SAME_AS_PBRLOD_RENDER)
  execute_process(COMMAND ${PBRLOD} render ${ARGS} -o ${OUT}_pbrlod.png RESULT_VARIABLE rc
                  ERROR_VARIABLE err OUTPUT_QUIET)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "pbrlod render failed (${rc}): ${err}")
  endif()
  execute_process(COMMAND ${PBRLOD} compare ${OUT}_cpu.png ${OUT}_pbrlod.png --json
                  RESULT_VARIABLE rc OUTPUT_VARIABLE cmp ERROR_VARIABLE err)
  string(JSON rmse GET "${cmp}" rmse)
  string(JSON h GET "${cmp}" holes)
  if(NOT rc EQUAL 0 OR NOT rmse EQUAL 0 OR NOT h EQUAL 0)
    message(FATAL_ERROR "pbrlod render ${ARGS} draws another frame than gl_viewer's CPU image: ${cmp} ${err}")
  endif()
endif()
