#!/usr/bin/env bash
# One lease of a GPU machine (issue 41, item 3), each stage time-boxed to one deadline so
# that the logs of the earlier ones come back whatever happens later:
#   1. the work queue's width (experiments/gpu/gpu_slots.py): the mixed 1000-grasp set at the
#      default 128 slots and at wider ones, chunks of 1024 to 16384;
#   2. where the GPU's time goes in a steady evaluate_batch of the set
#      (experiments/gpu/gpu_profile.py), with the same machine's CPU cores beside it;
#   3. the same with XLA's command buffers (CUDA graphs) for loops and conditionals (a
#      program of its own: jaxgrasp's store keys executables by XLA_FLAGS since 2026-11-28);
#   4. test_degenerate, which had not finished on either earlier lease;
#   5. the whole suite in the time left.
# Runs in the repository root of a machine whose Python already has JAX's CUDA build,
# NumPy, SciPy, matplotlib and pytest, and nothing else: jaxgrasp's other dependencies
# come as wheels in .whl/ (carried), since such a machine reaches no package index, and
# CasADi (for the Ipopt comparisons) as .whl/casadi-stripped.tar.xz, its Python files and
# the libraries Ipopt needs (the wheel is 93 MB, over what a lease carries). Writes its
# logs under $OUT (default ./gpu-out).
#
#     bash experiments/gpu/gpu_run.sh [SECONDS]    # the whole run ends by then (default 560)
set -uo pipefail
OUT=${OUT:-gpu-out}
mkdir -p "$OUT"
DEADLINE=${1:-560}
# MUJOCO_GL stays unset: =egl needs the EGL loader, which such a machine lacks (every
# MuJoCo test module failed to import there, 2026-11-26). Several pytest workers share the
# GPU, so none takes three quarters of its memory up front.
export PYTHONUNBUFFERED=1 JAXGRASP_CACHE_DIR=/tmp/jaxgrasp-cache XLA_PYTHON_CLIENT_PREALLOCATE=false
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
    [ -f .whl/casadi-stripped.tar.xz ] && tar xJf .whl/casadi-stripped.tar.xz -C /tmp/site
    export PYTHONPATH=/tmp/site:$PWD
fi
# The console script and the package metadata (test_packaging reads the version), without
# an index; where the local setuptools cannot build it, a plain entry script stands in.
python3 -m pip install -q --no-index --no-deps --no-build-isolation -e . >"$OUT/env.txt" 2>&1 || {
    mkdir -p /tmp/bin && printf '#!/usr/bin/env python3\nimport sys\nfrom jaxgrasp.cli import main\nsys.exit(main())\n' >/tmp/bin/jaxgrasp
    chmod +x /tmp/bin/jaxgrasp && export PATH=/tmp/bin:$PATH; }
{ date -u; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv; nproc; uptime
  python3 -c "import sys, jax; from importlib.metadata import version as v; print(sys.version); print(*(p + ' ' + v(p) for p in ('jax', 'jaxlib', 'jaxopt', 'numpy', 'scipy', 'trimesh', 'mujoco'))); print(jax.devices())"
  python3 -c "import casadi; print('casadi', casadi.__version__)"
  git log -1 --format='commit %h %s' 2>/dev/null; } >>"$OUT/env.txt" 2>&1
cat "$OUT/env.txt"

# stage NAME SECONDS COMMAND...: runs COMMAND for at most SECONDS, never past the deadline.
stage() {
    local name=$1 limit=$2 left=$((DEADLINE - SECONDS))
    shift 2
    if [ "$left" -lt 30 ]; then echo "== $name: skipped, $left s left"; return; fi
    [ "$limit" -gt "$left" ] && limit=$left
    echo "== $name (at most $limit s)"
    timeout "$limit" "$@" >"$OUT/$name.log" 2>&1
    echo "exit $? (124: stopped at $limit s)" >>"$OUT/$name.log"
    tail -n 40 "$OUT/$name.log"
}
PYTEST=(python3 -m pytest -v -p no:cacheprovider --timeout 240 -o addopts="-ra --strict-markers --dist loadfile")

stage slots 240 python3 experiments/gpu/gpu_slots.py --json "$OUT/slots.json"
stage profile 150 python3 experiments/gpu/gpu_profile.py --cpu --json "$OUT/profile.json"
stage profile_graphs 100 env XLA_FLAGS="--xla_gpu_enable_command_buffer=+WHILE,+CONDITIONAL --xla_gpu_graph_min_graph_size=1" \
    python3 experiments/gpu/gpu_profile.py
stage tests_degenerate 150 "${PYTEST[@]}" -n 4 tests/tolerance/test_degenerate.py
stage suite 600 "${PYTEST[@]}" -n 14 tests
for f in "$OUT"/tests_degenerate.log "$OUT"/suite.log; do
    [ -f "$f" ] || continue
    echo "$f: PASSED $(grep -c ' PASSED' "$f") SKIPPED $(grep -c ' SKIPPED' "$f") FAILED $(grep -c ' FAILED' "$f") ERROR $(grep -c ' ERROR' "$f")"
    grep -E " (FAILED|ERROR) " "$f" | sed 's/^\[gw[0-9]*\] \[ *[0-9]*%\] //' | sort -u | head -30
done
