# SPDX-License-Identifier: MIT
# cmake -DOUT=file.cc -DSOURCE_DIR=dir -DFILES="a.comp;b.glsl" -P EmbedShaders.cmake
# Writes a C++ file defining translume::gl::kEmbeddedShaders: {name, source} per file, so the
# shaders ship inside the binary and compile errors can name the file.
set(content "// Generated from ${SOURCE_DIR} by cmake/EmbedShaders.cmake. Do not edit.\n")
string(APPEND content "#include \"solver/gl_shaders.h\"\nnamespace translume::gl {\n")
string(APPEND content "const EmbeddedShader kEmbeddedShaders[] = {\n")
foreach(f ${FILES})
  file(READ "${SOURCE_DIR}/${f}" text)
  string(APPEND content "  {\"solver/shaders/${f}\", R\"TLSHADER(${text})TLSHADER\"},\n")
endforeach()
string(APPEND content "};\nconst int kNumEmbeddedShaders = sizeof(kEmbeddedShaders) / sizeof(kEmbeddedShaders[0]);\n}\n")
file(WRITE "${OUT}.new" "${content}")
execute_process(COMMAND ${CMAKE_COMMAND} -E copy_if_different "${OUT}.new" "${OUT}")
file(REMOVE "${OUT}.new")
