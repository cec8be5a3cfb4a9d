"""Procedures over an open session: what each command does, without printing.

jog / joint_jog / live_jog / joystick (moving joints), home, step (`log step`), diffdrive, stop,
program / restore / save_ledger (plan, write, read back, SV), params_read / params_file / params_diff,
scan, identify, monitor, raw (`sherpa cmd`), encoder-aware reads through devices/.

May import motion, log, devices, bus, elmo, joints, config, output_files, errors, paths; never cli,
recipes or sim. Results are dataclasses the CLI renders.
"""
