# SPDX-License-Identifier: MIT
# cmake -DOUT=file.cc -DSOURCE_DIR=dir -DFILES="a.comp;b.glsl" [-DPREFIX=solver/shaders/]
#       [-DVAR=kEmbeddedShaders] [-DHEADER=solver/gl_shaders.h] -P EmbedShaders.cmake
# Writes a C++ file defining translume::gl::VAR (and VAR's count, kNum<VAR without the k>):
# {PREFIX + name, source} per file, so the shaders ship inside the binary and compile errors can
# name the file. Each library embeds its own folder under its own variable name.
if(NOT DEFINED PREFIX)
  set(PREFIX "solver/shaders/")
endif()
if(NOT DEFINED VAR)
  set(VAR "kEmbeddedShaders")
endif()
if(NOT DEFINED HEADER)
  set(HEADER "solver/gl_shaders.h")
endif()
string(REGEX REPLACE "^k" "" count_name "${VAR}")
set(content "// Generated from ${SOURCE_DIR} by cmake/EmbedShaders.cmake. Do not edit.\n")
string(APPEND content "#include \"${HEADER}\"\nnamespace translume::gl {\n")
string(APPEND content "const EmbeddedShader ${VAR}[] = {\n")
foreach(f ${FILES})
  file(READ "${SOURCE_DIR}/${f}" text)
  string(APPEND content "  {\"${PREFIX}${f}\", R\"TLSHADER(${text})TLSHADER\"},\n")
endforeach()
string(APPEND content "};\nconst int kNum${count_name} = sizeof(${VAR}) / sizeof(${VAR}[0]);\n}\n")
file(WRITE "${OUT}.new" "${content}")
execute_process(COMMAND ${CMAKE_COMMAND} -E copy_if_different "${OUT}.new" "${OUT}")
file(REMOVE "${OUT}.new")
