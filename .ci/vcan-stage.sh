#!/usr/bin/env bash
# CI stage: the realbus-marked tests on kernel SocketCAN vcan0..2 inside a throw-away QEMU guest
# (and the `vcan`-marked ones, `sherpa bus` on a spare vcan3),
# the simulated arm (`sherpa sim`) in one process and the commands in the pytest process, as on a
# technician's Linux machine with vcan. One guest start for the whole selection. docs/testing.md.
#
# usage: .ci/vcan-stage.sh [PYTEST ARGS...]     (run from anywhere; uses `python` from PATH)
# env:   SHERPA_VCAN_VM       the guest runner (default: ../shared/tools/run-in-vcan-vm.sh from the repo
#                             root, else /work/shared/tools/run-in-vcan-vm.sh)
#        SHERPA_SKIP_VCAN=1   skip this stage on purpose (a machine without the runner); otherwise a
#                             missing runner fails the stage
#        SHERPA_VCAN_TIMEOUT  wall-clock limit of the guest run in seconds (default 2700: the realbus tests,
#                             motion ones with subprocesses, and the whole-arm commissioning (about 4 min
#                             there), in a 15-20x slower TCG guest)
#        SHERPA_VCAN_CPUS     guest vCPUs (default 2: the simulator and the tests each get one)
#        SHERPA_TEST_CONSUMER_MS  the commands' dead-man time in the guest (default 2000, the safe bound;
#                             the bundled config's 500 ms elsewhere): see below
#        SHERPA_TEST_LIVENESS_S  the time a command's loop may go without a sign of life before its
#                             heartbeat stops, in the guest (default 5; the bundled config's 1 s elsewhere)
#        SHERPA_TEST_PAIR_RECORD_RATE  `diffdrive move`'s recording rate in the guest (default 50 Hz; 500 elsewhere)
#        SHERPA_VCAN_FULL=1   also run the cross-process tests deselected below
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
limit=${SHERPA_VCAN_TIMEOUT:-2700}
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
# test_commission_whole_arm (apply, save, flash proof by NMT reset of 14 drives) runs here too: it
# never stalled, it is slow in the guest (measured 2026-11-25 alone: scan 51 s, identify 24 s, plan
# 38 s, apply 38 s, save 27 s, backup 15 s, verify 28 s, flash proof 16 s; 4 min against 6 s over
# python-can-remote: every step is 14 drives' interpreter traffic through a 15-20x slower Python on
# both ends), well inside the per-test timeout; the stage's limit above counts it.
# The cross-process tests run a moving command beside the simulator and, meanwhile, start a third
# Python process (program-limits, a second jog, the successor of a killed command) or flood the bus
# with EMCYs. In the 15-20x slower guest that starved the moving command's heartbeat thread past the
# bundled 500 ms consumer time (measured 2026-11-25: "heartbeat lost" before the test had acted), and
# the drive's dead-man stopped it first: correct dead-man behaviour, but the tests' premise gone. So
# the commands here arm their drives with a longer dead-man time (tests/conftest.py writes it into the
# harness's config); the tests that time a trip read it back from that config and scale with it, and
# the tests wait for the simulator's own "heartbeat lost" events rather than sleep a guessed time.
consumer_ms=${SHERPA_TEST_CONSUMER_MS:-2000}
# and a longer liveness: 1 s in the guest is 50-70 ms native, and a jog whose loop waited that long beside
# a starting Python process stopped itself (MO=0) before the test acted (SIGKILL of one of two jogs)
liveness_s=${SHERPA_TEST_LIVENESS_S:-5}
# and `diffdrive move` records its pair at 50 Hz, not the bundled 500: the guest's simulator could not
# answer 500 SYNCs a second beside the command's requests; its backlog grew until it lost the host's
# heartbeats, and the drives' dead-man stopped the move before a motor went on (measured 2026-11-28)
pair_rate=${SHERPA_TEST_PAIR_RECORD_RATE:-50}
# The killed `diffdrive move` runs here since 2026-11-28: its 28 set-up requests now count as signs of
# life (ArmSession.watch_requests), the simulator hears a frame its pump got to late when it arrived
# (sim/arm.py LATE_FRAME_S), and the pair records at 50 Hz here (above).
# Still failing in full guest stages with a 2000 ms dead-man and 5 s liveness (measured 2026-11-27 on a
# loaded 2-core host; they run in the remote stage every CI; on 2026-11-28, after the fixes above, each
# passed in a targeted guest run, which is not yet a full stage):
# - two motion commands, SIGSTOP and SIGKILL: the first command's drive went off by MO=0, not by its
#   dead-man (SIGKILL: passed in a targeted guest run with the 5 s liveness, failed in 2 of 3 full stages)
# - EMCY flood: the 2000-frame flood starved the jog's heartbeat past 2 s; the dead-man tripped first
# - program-limits: exit 0, it did not see the jog as moving the drive (not yet explained; the test now
#   says whether the jog was still running and shows both commands' output when it fails)
deselect=(--deselect "tests/test_motion_crossprocess.py::test_two_motion_commands_on_one_bus_a_killed_or_frozen_one_stops_its_drive_the_other_keeps_running[19]"
          --deselect "tests/test_motion_crossprocess.py::test_two_motion_commands_on_one_bus_a_killed_or_frozen_one_stops_its_drive_the_other_keeps_running[9]"
          --deselect tests/test_drive_watch_crossprocess.py::test_an_emcy_flood_from_the_moving_drive_stops_the_jog
          --deselect tests/test_motion_crossprocess.py::test_program_limits_during_a_jog_in_another_process_is_refused_with_exit_5)
if [ "${SHERPA_VCAN_FULL:-}" = 1 ]; then deselect=(); fi  # everything, the ones above included
# the guest sees this machine's files read-only, so the same interpreter and virtualenv work there
python=$(command -v python)

echo "CI: realbus tests on $interfaces in a QEMU guest ($cpus vCPUs, limit ${limit}s)" >&2
set +e
"$vm" -c "$cpus" -i "$interfaces,$spare" -t "$limit" -- \
  env SHERPA_TEST_BUS="socketcan:$interfaces" SHERPA_VCAN_SPARE="$spare" SHERPA_TEST_CONSUMER_MS="$consumer_ms" \
  SHERPA_TEST_LIVENESS_S="$liveness_s" SHERPA_TEST_PAIR_RECORD_RATE="$pair_rate" \
  "$python" -m pytest -m "realbus or vcan" --durations=5 -p no:randomly \
  -o timeout="${SHERPA_VCAN_TEST_TIMEOUT:-900}" "${deselect[@]}" "$@"
rc=$?
set -e
case "$rc" in
  0) ;;
  5) echo "CI: vcan stage: pytest collected no realbus or vcan tests" >&2; exit 1 ;;
  124) echo "CI: vcan stage: timed out after ${limit}s (SHERPA_VCAN_TIMEOUT)" >&2 ;;
  125) echo "CI: vcan stage: the QEMU guest could not run (see the runner's message above)" >&2 ;;
  *) echo "CI: vcan stage: tests failed (exit $rc)" >&2 ;;
esac
exit "$rc"
