# SPDX-License-Identifier: MIT
# translume_embed_shaders(OUTPUT_CC FOLDER VAR HEADER FILES...): a custom command that writes
# OUTPUT_CC embedding FOLDER/shaders/FILES as translume::gl::VAR (see EmbedShaders.cmake).
function(translume_embed_shaders out_cc folder var header)
  set(paths "")
  foreach(f ${ARGN})
    list(APPEND paths ${CMAKE_CURRENT_SOURCE_DIR}/shaders/${f})
  endforeach()
  add_custom_command(OUTPUT ${out_cc}
    COMMAND ${CMAKE_COMMAND} -DOUT=${out_cc} -DSOURCE_DIR=${CMAKE_CURRENT_SOURCE_DIR}/shaders
            "-DFILES=${ARGN}" -DPREFIX=${folder}/shaders/ -DVAR=${var} -DHEADER=${header}
            -P ${PROJECT_SOURCE_DIR}/cmake/EmbedShaders.cmake
    DEPENDS ${paths} ${PROJECT_SOURCE_DIR}/cmake/EmbedShaders.cmake
    COMMENT "Embedding ${folder} compute shaders" VERBATIM)
endfunction()
