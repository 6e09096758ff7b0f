#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Builds a self-contained GPU benchmark folder: the benchmark binaries (no file IO libraries),
# the shared libraries they need beyond glibc, and the GLVND EGL loader. It runs on a machine
# that has only an NVIDIA driver (docs/gpu.md):
#
#   bash tools/gpu_bundle.sh [BUILD_DIR [OUT_DIR [TARGET...]]]
#       default: build, gpu-bundle, translume-gpubench translume-renderbench
#   gpu-bundle/run.sh gl-info                          # the first TARGET
#   gpu-bundle/run.sh bench forward --backend gl
#   gpu-bundle/run.sh bench recovery --backend gl ...
#   gpu-bundle/run.sh translume-renderbench --shapes bunny ...   # another bundled TARGET
#   bash tools/gpu_session.sh                          # all of the GPU session's measurements
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${1:-$root/build}
out=${2:-$root/gpu-bundle}
shift $(( $# < 2 ? $# : 2 ))
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(translume-gpubench translume-renderbench)
cmake --build "$build" --target "${targets[@]}"
rm -rf "$out"
mkdir -p "$out/lib"
for target in "${targets[@]}"; do
  cp "$build/tools/$target" "$out/"
  # Everything the binary links except the C runtime, which every Linux has.
  for lib in $(ldd "$out/$target" | awk '/=>/ {print $3}'); do
    case "$(basename "$lib")" in
      libc.so*|libm.so*|ld-linux*|libpthread.so*|libdl.so*|librt.so*) ;;
      *) [ -e "$out/lib/$(basename "$lib")" ] || cp -L "$lib" "$out/lib/" ;;
    esac
  done
done
# run.sh's default binary: the first target.
echo "${targets[0]}" > "$out/target"
# What was bundled, for the figures' provenance (tools/gpu_session.sh prints it).
echo "commit $(git -C "$root" describe --always --dirty 2>/dev/null || echo unknown)," \
  "built $(date -u '+%Y-%m-%d %H:%M UTC') on $(uname -n): ${targets[*]}" > "$out/version"
# The GLVND EGL loader, dlopen()ed at run time; the vendor library comes from the driver.
arch_lib=/usr/lib/$(gcc -print-multiarch)
for lib in libEGL.so.1 libGLdispatch.so.0; do
  [ -e "$arch_lib/$lib" ] || { echo "gpu_bundle.sh: $arch_lib/$lib missing (apt-get install libegl1)" >&2; exit 1; }
  cp -L "$arch_lib/$lib" "$out/lib/"
done
cat > "$out/run.sh" <<'RUN'
#!/usr/bin/env bash
# Runs a bundled binary with the bundled libraries: `run.sh BINARY ARGS` when the first argument
# names one in this folder, else the default one (the file `target`). Finds the NVIDIA EGL
# vendor library in the usual driver folders when the system's GLVND configuration does not
# list it.
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
export LD_LIBRARY_PATH="$here/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
for d in /usr/local/nvidia/lib64 /usr/local/nvidia/lib /usr/lib/x86_64-linux-gnu/nvidia; do
  [ -d "$d" ] && LD_LIBRARY_PATH="$LD_LIBRARY_PATH:$d"
done
if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ] && ! ls /usr/share/glvnd/egl_vendor.d/*nvidia* >/dev/null 2>&1; then
  for f in /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json /etc/glvnd/egl_vendor.d/10_nvidia.json; do
    [ -e "$f" ] && export __EGL_VENDOR_LIBRARY_FILENAMES="$f" && break
  done
fi
bin=$(cat "$here/target")
case "${1:-}" in
  translume-*) [ -x "$here/$1" ] && { bin=$1; shift; } ;;
esac
exec "$here/$bin" "$@"
RUN
chmod +x "$out/run.sh"
du -sh "$out"
