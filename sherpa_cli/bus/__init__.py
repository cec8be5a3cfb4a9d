"""Buses and sessions: a python-can bus and a paced canopen Network per configured bus (links.py),
--bus-map overrides (busmap.py), work on several buses at once (parallel.py), the arm session that
opens them all and hands out one DriveClient and one SDO client per drive (session.py), SDO transfers
with one error type (sdo.py), CiA 301 names (canopen_names.py) and what a target name means
(targets.py: DriveRef, joints, pairs; docs/targets.md).

May import elmo, joints, config, errors, paths. python-can / canopen are imported inside functions so
`sherpa --help` stays fast. The in-process simulator is handed in by the CLI, never imported here.
"""
