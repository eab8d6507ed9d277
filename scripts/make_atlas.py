"""Build the conventions atlas of the docs: one section and one picture per built-in rotation system.

For every ``configs/systems/*.toml`` this script

1. writes the system's definition in words (``RotationSystem.describe``) and as a formula built from its
   fields (frame ``B``, head-model frame ``M``, turns, sequence, storage), and checks that formula
   numerically against the system's own kernels (so a formula that disagrees with the code stops the build);
2. calls ``hpe convert`` to express a real AFLW2000-3D label (PRNet's ``image00050``, shipped in
   ``sample_data/aflw2000``) in that system, then ``hpe convert`` again on four poses written in the system's
   own angles (the label, +30 deg pitch, +30 deg yaw, +30 deg roll) and ``hpe draw --columns matrix`` to draw
   them on the same face;
3. writes ``docs/atlas.md`` and ``docs/img/atlas/<system>.png``.

Run it from the repository root (CI runs it through ``tests/docs/test_docs_build.py`` before building the site)::

    python scripts/make_atlas.py                 # into docs/
    python scripts/make_atlas.py --docs /tmp/d   # into another docs folder
"""

from __future__ import annotations

import argparse
import csv
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FACE = "image00050"  # near-frontal AFLW2000-3D face: pitch -4.66, yaw 0.94, roll 5.64 (300W-LP angles)
STEP = 30.0
TILE = 300
AXES = "xyz"
GREEK = {"pitch": "p", "yaw": "y", "roll": "r"}


def hpe(*args: str) -> str:
    """Run one ``hpe`` command in this process (same code as the console script); fail loudly."""
    from click.testing import CliRunner

    from hpe_cli.cli.main import cli

    res = CliRunner().invoke(cli, list(args), catch_exceptions=False)
    if res.exit_code != 0:
        raise SystemExit(f"hpe {' '.join(args)} failed ({res.exit_code}): {res.output}")
    return res.output


