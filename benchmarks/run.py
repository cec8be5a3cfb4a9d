"""sherpa-cli benchmarks: each prints a measured value, a ratio and the goal for that ratio.

Ratios compare against a physical limit (the CAN bus) or a baseline measured in the same
run, because absolute times on shared machines move by 20-30 % between runs.

    python benchmarks/run.py [NAME ...] [--json]
"""

from __future__ import annotations

import argparse
import json
import operator
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

CAN_8BYTE_FRAMES_PER_S = 9_009  # 1 Mbit/s, 111 bits per 8-byte frame, no stuffing


@dataclass
class Result:
    name: str
    value: float
    unit: str
    ratio: float
    goal: str  # e.g. ">= 300"
    passed: bool
    note: str = ""

    def as_json(self) -> dict:
        d = asdict(self)
        d["pass"] = d.pop("passed")
        return d


_OPS = {">=": operator.ge, "<=": operator.le}


def _judge(ratio: float, goal: str) -> bool:
    op, number = goal.split()
    return _OPS[op](ratio, float(number))


def bench_codec() -> Result:
    """Encode a set frame and decode its reply: pairs per second vs. the bus's frame rate."""
    from sherpa_cli.elmo import codec

    cases = [("AC", 0, 150000), ("LL", 3, -240), ("CL", 1, 1.5), ("IL", 3, 21), ("VH", 2, 220)]
    replies = [codec.encode_reply(letters, index, value, isinstance(value, float))
               for letters, index, value in cases]
    n = 0
    start = time.perf_counter()
    deadline = start + 1.5
    while time.perf_counter() < deadline:
        for (letters, index, value), reply in zip(cases, replies):
            codec.encode_set(letters, index, value)
            codec.decode_reply(reply)
        n += len(cases)
    rate = n / (time.perf_counter() - start)
    goal = ">= 300"
    ratio = rate / CAN_8BYTE_FRAMES_PER_S
    ceiling = _raw_struct_pairs_per_s() / CAN_8BYTE_FRAMES_PER_S
    return Result("codec", round(rate), "pairs/s", round(ratio, 1), goal, _judge(ratio, goal),
                  f"ratio to {CAN_8BYTE_FRAMES_PER_S} frames/s (1 Mbit/s, 8-byte frames); "
                  f"bare struct pack+unpack in this run: {ceiling:.0f}x")


def _raw_struct_pairs_per_s() -> float:
    """The ceiling on this machine now: one struct pack and one unpack, no validation, no objects."""
    import struct

    pack, unpack = struct.Struct("<4si").pack, struct.Struct("<2sHi").unpack
    header = b"AC\x00\x00"
    n = 0
    start = time.perf_counter()
    deadline = start + 0.5
    while time.perf_counter() < deadline:
        for i in range(1000):
            unpack(pack(header, i))
        n += 1000
    return n / (time.perf_counter() - start)


def _wall(cmd: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, cwd=ROOT)
    return time.perf_counter() - start


def bench_startup(rounds: int = 15) -> Result:
    """`sherpa --help` wall time over `python -c pass`, medians of interleaved runs."""
    base_cmd = [sys.executable, "-c", "pass"]
    sherpa_cmd = [sys.executable, "-m", "sherpa_cli", "--help"]
    _wall(base_cmd), _wall(sherpa_cmd)  # warm the file cache
    base, sherpa = [], []
    for _ in range(rounds):
        base.append(_wall(base_cmd))
        sherpa.append(_wall(sherpa_cmd))
    ratio = statistics.median(sherpa) / statistics.median(base)
    goal = "<= 8"
    return Result("startup", round(statistics.median(sherpa) * 1000, 1), "ms", round(ratio, 2), goal,
                  _judge(ratio, goal), f"python -c pass: {statistics.median(base) * 1000:.1f} ms")


BENCHMARKS: dict[str, Callable[[], Result]] = {
    "codec": bench_codec,
    "startup": bench_startup,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("names", nargs="*", metavar="NAME", help=f"benchmarks to run: {', '.join(BENCHMARKS)}")
    parser.add_argument("--json", action="store_true", help="print a JSON list of results")
    args = parser.parse_args(argv)
    unknown = [n for n in args.names if n not in BENCHMARKS]
    if unknown:
        parser.error(f"unknown benchmark(s): {', '.join(unknown)}; known: {', '.join(BENCHMARKS)}")
    results = [BENCHMARKS[name]() for name in (args.names or BENCHMARKS)]
    if args.json:
        print(json.dumps([r.as_json() for r in results], indent=2))
    else:
        for r in results:
            verdict = "PASS" if r.passed else "FAIL"
            print(f"{r.name:10} {r.value:>12} {r.unit:8} ratio {r.ratio:>8}  goal {r.goal:6} {verdict}  {r.note}")
    return 0 if all(r.passed for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
