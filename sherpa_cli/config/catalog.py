"""Built-in component catalog: the seed's Table 3.1 (motors) and Table 3.2 (Elmo Whistle models).

A config may add entries or override these under ``catalog:``; names are lower-case keys.
"""

from __future__ import annotations

from sherpa_cli.config.model import Catalog, DriveModel, MotorModel

# (key, nominal V, max V, continuous A, peak A) -- seed Table 3.2
_WHISTLES = [
    ("whistle-15/48", 42, 48, 15, 30),
    ("whistle-20/48", 42, 48, 20, 40),
    ("whistle-1/60", 50, 59, 1, 2),
    ("whistle-2.5/60", 50, 59, 2.5, 5),
    ("whistle-5/60", 50, 59, 5, 10),
    ("whistle-10/60", 50, 59, 10, 20),
    ("whistle-15/60", 50, 59, 15, 30),
    ("whistle-20/60", 50, 59, 20, 40),
    ("whistle-1/100", 85, 95, 1, 2),
    ("whistle-2.5/100", 85, 95, 2.5, 5),
    ("whistle-5/100", 85, 95, 5, 10),
    ("whistle-10/100", 85, 95, 10, 20),
    ("whistle-15/100", 85, 95, 15, 30),
    ("whistle-20/100", 85, 95, 20, 40),
]

# (key, V, continuous A, W, peak A, peak W) -- seed Table 3.1
_MOTORS = [
    ("kollmorgen-rbe-02110-a", 38, 6.34, 241, 25.3, 960),
    ("tq-robodrive-70x18", 48, 7.0, 370, 43.75, 2100),
    ("tq-robodrive-50x14", 48, 3.5, 145, 25, 1200),
]


def builtin_catalog() -> Catalog:
    drives = {k: DriveModel(k, float(nv), float(mv), float(c), float(p)) for k, nv, mv, c, p in _WHISTLES}
    motors = {k: MotorModel(k, float(v), float(c), float(w), float(p), float(pw)) for k, v, c, w, p, pw in _MOTORS}
    return Catalog(drives=drives, motors=motors)
