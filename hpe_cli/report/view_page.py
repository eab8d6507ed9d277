"""The files of ``hpe view``'s page: ``index.html``, the script and style (package data ``hpe_cli/data/view``),
``rows.js`` (the grid's columns) and ``rows/NNNNN.js`` (every column of :data:`CHUNK` rows, for the detail view).

Data files are scripts that assign or call a global (``window.HPE_VIEW = {...}``, ``HPE_VIEW_ROWS(k, {...})``)
rather than JSON, so the page works from ``file://`` (browsers refuse ``fetch`` of local files) and from any
static host; nothing is loaded from the network. Columns are stored column-wise (one array per column; text
columns with few distinct values as ``{values, codes}``), serialised with orjson.
"""

from __future__ import annotations

import html
import importlib.resources as ir
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import orjson
import pandas as pd

from ..geometry.draw import image_vectors

#: rows per detail file
CHUNK = 1000
#: columns shown as categories (filters) when present, besides other text columns with few values and flags
CATEGORY_COLUMNS = ("dataset", "sequence", "camera", "person_id", "subject", "split", "source")
#: a text column with at most this many distinct values is a category
MAX_CATEGORIES = 512
_SKIP_NUMERIC = re.compile(r"^(lm\d+_[xyz]|r[0-2][0-2]|pitch(_2)?|yaw(_2)?|roll(_2)?|__line__)$")
ASSETS = ("index.html", "view.js", "view.css")


def n_chunks(n: int) -> int:
    """Number of ``rows/NNNNN.js`` files of a page of ``n`` rows."""
    return -(-n // CHUNK)


def _dumps(obj) -> bytes:
    return orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY, default=str)


def _num(v, digits=3):
    v = np.asarray(v, dtype=np.float64)
    return np.round(np.where(np.isfinite(v), v, np.nan), digits)


def _category(values) -> dict:
    s = pd.Series(values, dtype=object).map(
        lambda x: None if x is None or (isinstance(x, float) and x != x) else str(x)
    )
    codes, uniq = pd.factorize(s, sort=True)
    return {"values": [str(u) for u in uniq], "codes": codes.astype(np.int32)}


def grid_columns(frame) -> tuple:
    """``(numeric, categories, flags)`` column names of ``frame`` that the grid filters and sorts by."""
    numeric, cats, flags = [], [], []
    for c in frame.columns:
        s = frame[c]
        if pd.api.types.is_bool_dtype(s):
            flags.append(c)
        elif c in CATEGORY_COLUMNS:
            cats.append(c)
        elif pd.api.types.is_numeric_dtype(s):
            if not _SKIP_NUMERIC.match(c):
                numeric.append(c)
        elif c not in ("image", "file") and s.nunique(dropna=True) <= MAX_CATEGORIES:
            cats.append(c)
    return numeric, cats, flags


def _vectors(A) -> np.ndarray:
    """(N, 6): the image directions (u, v) of the three axis lines (:func:`hpe_cli.geometry.draw.image_vectors`)."""
    out = np.full((len(A), 6), np.nan)
    ok = np.isfinite(A.reshape(len(A), 9)).all(axis=1)
    if ok.any():
        out[ok] = image_vectors(A[ok])[:, :, :2].reshape(-1, 6)
    return np.round(out, 4)


@dataclass(frozen=True)
class Page:
    """What the page shows. ``labels``/``other`` are :class:`hpe_cli.pipelines.view.tables.Table` s (``other``
    None without OTHER); every array has one entry per row of ``labels``."""

    title: str
    labels: object
    other: object
    #: row of OTHER paired with each row (-1: none)
    bidx: np.ndarray
    #: (N, 3) pitch, yaw, roll of LABELS and of OTHER (in LABELS' system), degrees
    angles: np.ndarray
    other_angles: np.ndarray
    #: (N,) geodesic angle between the two poses, degrees
    angle: np.ndarray
    #: (N, 3, 3) canonical matrices of LABELS and OTHER (NaN where none)
    A: np.ndarray
    A_other: np.ndarray
    #: (N, 2) head centre and (N,) line length, image pixels
    centre: np.ndarray
    length: np.ndarray
    #: (N,) thumbnail file names (None: not shown)
    thumbs: np.ndarray
    #: per distinct image: reduced frame file name (or None) and (width, height) (or None)
    frames: list
    sizes: list
    #: (N,) index of each row's image (-1: none)
    img_code: np.ndarray
    #: (N,) "ok" or why the row is not shown
    status: np.ndarray
    #: the run's counts (ints and lists go into the page)
    counts: dict
    #: further system names -> ``(angles, other_angles)`` (:func:`hpe_cli.pipelines.view.job.also_angles`)
    also: dict | None = None


def write_page(folder, page: Page):
    """Write the page into ``folder`` (the run's staged output folder): ``rows.js``, ``rows/NNNNN.js`` and the
    static files."""
    folder = Path(folder)
    (folder / "rows.js").write_bytes(b"window.HPE_VIEW=" + _dumps(_grid_data(page)) + b";\n")
    _write_chunks(folder, page)
    _write_assets(folder, page.title)


