"""Pure joint math: units (units.py), differential pairs (diffpair.py), the drive parameter set and its
order (params.py), the Appendix C derivation (limits.py) and current checks (currents.py, below
limits.py: limits imports it, never the other way round), and time-stamped multi-joint paths
(trajectory.py: checks, resampling, motor points).

May import config and errors only. Nothing here talks to a bus or prints.
"""

from __future__ import annotations

__all__ = ["currents", "diffpair", "limits", "units"]
