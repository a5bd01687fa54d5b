#!/usr/bin/env bash
# The long property-test profile (200 examples per property, tests/tolerance/test_properties.py),
# logged with its command, date, load, examples run, result and wall time.
#   experiments/robustness/property_long.sh [python]   ->   experiments/robustness/property_long.log
# Environment: LOG (another log file), EXTRA (more pytest arguments, e.g. with
# JAXGRASP_PROPERTY_RANDOM=1: --hypothesis-seed=1 for other, reproducible examples).
set -u
cd "$(dirname "$0")/../.."
PY="${1:-python}"
LOG="${LOG:-experiments/robustness/property_long.log}"
EXTRA="${EXTRA:-}"
CMD="JAXGRASP_PROPERTY_PROFILE=long $PY -m pytest -q -p no:cacheprovider tests/tolerance/test_properties.py -k 'rotation_reflection or zero_mass_scaling' --hypothesis-show-statistics --durations=5 $EXTRA"
{
  echo "# long property profile"
  echo "command: $CMD"
  echo "env: JAXGRASP_PROPERTY_RANDOM=${JAXGRASP_PROPERTY_RANDOM:-}"
  echo "date: $(date -Is)"
  echo "commit: $(git rev-parse --short HEAD) $(git diff --quiet -- tests jaxgrasp || echo '(with uncommitted changes)')"
  echo "host: $(nproc) cores; load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
} > "$LOG"
start=$(date +%s)
JAXGRASP_PROPERTY_PROFILE=long "$PY" -m pytest -q -p no:cacheprovider tests/tolerance/test_properties.py \
  -k 'rotation_reflection or zero_mass_scaling' --hypothesis-show-statistics --durations=5 $EXTRA >> "$LOG" 2>&1
rc=$?
end=$(date +%s)
{
  echo "load average at end: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "exit status: $rc ($([ $rc -eq 0 ] && echo PASS || echo FAIL))"
  echo "wall time: $((end - start)) s"
} >> "$LOG"
exit $rc
