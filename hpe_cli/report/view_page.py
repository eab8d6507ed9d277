"""The files of ``hpe view``'s page: ``index.html``, the script and style (package data ``hpe_cli/data/view``),
``rows.js`` (the grid's columns) and ``rows/NNNNN.js`` (every column of :data:`CHUNK` rows, for the detail view).

Data files are scripts that assign or call a global (``window.HPE_VIEW = {...}``, ``HPE_VIEW_ROWS(k, {...})``)
rather than JSON, so the page works from ``file://`` (browsers refuse ``fetch`` of local files) and from any
static host; nothing is loaded from the network. Columns are stored column-wise (one array per column; text
columns with few distinct values as ``{values, codes}``), serialised with orjson.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

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
    import orjson

    return orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY, default=str)


def _num(v, digits=3):
    v = np.asarray(v, dtype=np.float64)
    return np.round(np.where(np.isfinite(v), v, np.nan), digits)


def _category(values) -> dict:
    import pandas as pd

    s = pd.Series(values, dtype=object).map(
        lambda x: None if x is None or (isinstance(x, float) and x != x) else str(x)
    )
    codes, uniq = pd.factorize(s, sort=True)
    return {"values": [str(u) for u in uniq], "codes": codes.astype(np.int32)}


def grid_columns(frame) -> tuple:
    """``(numeric, categories, flags)`` column names of ``frame`` that the grid filters and sorts by."""
    import pandas as pd

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
    from ..geometry.draw import image_vectors

    out = np.full((len(A), 6), np.nan)
    ok = np.isfinite(A.reshape(len(A), 9)).all(axis=1)
    if ok.any():
        out[ok] = image_vectors(A[ok])[:, :, :2].reshape(-1, 6)
    return np.round(out, 4)


def write_page(
    folder,
    *,
    title,
    labels,
    other,
    bidx,
    angles,
    other_angles,
    angle,
    A,
    also=None,
    A_other,
    centre,
    length,
    thumbs,
    frames,
    sizes,
    img_code,
    status,
    counts,
):
    """Write the page into ``folder`` (the run's staged output folder). ``labels``/``other`` are
    :class:`hpe_cli.pipelines.view.Table` s; the arrays have one entry per row of ``labels``; ``also`` maps
    further system names to ``(angles, other_angles)`` (:func:`hpe_cli.pipelines.view.also_angles`)."""
    import importlib.resources as ir

    folder = Path(folder)
    frame = labels.frame
    n = len(frame)
    numeric, cats, flags = grid_columns(frame)
    num = {"pitch": _num(angles[:, 0]), "yaw": _num(angles[:, 1]), "roll": _num(angles[:, 2])}
    if other is not None:
        num.update(angle=_num(angle), other_pitch=_num(other_angles[:, 0]), other_yaw=_num(other_angles[:, 1]),
                   other_roll=_num(other_angles[:, 2]))  # fmt: skip
    for c in numeric:
        num.setdefault(c, _num(frame[c].to_numpy(dtype=np.float64, na_value=np.nan), 4))
    num["row"] = labels.row_numbers()
    cat = {c: _category(frame[c].tolist()) for c in cats}
    cat["status"] = _category(status)
    if other is not None:
        cat["other"] = _category(np.where(bidx >= 0, "matched", "no row in OTHER"))
    flag = {c: frame[c].fillna(False).to_numpy(dtype=bool).astype(np.int8) for c in flags}
    images = [{"f": f, "w": s[0] if s else None, "h": s[1] if s else None} for f, s in zip(frames, sizes)]

    def describe(t):
        return None if t is None else {"path": str(t.src.path), "system": t.resolved.describe(),
                                       "unit": t.src.unit}  # fmt: skip

    meta = {
        "title": title,
        "labels": describe(labels),
        "other": describe(other),
        "n": n,
        "chunk": CHUNK,
        "counts": {k: v for k, v in counts.items() if isinstance(v, (int, list))},
        "angles_system": labels.system.name,
        "systems": [labels.system.name, *(also or {})],
    }
    systems = {}
    for name, (ang, ang_o) in (also or {}).items():
        d = {"pitch": _num(ang[:, 0]), "yaw": _num(ang[:, 1]), "roll": _num(ang[:, 2])}
        if other is not None:
            d.update(other_pitch=_num(ang_o[:, 0]), other_yaw=_num(ang_o[:, 1]), other_roll=_num(ang_o[:, 2]))
        systems[name] = d
    data = {
        "meta": meta,
        "num": num,
        "cat": cat,
        "flag": flag,
        "systems": systems,
        "thumb": thumbs.tolist(),
        "img": img_code,
        "images": images,
    }
    (folder / "rows.js").write_bytes(b"window.HPE_VIEW=" + _dumps(data) + b";\n")

    # every column, CHUNK rows per file
    (folder / "rows").mkdir(exist_ok=True)
    vec, vec_o = _vectors(A), _vectors(A_other)
    boxes = np.stack([frame[c].to_numpy(dtype=np.float64, na_value=np.nan) if c in frame else np.full(n, np.nan)
                      for c in ("bbox_x", "bbox_y", "bbox_w", "bbox_h")], axis=1)  # fmt: skip
    lm = sorted(
        {int(m.group(1)) for c in frame.columns if (m := re.match(r"^lm(\d+)_x$", c)) and f"lm{m.group(1)}_y" in frame}
    )
    lmxy = (
        np.stack([frame[f"lm{k}_{a}"].to_numpy(dtype=np.float64, na_value=np.nan) for k in lm for a in "xy"], axis=1)
        if lm
        else None
    )
    for k, a in enumerate(range(0, n, CHUNK)):
        b = min(n, a + CHUNK)
        part = frame.iloc[a:b]
        d = {
            "cols": list(part.columns),
            "values": {c: part[c].tolist() for c in part.columns},
            "src": [labels.where(i) for i in range(a, b)],
            "centre": np.round(centre[a:b], 2),
            "length": np.round(length[a:b], 2),
            "box": boxes[a:b],
            "vec": vec[a:b],
            "vec_other": vec_o[a:b],
            "lm": None if lmxy is None else np.round(lmxy[a:b], 2),
        }
        if other is not None:
            j = bidx[a:b]
            has = j >= 0
            ocols = [c for c in other.frame.columns if not re.match(r"^lm\d+_[xyz]$", c)]
            sub = other.frame.iloc[j[has]]
            d["other_cols"] = ocols
            d["other_values"] = {c: _scatter(sub[c].tolist(), has) for c in ocols}
            d["other_src"] = _scatter([other.where(int(i)) for i in j[has]], has)
        (folder / "rows" / f"{k:05d}.js").write_bytes(b"HPE_VIEW_ROWS(" + str(k).encode() + b"," + _dumps(d) + b");\n")

    assets = ir.files("hpe_cli.data") / "view"
    for name in ASSETS:
        text = (assets / name).read_text(encoding="utf-8")
        if name == "index.html":
            import html

            text = text.replace("{{title}}", html.escape(str(title)))
        (folder / name).write_text(text, encoding="utf-8")


def _scatter(values, has) -> list:
    out = [None] * len(has)
    for i, v in zip(np.flatnonzero(has), values):
        out[i] = v
    return out
