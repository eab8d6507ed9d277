"""Run the ``hpe`` examples of the docs and check (or refresh) the output printed under them.

A runnable example is a fenced ``bash`` block right after the marker ``<!-- hpe-example -->`` (or
``<!-- hpe-example realdata -->``: it runs only when ``../shared/realdata`` or ``$HPE_REALDATA`` exists).
Each line that starts with ``hpe `` (a trailing backslash continues it) runs, in order, in one scratch folder
per page that holds links to the repository's ``sample_data``, ``tests`` and ``configs``. An optional fenced
``text`` block right after the marker ``<!-- hpe-output -->`` that follows holds what the commands printed
(stdout and stderr, progress bars off).

    python tests/docs/doc_examples.py            # run every example, report differences
    python tests/docs/doc_examples.py --update   # run them and rewrite the output blocks
    python tests/docs/doc_examples.py --update systems.md   # one page
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
MARK = re.compile(
    r"<!-- hpe-example( realdata)? -->\n```bash\n(.*?)```\n"
    r"(?:\n<!-- hpe-output -->\n```text\n(.*?)```\n)?",
    re.S,
)


@dataclass
class Example:
    page: Path
    commands: list
    output: str | None
    realdata: bool
    span: tuple


def realdata_dir() -> Path | None:
    p = Path(os.environ.get("HPE_REALDATA", ROOT.parent / "shared" / "realdata"))
    return p if p.is_dir() else None


def commands(block: str) -> list[str]:
    out, cur = [], ""
    for line in block.splitlines():
        s = line.strip()
        if cur:
            cur += " " + s.rstrip("\\").strip()
        elif s.startswith("hpe "):
            cur = s.rstrip("\\").strip()
        else:
            continue
        if not s.endswith("\\"):
            out.append(re.sub(r"\s+#.*$", "", cur))
            cur = ""
    return out


def examples(page: Path) -> list[Example]:
    text = page.read_text(encoding="utf-8")
    return [Example(page, commands(m.group(2)), m.group(3), bool(m.group(1)), m.span()) for m in MARK.finditer(text)]


def pages() -> list[Path]:
    return sorted(p for p in DOCS.rglob("*.md") if "hpe-example" in p.read_text(encoding="utf-8"))


def _scratch(tmp: Path) -> None:
    for name in ("sample_data", "tests", "configs"):
        (tmp / name).symlink_to(ROOT / name)
    rd = realdata_dir()
    if rd is not None:
        (tmp / "realdata").symlink_to(rd)


def run(cmd: str, cwd: Path) -> tuple[int, str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="100", NO_COLOR="1")
    argv = [sys.executable, "-m", "hpe_cli", *shlex.split(cmd)[1:]]
    p = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=120)
    return p.returncode, (p.stdout + p.stderr)


def run_page(page: Path) -> list[tuple[Example, str, list]]:
    """Run every example of ``page``; returns (example, printed output, [(command, exit code)])."""
    results = []
    with tempfile.TemporaryDirectory(prefix="hpe-docs-") as tmp:
        tmp = Path(tmp)
        _scratch(tmp)
        for ex in examples(page):
            if ex.realdata and realdata_dir() is None:
                continue
            printed, codes = [], []
            for cmd in ex.commands:
                code, out = run(cmd, tmp)
                codes.append((cmd, code))
                printed.append(out)
            results.append((ex, "".join(printed), codes))
    return results


def normalise(text: str) -> str:
    return "\n".join(line.rstrip() for line in text.strip().splitlines())


#: a number written in e-notation (``6.57e-16``, ``-1E-13``)
E_NUMBER = re.compile(r"[-+]?\d+(?:\.\d*)?[eE][-+]?\d+")
#: below this, a printed number is rounding noise whose digits depend on the CPU's SIMD paths
ROUNDING_LEVEL = 1e-9


def rounding_level_numbers(text: str) -> list[str]:
    """The numbers in ``text`` at rounding level (``0 < |x| < 1e-9``), which no page may show digit for digit
    (a bound such as ``< 1e-12`` is stable, so it is not one of them)."""
    return [
        m.group(0)
        for m in E_NUMBER.finditer(text)
        if 0 < abs(float(m.group(0))) < ROUNDING_LEVEL and not text[: m.start()].endswith("< ")
    ]


def comparable(text: str) -> str:
    """``normalise(text)`` with every number at rounding level replaced by ``~0``: what the tests compare."""
    return E_NUMBER.sub(lambda m: "~0" if abs(float(m.group(0))) < ROUNDING_LEVEL else m.group(0), normalise(text))


def simd_restricted_env() -> dict:
    """``os.environ`` with ``NPY_DISABLE_CPU_FEATURES`` naming every SIMD extension numpy dispatches to on this CPU
    above its baseline (AVX2/AVX-512 on x86-64): numpy then runs its baseline kernels, as on another CPU."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    disable = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    return dict(os.environ, NPY_DISABLE_CPU_FEATURES=" ".join(disable))


def update(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    for ex, out, codes in reversed(run_page(page)):
        bad = [c for c in codes if c[1] != 0]
        if bad:
            raise SystemExit(f"{page}: {bad[0][0]!r} exited {bad[0][1]}:\n{out}")
        a, b = ex.span
        block = text[a:b]
        head = block.split("\n<!-- hpe-output -->")[0].rstrip("\n") + "\n"
        new = head + f"\n<!-- hpe-output -->\n```text\n{normalise(out)}\n```\n"
        text = text[:a] + new + text[b:]
    page.write_text(text, encoding="utf-8")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    only = [a for a in argv if not a.startswith("--")]
    for page in pages():
        if only and not any(page.match(o) or page.name == o for o in only):
            continue
        if "--update" in argv:
            update(page)
            print(f"updated {page.relative_to(ROOT)}")
            continue
        for ex, out, codes in run_page(page):
            for cmd, code in codes:
                print(f"{code}  {cmd}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
