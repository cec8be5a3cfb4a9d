"""Pure joint math: units, differential pairs, and the drive limits of seed Appendix C.

Nothing here talks to a bus or prints; the CLI and the drive writer build on it.
Submodules are imported on use so that loading the package stays cheap.
"""

from __future__ import annotations

__all__ = ["currents", "diffpair", "limits", "units"]
