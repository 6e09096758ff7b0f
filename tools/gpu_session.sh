#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The prepared GPU session (docs/gpu.md, "GPU sessions"): every GPU measurement the issues
# still lack, in one command, from the bundle that tools/gpu_bundle.sh writes (default
# gpu-bundle/: translume-gpubench and translume-renderbench). Run from the repository root on
# the GPU machine:
#
#   bash tools/gpu_session.sh [--quick] [--long-recoveries] [--bundle DIR] [--budget SECONDS]
#
# Steps, in this order, each under its own `timeout` (one hang cannot eat the session) and all
# within --budget seconds (default 400, 560 with --long-recoveries; a step gets at most what is
# left, a step with under 20 s left is skipped): nvidia-smi, gl-info, bench forward --backend gl
# on Wax I, Marble and 129^3 with a batch of 16 (the cpu solver as the peer), the same on Wax I
# and Marble with the line smoother by cyclic reduction (TRANSLUME_GL_LINE_PCR=1) and with the
# buffer clears and copies by shader (TRANSLUME_GL_SHADER_CLEAR=1), a profile
# of Wax I's solves per kernel and level on GPU timestamps (default and cyclic reduction), the
# renderbench on the 253-cube bunny (17^3 nodes per cube, 3 levels, no frame coherence, the
# default 30/15/15 Chebyshev steps; then with --stencil 6), a profile of its frames per
# shader and level on GPU timestamps and its frame's fixed cost (1/1/1 steps),
# the RGB recoveries with 16 conditions on the Wax I grid (a whole default one, capped at
# 100 s; then capped alike with --joint-optimizer, one optimiser over all channels as until
# 2026-12-04, and without; then 15 s with a GPU-timestamp profile per kernel and grid) and the
# Marble grid on the gl backend, the capped ones
# time-capped at 40 s and 30 s (their seconds per iteration give the time of the bench's full
# 300 iterations; run with --level-search 0, whose trials the cap would not stop), the level
# search on Wax I (the homogeneous fit, the trials and one iteration: what a default recovery
# adds to its 300 iterations), the bunny's variants (18/9/9 and 20/10/10 Chebyshev steps, the
# 2026-11-30 runs' 60/30/30 Jacobi steps, the adaptive depth), and last the Wax I and Marble batches (no peer)
# under other shader tunings side by side: a glFlush every 16 dispatches, that with cyclic
# reduction, the tail from 1024 nodes and shader clears all at once, line smoother blocks of 1
# node against the default 4, a coarse tail from 8192 nodes against 4096, cyclic reduction with
# tails from 1024 and 8192 nodes; then the renderbench again.
#
# --long-recoveries: no tuning steps; Wax I runs a whole default recovery, its absorption level
# search and 300 iterations (cap 120 s, ~100 s on the H200 on 2026-12-04), Marble 300 s (~170
# of its 300 iterations: 300 take ~520 s, more than one device call holds), and the cpu
# backend's recovery on Wax I (20 s) runs as their peer.
#
# Output: "$OUT" (the device tool's output folder; default ./gpu-session): session.log (every
# step's full output, in order), summary.md (the figures for docs/benchmarks.md, also printed
# at the end): two files, well within what the device tool brings back (8).
#
# --quick runs every step (the cpu peer too) on tiny sizes: a dry run here, on Mesa llvmpipe,
# about a minute (the unrolled line blocks compile slowly there).
set -uo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bundle=$root/gpu-bundle
quick=0
long=0
budget=
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --long-recoveries) long=1 ;;
    --bundle) bundle=$2; shift ;;
    --budget) budget=$2; shift ;;
    -h|--help) sed -n '3,/^[^#]/p' "${BASH_SOURCE[0]}" | sed '$d' | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "gpu_session.sh: unknown argument '$1' (--quick, --long-recoveries, --bundle DIR, --budget SECONDS)" >&2; exit 2 ;;
  esac
  shift