def elemental(axis: str, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i = AXES.index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    R = np.eye(3)
    R[j, j], R[j, k], R[k, j], R[k, k] = c, -s, s, c
    return R


def _mat(M) -> str:
    rows = [" & ".join(f"{v:g}" for v in r) for r in np.asarray(M, dtype=float)]
    return r"\begin{pmatrix}" + r" \\ ".join(rows) + r"\end{pmatrix}"


def formula(s) -> tuple[str, str]:
    """LaTeX for the system matrix ``S(angles)`` and for its relation to the canonical ``A``; checked."""
    rng = np.random.default_rng(0)
    pyr = rng.uniform([-60, -80, -60], [60, 80, 60], (5, 3))
    A = np.stack([elemental("x", -p) @ elemental("y", -y) @ elemental("z", -r) for p, y, r in pyr])
    B, M = s.B, s.M
    t = "^T" if s.storage == "transposed" else ""
    same = np.allclose(B, np.eye(3)) and np.allclose(M, np.eye(3))
    if same:
        rel = f"R = A{t}"
    else:
        core = "B\\,A\\,B^T" if np.allclose(B, M) else "B\\,A\\,M^T"
        core = f"({core})^T" if t else core
        frames = f"B = {_mat(B)}" if np.allclose(B, M) else f"B = {_mat(B)},\\ M = {_mat(M)}"
        rel = f"R = {core},\\quad {frames}"
    expect = B @ A @ M.T
    if s.storage == "transposed":
        expect = np.swapaxes(expect, 1, 2)
    if not np.allclose(s.from_canonical(A), expect, atol=1e-9):
        raise SystemExit(f"{s.name}: the relation {rel} does not match the system's kernels")
    if s.angle_frame == "canonical":
        return "R \\text{ from the 300W-LP angles of the same rotation (no angles of its own)}", rel
    turns = list(s.turns) if s.sequence == "intrinsic" else list(s.turns)[::-1]
    terms, mats = [], []
    for tr in turns:
        sign = "" if tr.hand == "right" else "-"
        terms.append(f"R_{tr.axis}({sign}{GREEK[tr.angle]})")
    roles = ("pitch", "yaw", "roll")
    for row in pyr:
        ang = dict(zip(roles, row))
        S = np.eye(3)
        for tr in turns:
            S = S @ elemental(tr.axis, ang[tr.angle] * tr.sign())
        mats.append(S)
    if not np.allclose(s.from_angles(pyr), np.stack(mats), atol=1e-9):
        raise SystemExit(f"{s.name}: the formula {' '.join(terms)} does not match the system's kernels")
    S = "\\,".join(terms)
    return f"R = {S}", rel


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def picture(s, work: Path, out_png: Path) -> list[str]:
    """Draw the face at four poses in ``s``'s angles with ``hpe``; returns the tile captions."""
    import cv2

    label_csv = work / f"label_{s.name}.csv"
    hpe(
        "convert",
        str(ROOT / "sample_data" / "aflw2000"),
        "-o",
        str(label_csv),
        "--from",
        "300w_lp",
        "--to",
        s.name,
        "-q",
        "--overwrite",
    )
    row = next(r for r in _rows(label_csv) if r["file"].startswith(FACE))
    label = [float(row[k]) for k in ("pitch", "yaw", "roll")]
    poses = [label, [STEP, 0, 0], [0, STEP, 0], [0, 0, STEP]]
    images = work / "images"
    images.mkdir(exist_ok=True)
    # the face centre and size from Pose_Para (tdy counts from the image bottom)
    tdx, tdy = float(row["tdx"]), 449 - float(row["tdy"])
    poses_csv = work / f"poses_{s.name}.csv"
    with open(poses_csv, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["image", "pitch", "yaw", "roll", "tdx", "tdy", "size"])
        for k, p in enumerate(poses):
            name = f"{s.name}_{k}.jpg"
            shutil.copyfile(ROOT / "sample_data" / "aflw2000" / f"{FACE}.jpg", images / name)
            w.writerow([name, *p, tdx, tdy, 120])
    stored = work / f"stored_{s.name}.csv"
    hpe("convert", str(poses_csv), "-o", str(stored), "--from", s.name, "--to", s.name, "-q", "--overwrite")
    drawn = work / f"drawn_{s.name}"
    hpe(
        "draw",
        str(stored),
        "-o",
        str(drawn),
        "--images",
        str(images),
        "--system",
        s.name,
        "--columns",
        "matrix",
        "--thickness",
        "3",
        "-q",
        "--overwrite",
    )
    values = s.value_columns if s.storage_kind != "angles" else []
    captions, tiles = [], []
    heads = ["its label", f"+{STEP:g} pitch", f"+{STEP:g} yaw", f"+{STEP:g} roll"]
    for k, r in enumerate(_rows(stored)):
        img = cv2.imread(str(drawn / f"{s.name}_{k}.jpg"))
        img = cv2.resize(img, (TILE, TILE), interpolation=cv2.INTER_AREA)
        bar = np.full((58, TILE, 3), 255, np.uint8)
        ang = f"p {float(r['pitch']):.1f}  y {float(r['yaw']):.1f}  r {float(r['roll']):.1f}"
        cv2.putText(bar, heads[k], (6, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(bar, ang, (6, 48), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (60, 60, 60), 1, cv2.LINE_AA)
        tiles.append(np.vstack([bar, img]))
        vals = ", ".join(f"{c} {float(r[c]):.3f}" for c in values) if values else ""
        captions.append(
            f"{heads[k]}: pitch {float(r['pitch']):.2f}, yaw {float(r['yaw']):.2f}, "
            f"roll {float(r['roll']):.2f}" + (f" (stored: {vals})" if vals else "")
        )
    sheet = np.hstack([np.hstack([t, np.full((t.shape[0], 4, 3), 255, np.uint8)]) for t in tiles])[:, :-4]
    out_png.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out_png), sheet, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    return captions


def _clean(text: str) -> str:
    """Source notes without references to internal design notes."""
    parts = [p for p in text.split(";") if "SPEC" not in p]
    return ";".join(parts).strip()


HEADER = """# Conventions atlas

<!-- generated by scripts/make_atlas.py: do not edit by hand (CI regenerates it before every build) -->

Every built-in rotation system, in words, as a formula, and drawn. The pictures are made by `hpe` itself:
the same real AFLW2000-3D face (PRNet's `image00050`, see `sample_data/aflw2000/ATTRIBUTION.md`) with, from
left to right, its own label expressed in the system, then +30 degrees of the system's pitch, yaw and roll
alone. The axes are drawn from the matrix, so they mean the same in every picture:
**red** points to the subject's left, **green** runs from forehead to chin, **blue** comes out of the nose
(see [Drawing](drawing.md)). What changes from system to system is which physical turn a positive angle
is: compare the +yaw tiles.

Notation. `A` is the canonical matrix (300W-LP's: x = subject's left, y = up, z = out of the face,
$A = R_x(-p)\\,R_y(-y)\\,R_z(-r)$). $R_x, R_y, R_z$ are the right-handed elemental rotations
([Maths](maths.md#elemental-rotations)); a left-handed turn is the elemental rotation by the negated angle.
`B` is the system's frame (row n = the system's axis n in canonical coordinates) and `M` its head-model
frame when it differs. Each formula below is checked against the code when this page is generated.

| system | storage | +yaw turns the nose towards |
|---|---|---|
"""


def nose_direction(s) -> str:
    """Where +30 yaw in ``s``'s angles moves the nose, in image words (from the canonical matrix)."""
    R = s.from_angles(np.array([[0.0, STEP, 0.0]]))
    A = s.to_canonical(R)[0]
    z = A[:, 2]  # the nose axis in canonical coordinates: x = subject's left = image right
    return "the image right" if z[0] > 0.05 else "the image left" if z[0] < -0.05 else "(no yaw change)"


def build(docs: Path) -> Path:
    from hpe_cli.rotation.systems import get_system, system_names

    names = [n for n in system_names() if (ROOT / "configs" / "systems" / f"{n}.toml").exists()]
    table, sections = [], []
    with tempfile.TemporaryDirectory(prefix="hpe-atlas-") as tmp:
        for name in names:
            s = get_system(name)
            S, rel = formula(s)
            caps = picture(s, Path(tmp), docs / "img" / "atlas" / f"{name}.png")
            d = s.describe()
            table.append(f"| [`{name}`](#{name.replace('_', '_')}) | {s.storage_kind} | {nose_direction(s)} |")
            words = "\n".join(f"- **{k}**: {v}" for k, v in d.items())
            lines = [f"## {name}", "", s.description, "", words, "", f"$$ {S} $$", "", f"$$ {rel} $$", ""]
            if s.notes:
                lines += [f"Notes: {s.notes}", ""]
            src = _clean(s.source)
            if src:
                lines += [f"Follows: {src}. Status: {s.verified}.", ""]
            lines += [f"![{name}: the face with its label and +30 degrees of each angle](img/atlas/{name}.png)", ""]
            lines += [f"- {c}" for c in caps] + [""]
            sections.append("\n".join(lines))
    out = docs / "atlas.md"
    out.write_text(HEADER + "\n".join(table) + "\n\n" + "\n".join(sections), encoding="utf-8")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--docs", type=Path, default=ROOT / "docs", help="docs folder to write into")
    args = ap.parse_args(argv)
    print(build(args.docs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
