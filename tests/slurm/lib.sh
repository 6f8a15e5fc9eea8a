# shellcheck shell=bash
# Sourced by the Slurm integration tests (generate_test.sh, evaluate_test.sh): the skip checks,
# step/die, and a real single-node Slurm (scripts/slurm_local.sh: munged, slurmctld, slurmd on
# loopback, all state in the test's temp dir) that is stopped on every exit path.

# slurm_test_args HANDDB_EXE SOURCE_DIR: sets HANDDB and SRC (absolute) and PY, for the test.
# shellcheck disable=SC2034
slurm_test_args() {
  local usage
  usage="usage: $(basename "$0") HANDDB_EXE SOURCE_DIR"
  HANDDB="$(realpath "${1:?$usage}")"
  SRC="$(realpath "${2:?$usage}")"
  PY=/usr/bin/python3
}

t_start=$(date +%s)
step() { echo "--- [$(( $(date +%s) - t_start ))s] $*"; }
die() { echo "FAIL: $*" >&2; exit 1; }

# Exits 77 (skipped) unless Slurm, Blender and root (slurmd launches jobs as their owner) are here.
slurm_test_require() {
  local tool
  for tool in slurmctld slurmd munged sbatch scontrol; do
    command -v "$tool" >/dev/null || { echo "SKIP: $tool not installed (scripts/deps.sh)"; exit 77; }
  done
  command -v "${HANDDB_BLENDER:-blender}" >/dev/null || { echo "SKIP: blender not installed"; exit 77; }
  [ "$(id -u)" -eq 0 ] || { echo "SKIP: a local slurmd needs root"; exit 77; }
}

# The EXIT trap: stops the test's Slurm (if started); removes $work after a pass, keeps it after a
# failure.
slurm_test_cleanup() {
  local rc=$?
  if [ -n "$cluster" ]; then "$SRC/scripts/slurm_local.sh" stop "$cluster" || true; fi
  if [ "$rc" -eq 0 ]; then
    rm -rf "$work"
  else
    echo "test failed (exit $rc); files kept in $work (Slurm logs: $work/cluster/log)" >&2
  fi
}

# slurm_test_start NAME: makes $work (a temp dir named after NAME), installs the cleanup trap, then
# starts Slurm in $work/cluster ($cluster) and exports SLURM_CONF.
slurm_test_start() {
  work="$(mktemp -d "${TMPDIR:-/tmp}/$1.XXXXXX")"
  cluster=""
  trap slurm_test_cleanup EXIT
  trap 'exit 130' INT TERM HUP

  step "start Slurm"
  cluster="$work/cluster"
  "$SRC/scripts/slurm_local.sh" start "$cluster" >/dev/null
  export SLURM_CONF="$cluster/slurm.conf"
}
