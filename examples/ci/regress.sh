#!/usr/bin/env bash
# Your odometry against its committed baseline on a simulated suite (salo regress --method).
#
#   bash examples/ci/regress.sh            # in CI: exit 0 passed, 1 regressed (or a run failed), 2 misused
#   bash examples/ci/regress.sh --update   # once, and after an intended change: rewrite the baseline, commit it
#
# Settings (environment; the defaults are this example's):
#   SALO_METHOD     the name your baseline is kept under           (my-odometry)
#   SALO_COMMAND    your program: {sequence} or {scans}, {sensor}, {times}, {fields} in, {out} out
#   SALO_SUITE      the suite, a sweep spec                        (examples/ci/suite.yaml)
#   SALO_BASELINES  the folder of committed baselines              (examples/ci/baselines)
#   SALO_OUT        runs and the simulated sequences (cache this)  (.salo/regress)
#   SALO_FIELDS     per-point fields your method is handed         (the suite's: ring,time_s)
#   SALO_WORKERS    parallel runs                                  (2)
#   SALO            the salo command                               (salo)
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
SALO="${SALO:-salo}"
SALO_METHOD="${SALO_METHOD:-my-odometry}"
example_command="python $here/my_odometry.py {sequence} {out}"
SALO_COMMAND="${SALO_COMMAND:-$example_command}"
SALO_SUITE="${SALO_SUITE:-$here/suite.yaml}"
SALO_BASELINES="${SALO_BASELINES:-$here/baselines}"
SALO_OUT="${SALO_OUT:-.salo/regress}"

args=(regress --method "$SALO_METHOD" --odometry-command "$SALO_COMMAND" --suite "$SALO_SUITE"
      --baseline-dir "$SALO_BASELINES" --out "$SALO_OUT" --keep-sequences --workers "${SALO_WORKERS:-2}")
if [ -n "${SALO_FIELDS:-}" ]; then
  args+=(--fields "$SALO_FIELDS")
fi
if [ "${1:-}" = "--update" ]; then
  args+=(--update)
elif [ -n "${1:-}" ]; then
  echo "usage: $0 [--update]" >&2
  exit 2
fi
echo "+ $SALO ${args[*]}"
exec $SALO "${args[@]}"
