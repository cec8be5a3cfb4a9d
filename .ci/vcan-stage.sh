#!/usr/bin/env bash
# CI stage: what only kernel SocketCAN shows (.ci/vcan-selection.txt) on vcan0..2 inside a throw-away
# QEMU guest (and `sherpa bus`, error frames and capture on a spare vcan3),
# the simulated arm (`sherpa sim`) in one process and the commands in the pytest process, as on a
# technician's Linux machine with vcan. One guest start for the whole selection. docs/testing.md.
#
# usage: .ci/vcan-stage.sh [PYTEST ARGS...]     (run from anywhere; uses `python` from PATH)
# env:   SHERPA_VCAN_VM       the guest runner (default: ../shared/tools/run-in-vcan-vm.sh from the repo
#                             root, else /work/shared/tools/run-in-vcan-vm.sh)
#        SHERPA_SKIP_VCAN=1   skip this stage on purpose (a machine without the runner); otherwise a
#                             missing runner fails the stage
#        SHERPA_VCAN_SELECTION  the selection file (default .ci/vcan-selection.txt: a node id per line, and why)
#        SHERPA_VCAN_ALL=1    every realbus and vcan test instead (about 26 min; not in CI)
#        SHERPA_VCAN_TIMEOUT  wall-clock limit of the guest run in seconds (default 1200: the selection
#                             takes about 3-4 min with the guest's start, 2026-11-29)
#        SHERPA_VCAN_CPUS     guest vCPUs (default 2: the simulator and the tests each get one)
#        SHERPA_TEST_CONSUMER_MS  the commands' dead-man time in the guest (default 2000, the safe bound;
#                             the bundled config's 500 ms elsewhere): see below
#        SHERPA_TEST_LIVENESS_S  the time a command's loop may go without a sign of life before its
#                             heartbeat stops, in the guest (default 5; the bundled config's 1 s elsewhere)
#        SHERPA_TEST_PAIR_RECORD_RATE  `diffdrive move`'s recording rate in the guest (default 50 Hz; 500 elsewhere)
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
# The runner sits beside the checkout (../shared/tools); a clean clone made elsewhere on the same
# machine finds it at the workplace's fixed path.
vm=${SHERPA_VCAN_VM:-}
if [ -z "$vm" ]; then
  for candidate in "$root/../shared/tools/run-in-vcan-vm.sh" /work/shared/tools/run-in-vcan-vm.sh; do
    if [ -x "$candidate" ]; then vm=$candidate; break; fi
  done
  vm=${vm:-$root/../shared/tools/run-in-vcan-vm.sh}
fi
limit=${SHERPA_VCAN_TIMEOUT:-$([ "${SHERPA_VCAN_ALL:-}" = 1 ] && echo 2700 || echo 1200)}
cpus=${SHERPA_VCAN_CPUS:-2}
interfaces=vcan0,vcan1,vcan2
spare=vcan3  # the `vcan` tests' own interface (tests/test_bus_vcan.py takes it down and up)

if [ "${SHERPA_SKIP_VCAN:-}" = 1 ]; then
  echo "CI: vcan stage skipped (SHERPA_SKIP_VCAN=1)" >&2
  exit 0
fi
if [ ! -x "$vm" ]; then
  echo "CI: vcan stage: no guest runner at $vm" >&2
  echo "CI: set SHERPA_VCAN_VM to run-in-vcan-vm.sh, or SHERPA_SKIP_VCAN=1 to skip this stage on purpose" >&2
  exit 1
fi
# What runs here: .ci/vcan-selection.txt, what only kernel SocketCAN shows (the socketcan paths of
# scan, commission and capture, `sherpa bus` over netlink, error frames, the dead-man across processes),
# with the reason for each test; every other realbus test runs in the `remote` stage. The whole-arm
# commissioning is the slowest (about 4 min in the guest: every step is 14 drives' interpreter traffic
# through a 15-20x slower Python on both ends), well inside the per-test timeout.
# The cross-process tests run a moving command beside the simulator. In the 15-20x slower guest that
# starved the moving command's heartbeat thread past the bundled 500 ms consumer time, and the drive's
# dead-man stopped it first: correct dead-man behaviour, but the tests' premise gone. So the commands
# here arm their drives with a longer dead-man time (tests/conftest.py writes it into the harness's
# config); the tests that time a trip read it back from that config and scale with it, and they wait
# for the simulator's own "heartbeat lost" events rather than sleep a guessed time.
consumer_ms=${SHERPA_TEST_CONSUMER_MS:-2000}
# and a longer liveness: 1 s in the guest is 50-70 ms native, and a jog whose loop waited that long beside
# a starting Python process stopped itself (MO=0) before the test acted
liveness_s=${SHERPA_TEST_LIVENESS_S:-5}
# and `diffdrive move` records its pair at 50 Hz, not the bundled 500: the guest's simulator could not
# answer 500 SYNCs a second beside the command's requests (measured 2026-11-28)
pair_rate=${SHERPA_TEST_PAIR_RECORD_RATE:-50}
selection_file=${SHERPA_VCAN_SELECTION:-$root/.ci/vcan-selection.txt}
if [ "${SHERPA_VCAN_ALL:-}" = 1 ]; then
  selection=(-m "realbus or vcan")  # every realbus test, as before 2026-11-29 (about 26 min)
else
  mapfile -t selection < <(sed -e 's/#.*//' -e 's/[[:space:]]*$//' -e '/^[[:space:]]*$/d' -e 's/^[[:space:]]*//' \
    -e 's/[[:space:]].*//' "$selection_file")
  if [ "${#selection[@]}" -eq 0 ]; then
    echo "CI: vcan stage: $selection_file selects no test" >&2
    exit 1
  fi
fi
# the guest sees this machine's files read-only, so the same interpreter and virtualenv work there
python=$(command -v python)

what="the ${#selection[@]} entries of $(basename "$selection_file")"
[ "${SHERPA_VCAN_ALL:-}" = 1 ] && what="every realbus and vcan test (SHERPA_VCAN_ALL=1)"
echo "CI: $what on $interfaces in a QEMU guest ($cpus vCPUs, limit ${limit}s)" >&2
set +e
"$vm" -c "$cpus" -i "$interfaces,$spare" -t "$limit" -- \
  env SHERPA_TEST_BUS="socketcan:$interfaces" SHERPA_VCAN_SPARE="$spare" SHERPA_TEST_CONSUMER_MS="$consumer_ms" \
  SHERPA_TEST_LIVENESS_S="$liveness_s" SHERPA_TEST_PAIR_RECORD_RATE="$pair_rate" \
  "$python" -m pytest "${selection[@]}" --durations=10 -p no:randomly \
  -o timeout="${SHERPA_VCAN_TEST_TIMEOUT:-900}" "$@"
rc=$?
set -e
case "$rc" in
  0) ;;
  4) echo "CI: vcan stage: a test of the selection was not found (.ci/vcan-selection.txt)" >&2 ;;
  5) echo "CI: vcan stage: pytest collected no test" >&2; exit 1 ;;
  124) echo "CI: vcan stage: timed out after ${limit}s (SHERPA_VCAN_TIMEOUT)" >&2 ;;
  125) echo "CI: vcan stage: the QEMU guest could not run (see the runner's message above)" >&2 ;;
  *) echo "CI: vcan stage: tests failed (exit $rc)" >&2 ;;
esac
exit "$rc"