def _grid_data(page: Page) -> dict:
    """``window.HPE_VIEW``: the columns the grid filters and sorts by, the thumbnails, the images, the meta."""
    labels, other, angles = page.labels, page.other, page.angles
    frame = labels.frame
    numeric, cats, flags = grid_columns(frame)
    num = {"pitch": _num(angles[:, 0]), "yaw": _num(angles[:, 1]), "roll": _num(angles[:, 2])}
    if other is not None:
        oa = page.other_angles
        num.update(angle=_num(page.angle), other_pitch=_num(oa[:, 0]), other_yaw=_num(oa[:, 1]),
                   other_roll=_num(oa[:, 2]))  # fmt: skip
    for c in numeric:
        num.setdefault(c, _num(frame[c].to_numpy(dtype=np.float64, na_value=np.nan), 4))
    num["row"] = labels.row_numbers()
    cat = {c: _category(frame[c].tolist()) for c in cats}
    cat["status"] = _category(page.status)
    if other is not None:
        cat["other"] = _category(np.where(page.bidx >= 0, "matched", "no row in OTHER"))
    flag = {c: frame[c].fillna(False).to_numpy(dtype=bool).astype(np.int8) for c in flags}
    images = [{"f": f, "w": s[0] if s else None, "h": s[1] if s else None} for f, s in zip(page.frames, page.sizes)]
    return {
        "meta": _meta(page),
        "num": num,
        "cat": cat,
        "flag": flag,
        "systems": _systems(page),
        "thumb": page.thumbs.tolist(),
        "img": page.img_code,
        "images": images,
    }


def _meta(page: Page) -> dict:
    def describe(t):
        return None if t is None else {"path": str(t.src.path), "system": t.resolved.describe(),
                                       "unit": t.src.unit}  # fmt: skip

    return {
        "title": page.title,
        "labels": describe(page.labels),
        "other": describe(page.other),
        "n": len(page.labels.frame),
        "chunk": CHUNK,
        "counts": {k: v for k, v in page.counts.items() if isinstance(v, (int, list))},
        "angles_system": page.labels.system.name,
        "systems": [page.labels.system.name, *(page.also or {})],
    }


def _systems(page: Page) -> dict:
    """The angles in each ``--also-in`` system."""
    systems = {}
    for name, (ang, ang_o) in (page.also or {}).items():
        d = {"pitch": _num(ang[:, 0]), "yaw": _num(ang[:, 1]), "roll": _num(ang[:, 2])}
        if page.other is not None:
            d.update(other_pitch=_num(ang_o[:, 0]), other_yaw=_num(ang_o[:, 1]), other_roll=_num(ang_o[:, 2]))
        systems[name] = d
    return systems


def _write_chunks(folder: Path, page: Page) -> None:
    """Every column, :data:`CHUNK` rows per ``rows/NNNNN.js`` (the detail view)."""
    frame, other, labels = page.labels.frame, page.other, page.labels
    n = len(frame)
    (folder / "rows").mkdir(exist_ok=True)
    vec, vec_o = _vectors(page.A), _vectors(page.A_other)
    boxes = np.stack([frame[c].to_numpy(dtype=np.float64, na_value=np.nan) if c in frame else np.full(n, np.nan)
                      for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h")], axis=1)  # fmt: skip
    lmxy = _landmarks(frame)
    for k, a in enumerate(range(0, n, CHUNK)):
        b = min(n, a + CHUNK)
        part = frame.iloc[a:b]
        d = {
            "cols": list(part.columns),
            "values": {c: part[c].tolist() for c in part.columns},
            "src": [labels.where(i) for i in range(a, b)],
            "centre": np.round(page.centre[a:b], 2),
            "length": np.round(page.length[a:b], 2),
            "box": boxes[a:b],
            "vec": vec[a:b],
            "vec_other": vec_o[a:b],
            "lm": None if lmxy is None else np.round(lmxy[a:b], 2),
        }
        if other is not None:
            d.update(_other_chunk(other, page.bidx[a:b]))
        (folder / "rows" / f"{k:05d}.js").write_bytes(b"HPE_VIEW_ROWS(" + str(k).encode() + b"," + _dumps(d) + b");\n")


def _landmarks(frame):
    """(N, 2K) ``lm{k}_x, lm{k}_y`` of every landmark with both columns, or None."""
    lm = sorted(
        {int(m.group(1)) for c in frame.columns if (m := re.match(r"^lm(\d+)_x$", c)) and f"lm{m.group(1)}_y" in frame}
    )
    if not lm:
        return None
    return np.stack([frame[f"lm{k}_{a}"].to_numpy(dtype=np.float64, na_value=np.nan) for k in lm for a in "xy"], axis=1)


def _other_chunk(other, j) -> dict:
    """OTHER's columns (landmarks left out) and row names for the rows ``j`` of a chunk (-1: none)."""
    has = j >= 0
    ocols = [c for c in other.frame.columns if not re.match(r"^lm\d+_[xyz]$", c)]
    sub = other.frame.iloc[j[has]]
    return {
        "other_cols": ocols,
        "other_values": {c: _scatter(sub[c].tolist(), has) for c in ocols},
        "other_src": _scatter([other.where(int(i)) for i in j[has]], has),
    }


def _write_assets(folder: Path, title) -> None:
    """``index.html`` (with the title), ``view.js`` and ``view.css`` from the package data."""
    assets = ir.files("hpe_cli.data") / "view"
    for name in ASSETS:
        text = (assets / name).read_text(encoding="utf-8")
        if name == "index.html":
            text = text.replace("{{title}}", html.escape(str(title)))
        (folder / name).write_text(text, encoding="utf-8")


def _scatter(values, has) -> list:
    out = [None] * len(has)
    for i, v in zip(np.flatnonzero(has), values):
        out[i] = v
    return out