done
[ -n "$budget" ] || budget=$([ $long = 1 ] && echo 560 || echo 400)
out=${OUT:-$root/gpu-session}
mkdir -p "$out"
log=$out/session.log
summary=$out/summary.md
: >"$log"
: >"$summary"
run=$bundle/run.sh
if [ ! -x "$run" ] || [ ! -x "$bundle/translume-gpubench" ]; then
  echo "gpu_session.sh: no translume-gpubench bundle at $bundle (build it: bash tools/gpu_bundle.sh)" >&2
  exit 1
fi
# The renderbench: in the same bundle (default), else a separate render-bundle/ beside it.
render=("$run" translume-renderbench)
if [ ! -x "$bundle/translume-renderbench" ]; then
  if [ -x "$root/render-bundle/translume-renderbench" ]; then
    render=("$root/render-bundle/run.sh")
  else
    render=()
  fi
fi

start=$(date +%s)
failed=0
say() { echo "$*" | tee -a "$log" >&2; }

# step NAME LIMIT_S COMMAND...: runs COMMAND under timeout (LIMIT_S, or what is left of the
# budget), stdout (the result table) and a dispatch profile's lines into the summary, stdout
# and stderr into the log.
step() {
  local name=$1 limit=$2
  shift 2
  local left=$(( budget - ($(date +%s) - start) ))
  [ "$limit" -gt $(( left - 5 )) ] && limit=$(( left - 5 ))
  if [ "$limit" -lt 20 ]; then
    say "== $name: SKIPPED (${left} s of the ${budget} s budget left)"
    printf '\n### %s\n\nskipped: the session budget ran out\n' "$name" >>"$summary"
    failed=1
    return
  fi
  say "== $name (limit ${limit} s): $*"
  local t0 rc so se
  t0=$(date +%s.%N)
  so=$(mktemp) se=$(mktemp)
  timeout -k 10 "$limit" "$@" >"$so" 2>"$se"
  rc=$?
  local secs
  secs=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  cat "$se" "$so" >>"$log"
  local status="ok"
  if [ $rc -eq 124 ] || [ $rc -eq 137 ]; then status="TIMED OUT after ${limit} s"; failed=1
  elif [ $rc -ne 0 ]; then status="FAILED (exit $rc)"; failed=1; fi
  say "== $name: $status, ${secs} s"
  {
    printf '\n### %s (%s, %s s)\n\n`%s`\n\n' "$name" "$status" "$secs" "$*"
    cat "$so"
    # TRANSLUME_GL_PROFILE's table (stderr, at exit) belongs to the results.
    grep '^gl profile' "$se" | head -n 40
    # Failed or stopped: the last lines of stderr say why.
    if [ "$status" != "ok" ]; then echo; tail -n 5 "$se" | sed 's/^/    /'; fi
  } >>"$summary"
  rm -f "$so" "$se"
}

if [ $quick = 1 ]; then
  grids=33x25x17; pack_grids=$grids; profile_grid=$grids; repeats=1; batch=4  # (above the coarse tail)
  render_args=(--shapes bunny --resolutions 3,4 --frames 2 --image 64 --skip-coherent --no-error)
  render_profile_args=(--shapes bunny --resolutions 4 --frames 2 --image 64 --skip-coherent --no-error)
  render_variant_args=("${render_profile_args[@]}")
  wax=(--grid 12x10x5 --max-iterations 3 --max-seconds 60 --level-search 0)
  wax_first=(--grid 12x10x5 --max-iterations 3 --max-seconds 60); first_limit=30
  marble=(--grid 16x16x4 --max-iterations 3 --max-seconds 60 --level-search 0)
  peer=(--grid 12x10x5 --max-iterations 3 --max-seconds 30 --level-search 0)
  profile_recovery=(--grid 24x18x8 --max-iterations 3 --max-seconds 30 --level-search 0)
  level=(--grid 12x10x5 --max-iterations 1 --level-search 10)
  limits=(30 30 30)
  tunings=1
