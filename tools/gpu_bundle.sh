#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Builds a self-contained GPU benchmark folder: translume-gpubench (the solver core, no file IO),
# the few shared libraries it needs beyond glibc and libstdc++, and the GLVND EGL loader. It runs
# on a machine that has only an NVIDIA driver (docs/gpu.md):
#
#   bash tools/gpu_bundle.sh [BUILD_DIR] [OUT_DIR] [TARGET]  # default: build, gpu-bundle,
#                                                            # translume-gpubench
#   gpu-bundle/run.sh gl-info
#   gpu-bundle/run.sh bench forward --backend gl
# TARGET=translume-renderbench bundles the renderer's frame-rate benchmark instead.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${1:-$root/build}
out=${2:-$root/gpu-bundle}
target=${3:-translume-gpubench}
cmake --build "$build" --target "$target"
rm -rf "$out"
mkdir -p "$out/lib"
cp "$build/tools/$target" "$out/"
echo "$target" > "$out/target"
# Everything the binary links except the C runtime, which every Linux has.
for lib in $(ldd "$out/$target" | awk '/=>/ {print $3}'); do
  case "$(basename "$lib")" in
    libc.so*|libm.so*|ld-linux*|libpthread.so*|libdl.so*|librt.so*) ;;
    *) cp -L "$lib" "$out/lib/" ;;
  esac
done
# The GLVND EGL loader, dlopen()ed at run time; the vendor library comes from the driver.
arch_lib=/usr/lib/$(gcc -print-multiarch)
for lib in libEGL.so.1 libGLdispatch.so.0; do
  [ -e "$arch_lib/$lib" ] || { echo "gpu_bundle.sh: $arch_lib/$lib missing (apt-get install libegl1)" >&2; exit 1; }
  cp -L "$arch_lib/$lib" "$out/lib/"
done
cat > "$out/run.sh" <<'RUN'
#!/usr/bin/env bash
# Runs translume-gpubench with the bundled libraries; finds the NVIDIA EGL vendor library in
# the usual driver folders when the system's GLVND configuration does not list it.
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
exec "$here/$(cat "$here/target")" "$@"
RUN
chmod +x "$out/run.sh"
du -sh "$out"
