"""Early-error exits under CPU load: every run must end with exit 1 (bad input) or 2 (usage), never an abort.

Each case is a command a user mistypes (a missing column, an existing output
without --overwrite, an unknown system name, a missing file) run as
``python -m hpe_cli ...`` in a fresh process while another process burns a
core. Before the fix ~1 run in 5 of ``hpe convert labels.csv -o existing.parquet``
with a missing column ended in ``terminate called without an active exception``
(exit 134): Arrow pool threads still starting when the interpreter tore them
down. Prints the count of each exit code and exits 1 if any run ended otherwise.

    PYTHONPATH=. python benchmarks/early_errors.py            # 2,000 runs
    PYTHONPATH=. python benchmarks/early_errors.py -n 200 -j 4
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def make_inputs(d: Path) -> dict:
    """Small input files in ``d``: a CSV missing ``roll``, a good CSV, an existing output."""
    d.mkdir(parents=True, exist_ok=True)
    bad = d / "labels_no_roll.csv"
    bad.write_text("image,pitch,yaw\na.jpg,1,2\nb.jpg,3,4\n")
    good = d / "labels.csv"
    good.write_text("image,pitch,yaw,roll,bbox_x,bbox_y,bbox_w,bbox_h\na.jpg,1,2,3,0,0,10,10\nb.jpg,3,4,5,0,0,10,10\n")
    existing = d / "existing.parquet"
    existing.write_bytes(b"not yours")
    return {"bad": bad, "good": good, "existing": existing, "missing": d / "no_such_file.csv", "dir": d}


def cases(f: dict) -> list:
    """``(name, argv)`` of every early-error path (each must exit 1 or 2)."""
    d = f["dir"]
    bad, good, existing, missing = (str(f[k]) for k in ("bad", "good", "existing", "missing"))
    out = str(d / "out.parquet")
    return [
        ("convert missing column", ["convert", bad, "-o", out, "--from", "300w_lp", "--to", "6drepnet"]),
        ("convert existing output", ["convert", bad, "-o", existing, "--from", "300w_lp", "--to", "6drepnet"]),
        (
            "convert existing output, good input",
            ["convert", good, "-o", existing, "--from", "300w_lp", "--to", "6drepnet"],
        ),
        ("convert bad system", ["convert", good, "-o", out, "--from", "nope", "--to", "6drepnet"]),
        ("convert missing file", ["convert", missing, "-o", out, "--from", "300w_lp", "--to", "6drepnet"]),
        ("audit missing column", ["audit", bad]),
        ("audit existing output", ["audit", good, "-o", existing]),
        ("audit bad system", ["audit", good, "--system", "nope"]),
        ("audit missing file", ["audit", missing]),
        ("draw missing column", ["draw", bad, "-o", str(d / "drawn"), "--canvas", "64x64"]),
        ("draw bad system", ["draw", good, "-o", str(d / "drawn"), "--system", "nope"]),
        ("augment missing column", ["augment", bad, "-o", out, "--image-size", "64", "64", "--hflip"]),
        ("augment existing output", ["augment", good, "-o", existing, "--image-size", "64", "64", "--hflip"]),
        ("evaluate missing column", ["evaluate", bad, good, "--pred-system", "300w_lp", "--gt-system", "300w_lp"]),
        ("evaluate missing file", ["evaluate", missing, good, "--pred-system", "300w_lp", "--gt-system", "300w_lp"]),
        ("export missing column", ["export", bad, "-o", str(d / "ex"), "--layout", "hf"]),
        (
            "relabel-panoptic existing output",
            ["relabel-panoptic", str(ROOT / "sample_data" / "panoptic_synth"), "-o", existing],
        ),
    ]


def run_one(argv, timeout=120) -> tuple:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    p = subprocess.run(
        [sys.executable, "-m", "hpe_cli", *argv],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
        cwd=str(ROOT),
        check=False,
    )
    return p.returncode, p.stderr


class Burner:
    """A second process that keeps one core busy for the duration (the load under which the abort showed)."""

    def __enter__(self):
        self.p = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        return self

    def __exit__(self, *exc):
        self.p.kill()
        self.p.wait()


def run(n: int, jobs: int, d: Path) -> collections.Counter:
    todo = cases(make_inputs(d))
    plan = [todo[k % len(todo)] for k in range(n)]
    counts: collections.Counter = collections.Counter()
    bad = []
    with Burner(), ThreadPoolExecutor(jobs) as pool:
        for (name, argv), (rc, err) in zip(plan, pool.map(lambda c: run_one(c[1]), plan)):
            counts[rc] += 1
            want = 2 if ("bad system" in name or "missing file" in name) else 1
            if rc != want or "Traceback" in err or "terminate called" in err or err.count("Error:") != 1:
                bad.append((name, rc, err.strip()[-300:]))
    for name, rc, err in bad[:10]:
        print(f"UNEXPECTED exit {rc} in {name!r}: {err}", file=sys.stderr)
    counts["unexpected"] = len(bad)
    return counts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=2000, help="runs (cycling through the cases)")
    ap.add_argument("-j", "--jobs", type=int, default=2, help="runs at once")
    a = ap.parse_args()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        counts = run(a.n, a.jobs, Path(tmp))
    dt = time.perf_counter() - t0
    unexpected = counts.pop("unexpected")
    print(
        f"{a.n} early-error runs under load in {dt:.0f} s: "
        + ", ".join(f"exit {k}: {v}" for k, v in sorted(counts.items()))
        + f"; unexpected status or message: {unexpected}"
    )
    return 0 if set(counts) <= {1, 2} and not unexpected else 1


if __name__ == "__main__":
    sys.exit(main())