else
  grids=130x53x37,256x256x20,129x129x129; pack_grids=130x53x37,256x256x20; profile_grid=130x53x37
  repeats=7; batch=16
  # (17 only: 16 nodes per edge make one level, which the 3-level schedule's last entry, 15
  # steps from zero, does not converge.)
  render_args=(--shapes bunny --resolutions 17 --frames 20 --skip-coherent --no-error)
  render_profile_args=(--shapes bunny --resolutions 17 --frames 10 --skip-coherent --no-error)
  render_variant_args=("${render_profile_args[@]}")
  peer=(--grid 130x53x37 --max-iterations 300 --max-seconds 20 --level-search 0)
  profile_recovery=(--grid 130x53x37 --max-iterations 300 --max-seconds 15 --level-search 0)
  level=(--grid 130x53x37 --max-iterations 1 --level-search 10)
  if [ $long = 1 ]; then
    wax=(--grid 130x53x37 --max-iterations 300 --max-seconds 120)
    wax_first=("${wax[@]}"); first_limit=150
    marble=(--grid 256x256x20 --max-iterations 300 --max-seconds 300 --level-search 0)
    limits=(150 345 45)
    tunings=0
  else
    wax=(--grid 130x53x37 --max-iterations 300 --max-seconds 40 --level-search 0)
    # The first Wax I recovery whole (level search, validation; ~45-60 s expected with one
    # optimiser per channel): issue 5's figure itself rather than an extrapolation.
    wax_first=(--grid 130x53x37 --max-iterations 300 --max-seconds 100); first_limit=130
    marble=(--grid 256x256x20 --max-iterations 300 --max-seconds 30 --level-search 0)
    limits=(70 75 0)
    tunings=1
  fi
fi
# The data simulated on the GPU too (Wax I ~3 s, Marble ~18 s on the H200; on the host's 16
# cores the cpu took 23 s and 133 s), the held-out evaluation on the recovery's backend.
one_case=(--setups back --noises 0 --no-comparison --data-backend gl)
batches=(bench forward --backend gl --grids "$pack_grids" --repeats "$repeats" --batch "$batch" --no-peers)

{
  echo "# GPU session $(date -u '+%Y-%m-%d %H:%M UTC')$([ $quick = 1 ] && echo ' (--quick)')"
  echo
  echo "bundle: $(cat "$bundle/version" 2>/dev/null || echo 'version unknown')"
  echo "host: $(nproc) cores, $(uname -m), $(awk '/MemTotal/ { printf "%.0f GiB", $2 / 1048576 }' /proc/meminfo)"
} >>"$summary"

if command -v nvidia-smi >/dev/null; then
  step "nvidia-smi" 30 nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm,clocks.max.mem --format=csv
else
  say "== nvidia-smi: not found (no NVIDIA driver here)"
  printf '\n### nvidia-smi\n\nnot found\n' >>"$summary"
fi
step "gl-info" 60 "$run" gl-info
step "bench forward (gl, batch ${batch})" 90 \
  "$run" bench forward --backend gl --grids "$grids" --repeats "$repeats" --batch "$batch"
# The line smoother by cyclic reduction (off by default until measured here), right after the
# default for a side-by-side comparison: single solves and batches on Wax I and Marble.
step "bench forward (gl, batch ${batch}, TRANSLUME_GL_LINE_PCR=1)" 60 \
  env TRANSLUME_GL_LINE_PCR=1 "$run" "${batches[@]}"
# The solver's buffer clears (each coarse level's x in every V-cycle) and CG's restart copy as
# dispatches of copy.comp (Tuning::shader_clear, off by default): the renderer's copies and
# clears cost ~1.2 ms a frame on 2026-12-04 (later).
step "bench forward (gl, batch ${batch}, TRANSLUME_GL_SHADER_CLEAR=1)" 60 \
  env TRANSLUME_GL_SHADER_CLEAR=1 "$run" "${batches[@]}"
