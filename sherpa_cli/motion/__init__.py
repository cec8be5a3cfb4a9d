"""Everything that moves a motor runs through here (docs/motion.md).

axis.py (Axis: the one type for everything a command moves, its limits, joint<->motor maps and
move-time bound; resolve_axis, the one resolver), request.py (MoveRequest: the one typed move
request, in counts), recovery.py (the one breach -> stop -> standstill -> move back), guard.py
(MotionGuard: fault check, dead-man, stop on every exit path), deadman.py (the consumer objects
and the host heartbeat thread), lock.py (one motion lock per drive), stopping.py (the one stop path
and standstill wait), report.py (what the guard did per drive), settings.py (MotionSettings),
pair_start.py (both motors of a pair started together), limit_watch.py (joint-limit breach and
recovery targets), calibration.py (the homed flag UI[3]).

May import devices, bus, elmo, joints, config, errors, paths; never ops, log, cli or sim.
"""