# Where a Wax I solve's time goes, per kernel and level, timed on the GPU without finishes
# (TRANSLUME_GL_PROFILE=gpu2; a single solve and a batch), default and cyclic reduction.
for variant in TRANSLUME_GL_LINE_PCR=0 TRANSLUME_GL_LINE_PCR=1; do
  step "profile Wax I (TRANSLUME_GL_PROFILE=gpu2, ${variant})" 40 env TRANSLUME_GL_PROFILE=gpu2 "$variant" \
    "$run" bench forward --backend gl --grids "$profile_grid" --repeats 3 --batch "$batch" --no-peers
done
if [ ${#render[@]} -gt 0 ]; then
  step "renderbench (bunny)" 60 "${render[@]}" "${render_args[@]}"
  # The paper's six-point rows beside the default wide stencil (6 % of the bunny's rows wide).
  step "renderbench (bunny, --stencil 6)" 40 "${render[@]}" "${render_args[@]}" --stencil 6
  # Where a frame's time goes, per shader and level, timed on the GPU without finishes.
  step "renderbench profile (bunny, TRANSLUME_GL_PROFILE=gpu2)" 60 env TRANSLUME_GL_PROFILE=gpu2 \
    "${render[@]}" "${render_profile_args[@]}"
  # A frame's fixed cost: one step per level. On 2026-12-04 (later) 1.6 ms of diffusion, ~1.2
  # ms of it outside any dispatch (the fluence buffers' copies and clears, removed since).
  step "renderbench (bunny, 1,1,1: the fixed cost)" 30 "${render[@]}" "${render_variant_args[@]}" \
    --iterations 1,1,1
else
  say "== renderbench: no translume-renderbench in $bundle or render-bundle/"
  failed=1
fi
step "recovery Wax I (wax, gl)" "$first_limit" \
  "$run" bench recovery --presets wax "${one_case[@]}" --backend gl "${wax_first[@]}"
if [ $tunings = 1 ]; then
  # The host's L-BFGS took 63 % of a Wax I iteration on 2026-12-04 at rank 20, 50 % at rank 5,
  # when one optimiser ran all three channels on one thread. Since then one per channel, on
  # three threads and overlapping the GPU's evaluations: the joint optimiser and one per
  # channel side by side, capped alike. (These steps replace a recovery with
  # TRANSLUME_GL_LINE_PCR=1, 0.300 against 0.281 s an iteration, and one at rank 5.)
  step "recovery Wax I (wax, gl, --joint-optimizer)" "${limits[0]}" \
    "$run" bench recovery --presets wax "${one_case[@]}" --backend gl "${wax[@]}" --joint-optimizer
  step "recovery Wax I (wax, gl, capped as the joint one)" "${limits[0]}" \
    "$run" bench recovery --presets wax "${one_case[@]}" --backend gl "${wax[@]}"
  # The recovery's GPU time per kernel (GPU timestamps, keyed by threads too, so that the
  # recovery grid's dispatches stand apart from the data simulation's on the 2x finer grid):
  # against its seconds per iteration it tells GPU-bound from host-bound (uploads, read-backs).
  step "profile recovery Wax I (TRANSLUME_GL_PROFILE=gpu2)" 45 env TRANSLUME_GL_PROFILE=gpu2 \
    "$run" bench recovery --presets wax "${one_case[@]}" --backend gl "${profile_recovery[@]}"
fi
step "recovery Marble (marble, gl)" "${limits[1]}" \
  "$run" bench recovery --presets marble "${one_case[@]}" --backend gl "${marble[@]}"
# The absorption level search on Wax I (on by default in solve and acquire, off above): the
# homogeneous fit, the search's 3-6 trials of 10 iterations per channel and one iteration, so
# the row's time is what a default recovery adds to the 300 iterations (session.log's progress
# line splits it: "homogeneous X s, level search Y s: N trials").
step "level search Wax I (wax, gl, 1 iteration)" 60 \
  "$run" bench recovery --presets wax "${one_case[@]}" --backend gl "${level[@]}"
if [ "${limits[2]}" -gt 0 ]; then
  step "recovery Wax I (wax, cpu peer, time-capped)" "${limits[2]}" \
    "$run" bench recovery --presets wax "${one_case[@]}" --backend cpu "${peer[@]}"
fi
# The bunny's diffusion with 18,9,9 and two thirds the default Chebyshev steps, and with the paper's Jacobi
# steps as measured on 2026-11-30 (60,30,30). Their errors against the converged solution (the
# renderbench's E, a host solve that takes a minute at 17^3: --no-error here) do not depend on
# the backend; docs/benchmarks.md has them from the cpu backend. Then the adaptive scheme
# (Section 5.3): the finest level updates only its outer 4 node layers (measured on the cpu
# on 2026-12-01 with the six weights: E 5.8e-4 instead of 4.7e-4, t2 0.73-0.87x there).
if [ ${#render[@]} -gt 0 ]; then
  # Around the paper's E of 5e-3: 18,9,9 6.8e-3 on the cpu, 20,10,10 2.7e-3.
  step "renderbench (bunny, chebyshev 18,9,9)" 30 "${render[@]}" "${render_variant_args[@]}" \
    --iterations 18,9,9
  # Two thirds of the default steps: E 2.7e-3 on the cpu (2026-12-04), about half the paper's 5e-3.
  step "renderbench (bunny, chebyshev 20,10,10)" 30 "${render[@]}" "${render_variant_args[@]}" \
    --iterations 20,10,10
  step "renderbench (bunny, jacobi 60,30,30)" 30 "${render[@]}" "${render_variant_args[@]}" \
    --relaxation jacobi --iterations 60,30,30
  step "renderbench (bunny, adaptive depth -1,-1,4)" 30 "${render[@]}" "${render_variant_args[@]}" \
    --depth=-1,-1,4
fi
# The shader tunings side by side (gl_internal.h's Tuning; each an environment override).
if [ $tunings = 1 ]; then
  # (A variant may set several variables, separated by spaces.)
  # First a flush every 16 dispatches (Tuning::flush_every, off by default): whether the
  # driver held a solve's commands while the host issued them; then every option that has
  # helped Wax I's single solve at once (cyclic reduction, the tail from 1024 nodes, shader
  # clears, flushes), against its 5 ms. Line blocks of 8 and four fields per value, slower in
  # both sessions of 2026-12-04, are no longer run.
  for variant in TRANSLUME_GL_FLUSH_EVERY=16 \
                 "TRANSLUME_GL_LINE_PCR=1 TRANSLUME_GL_TAIL_NODES=1024 TRANSLUME_GL_SHADER_CLEAR=1 TRANSLUME_GL_FLUSH_EVERY=16" \
                 TRANSLUME_GL_LINE_BLOCK=1 TRANSLUME_GL_TAIL_NODES=8192 \
                 "TRANSLUME_GL_LINE_PCR=1 TRANSLUME_GL_TAIL_NODES=1024" \
                 "TRANSLUME_GL_LINE_PCR=1 TRANSLUME_GL_TAIL_NODES=8192"; do
    # shellcheck disable=SC2086  # the variant's words are the assignments
    step "bench forward (gl, batch ${batch}, ${variant})" 40 env $variant "$run" "${batches[@]}"
  done
fi
# The bunny again: its diffusion time differed 2.5x between the 2026-11-30 calls; a second
# measurement in the same call (and each run's t2 range) tells drift within a session from
# differences between machines.
if [ ${#render[@]} -gt 0 ]; then
  step "renderbench (bunny, again)" 60 "${render[@]}" "${render_args[@]}"
fi

total=$(( $(date +%s) - start ))
printf '\nsession: %d s of the %d s budget%s\n' "$total" "$budget" \
  "$([ $failed = 1 ] && echo '; SOME STEPS FAILED, TIMED OUT OR WERE SKIPPED (session.log)')" >>"$summary"
echo
cat "$summary"
exit $failed
