"""``hpe evaluate --report FILE.html``: one self-contained page people would rather read than the JSON.

Every protocol with its unit and source (``repo@commit file:lines``), the
counts of missing, invalid, unmatched, unreadable and re-expressed rows, the
core metrics, the ``--by`` and ``--yaw-bins`` tables, three plots and the worst
rows (with the pictures of GT and prediction drawn on the face when the
caller supplies them). Figures and pictures are embedded as data URIs, so the
page is one file; it is written atomically.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from ..io.writers import AtomicFile
from .evaluate_text import same_rotation_notes

UNITS = {"geodesic": "deg", "maev": "deg", "frobenius": "unitless", "mae_wrapped": "deg", "mae_best_of_two": "deg"}
ANGLES = ("pitch", "yaw", "roll")
#: rows per --by / --yaw-bins table on the page (the JSON report holds every group)
MAX_GROUPS = 500
_SKIP = {"n", "dropped", "pitch", "yaw", "roll", "mean", "system", "source", "notes", "units", "re_expressed"}


def _f(v, digits=3) -> str:
    if v is None:
        return "&ndash;"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float):
        return "NaN" if np.isnan(v) else f"{v:.{digits}f}"
    return html.escape(str(v))


def _table(head, rows, cls="") -> str:
    h = "".join(f"<th>{x}</th>" for x in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f'<div class="wrap"><table class="{cls}"><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table></div>'


def _counts(result) -> str:
    n = result["n"]
    rows = [[html.escape(k.replace("_", " ")), _f(v)] for k, v in n.items()]
    rx = []
    for name, p in result.get("protocols", {}).items():
        r = p.get("re_expressed")
        if r:
            rx.append(f"{html.escape(name)}: " + ", ".join(f"{s} {_f(v)}" for s, v in r.items()))
    if rx:
        rows.append(["re-expressed (rows whose written angles the protocol had to convert)", "<br>".join(rx)])
    return _table(["rows", "count"], rows, "counts")


def _metrics(m) -> str:
    rows = []
    g = m["geodesic"]
    rows.append(
        [
            "geodesic",
            "deg",
            _f(g["mean"]),
            f"median {_f(g['median'])}, p90 {_f(g['p90'])}, p95 "
            f"{_f(g['p95'])}, max {_f(g['max'])}; within 5/10/15/30 deg: "
            + " / ".join(_f(g[f"within_{t}"]) for t in (5, 10, 15, 30)),
        ]
    )
    mv = m["maev"]
    rows.append(
        ["maev (axis angles)", "deg", _f(mv["mean"]), ", ".join(f"{a} {_f(mv[a])}" for a in ("left", "down", "front"))]
    )
    rows.append(["frobenius ||I - P G<sup>T</sup>||<sub>F</sub>", "unitless", _f(m["frobenius"]["mean"]), ""])
    for k in ("mae_wrapped", "mae_best_of_two"):
        e = m[k]
        rows.append([k, "deg", _f(e["mean"]), ", ".join(f"{a} {_f(e[a])}" for a in ANGLES)])
    return _table(["metric", "unit", "mean", "detail"], rows)


def _extras(p) -> str:
    out = []
    for k, v in p.items():
        if k in _SKIP:
            continue
        if isinstance(v, dict):
            inner = ", ".join(f"{kk} {_f(vv)}" for kk, vv in v.items())
            out.append(f"<b>{html.escape(k)}</b>: {inner}")
        else:
            out.append(f"<b>{html.escape(k)}</b> {_f(v)}")
    return "<br>".join(out)


def _protocols(protocols) -> str:
    rows = []
    for name, p in protocols.items():
        unit = p.get("units", "deg")
        ang = [_f(p.get(a)) for a in ANGLES] if unit != "unitless" else ["&ndash;"] * 3
        mean = _f(p.get("mean"), 4 if unit == "unitless" else 3)
        rx = p.get("re_expressed")
        rxs = ", ".join(f"{s} {_f(v)}" for s, v in rx.items()) if rx else "&ndash;"
        notes = "".join(f'<div class="note">{html.escape(x)}</div>' for x in p.get("notes", []))
        rows.append(
            [
                f"<b>{html.escape(name)}</b>",
                html.escape(unit),
                *ang,
                mean,
                _f(p.get("n")),
                _f(p.get("dropped")),
                rxs,
                _extras(p),
                f"<code>{html.escape(p.get('source', ''))}</code>{notes}",
            ]
        )
    return _table(
        [
            "protocol",
            "unit",
            "pitch",
            "yaw",
            "roll",
            "mean",
            "n",
            "dropped",
            "re-expressed",
            "extras",
            "source (repo@commit file:lines)",
        ],
        rows,
        "protocols",
    )


#: protocol columns per table of a --by / --yaw-bins section (the first also has the six metric columns): more
#: continue in further tables, so a 1280-px window needs no sideways scroll (tests/evaluate: headless Chromium)
PROTOCOLS_PER_TABLE, PROTOCOLS_FIRST_TABLE = 7, 3


def _group_table(label, groups, protocols) -> str:
    names = list(protocols)
    groups = list(groups)
    first, rest = names[:PROTOCOLS_FIRST_TABLE], names[PROTOCOLS_FIRST_TABLE:]
    blocks = [first] + [rest[i : i + PROTOCOLS_PER_TABLE] for i in range(0, len(rest), PROTOCOLS_PER_TABLE)]
    tables = []
    for b, block in enumerate(blocks):
        fixed = ["n", "geodesic mean (deg)", "median", "p90", "mae_wrapped (deg)", "maev (deg)"] if b == 0 else []
        head = (
            [html.escape(label)]
            + fixed
            + [f"{html.escape(n)} ({'unitless' if protocols[n].get('units') == 'unitless' else 'deg'})" for n in block]
        )
        rows = []
        for key, s in groups[:MAX_GROUPS]:
            g = s["metrics"]["geodesic"]
            first = (
                [
                    _f(s["n"]),
                    _f(g["mean"]),
                    _f(g["median"]),
                    _f(g["p90"]),
                    _f(s["metrics"]["mae_wrapped"]["mean"]),
                    _f(s["metrics"]["maev"]["mean"]),
                ]
                if b == 0
                else []
            )
            rows.append([html.escape(str(key))] + first + [_f(s["protocols"][n].get("mean")) for n in block])
        tables.append(_table(head, rows, "groups"))
    more = len(groups) - MAX_GROUPS
    note = f"<p class='note'>{more:,} more groups: see the JSON report</p>" if more > 0 else ""
    return "".join(tables) + note


def _png(fig) -> str:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _figures(sample, gt_system_name) -> str:
    """Error against GT yaw, geodesic CDF and per-angle error histograms, from the (sampled) per-row errors."""
    from matplotlib.figure import Figure

    if sample is None or not sample.n:
        return ""
    yaw, geo, err = sample.gt_angles[:, 1], sample.geodesic, sample.mae_wrapped
    rng = np.random.default_rng(0)
    pick = rng.choice(len(geo), min(len(geo), 20_000), replace=False) if len(geo) > 20_000 else slice(None)
    figs = []
    fig = Figure(figsize=(6.4, 3.6))
    ax = fig.add_subplot()
    ax.scatter(yaw[pick], geo[pick], s=4, alpha=0.5, color="#3b6ea8")
    ax.set_xlabel(f"GT yaw ({gt_system_name}, deg)")
    ax.set_ylabel("geodesic error (deg)")
    ax.set_ylim(0, max(1.0, float(geo[pick].max()) * 1.05 if len(geo) else 1.0))  # rounding noise reads as 0
    ax.set_title("error against GT yaw")
    figs.append(("error against GT yaw", _png(fig)))
    fig = Figure(figsize=(6.4, 3.6))
    ax = fig.add_subplot()
    g = np.sort(geo)
    ax.plot(g, np.arange(1, len(g) + 1) / len(g), color="#3b6ea8")
    ax.set_xlabel("geodesic error (deg)")
    ax.set_ylabel("fraction of pairs")
    ax.set_xlim(0, max(1.0, float(np.percentile(g, 99))))
    ax.grid(alpha=0.3)
    ax.set_title("geodesic error CDF")
    figs.append(("geodesic CDF", _png(fig)))
    fig = Figure(figsize=(6.4, 3.6))
    ax = fig.add_subplot()
    for k, (a, c) in enumerate(zip(ANGLES, ("#c0392b", "#27ae60", "#2c3e50"))):
        ax.hist(err[:, k], bins=np.linspace(0, 180, 91), histtype="step", color=c, label=a, log=True)
    ax.set_xlabel("wrapped per-angle error (deg)")
    ax.set_ylabel("pairs")
    ax.legend()
    ax.set_title("per-angle error histogram")
    figs.append(("per-angle errors", _png(fig)))
    note = (
        ""
        if getattr(sample, "step", 1) == 1
        else f"<p class='note'>plots drawn from every {sample.step}-th pair ({sample.n:,} pairs); numbers use all pairs</p>"
    )
    return note + "".join(
        f'<figure><img src="{src}" alt="{html.escape(t)}"><figcaption>{html.escape(t)}</figcaption></figure>'
        for t, src in figs
    )


def _worst(frame, pictures, systems=None) -> str:
    """The worst rows: keys, GT and predicted angles (GT system, deg), errors, and the picture when drawn.

    The prediction is shown re-expressed by hpe in the GT system (the same rotation, stated as the GT system's
    primary Euler solution), so the per-angle errors compare like with like; when the frame carries the values
    as written (``pred_written_pitch``...), they are shown beside it.
    """
    if frame is None or not len(frame):
        return "<p>no rows</p>"
    cols = list(frame.columns)
    keys = [
        c
        for c in cols
        if c
        not in {
            "gt_pitch",
            "gt_yaw",
            "gt_roll",
            "pred_pitch",
            "pred_yaw",
            "pred_roll",
            "err_pitch",
            "err_yaw",
            "err_roll",
            "geodesic",
            "maev_left",
            "maev_down",
            "maev_front",
            "frobenius",
            "image_path",
            "pred_rotation_distance",
            "pred_written_pitch",
            "pred_written_yaw",
            "pred_written_roll",
            "bbox_x",
            "bbox_y",
            "bbox_w",
            "bbox_h",
            "tdx",
            "tdy",
            "size",
        }
    ]
    gsys = html.escape((systems or {}).get("gt", "GT system"))
    psys = html.escape((systems or {}).get("pred", "its system"))
    written = all(f"pred_written_{a}" in cols for a in ANGLES)
    head = (
        ["#"]
        + [html.escape(k) for k in keys]
        + [f"GT p / y / r (deg, {gsys})"]
        + ([f"pred as written p / y / r ({psys})"] if written else [])
        + [
            f"pred p / y / r (deg, re-expressed by hpe in {gsys})",
            "err p / y / r (deg, wrapped)",
            "geodesic (deg)",
            "frobenius (unitless)",
            "picture",
        ]
    )
    rows = []
    for i in range(len(frame)):
        r = frame.iloc[i]
        pic = pictures[i] if pictures and i < len(pictures) and pictures[i] else None
        img = (
            f'<img class="pic" src="{pic}" alt="row {i + 1}">'
            if pic
            else (
                f"<span class='note'>{html.escape(str(r['image_path']))}</span>"
                if "image_path" in cols and r["image_path"]
                else "&ndash;"
            )
        )
        rows.append(
            [str(i + 1)]
            + [_f(r[k]) for k in keys]
            + [" / ".join(_f(float(r[f"{s}_{a}"]), 1) for a in ANGLES) for s in ("gt",)]
            + ([" / ".join(_f(float(r[f"pred_written_{a}"]), 1) for a in ANGLES)] if written else [])
            + [" / ".join(_f(float(r[f"{s}_{a}"]), 1) for a in ANGLES) for s in ("pred", "err")]
            + [f"<b>{_f(float(r['geodesic']))}</b>", _f(float(r["frobenius"]), 4), img]
        )
    return _table(head, rows, "worst")


CSS = """body{font-family:system-ui,sans-serif;margin:1.5em;max-width:110em;color:#222}
h1{margin-bottom:.2em} h2{margin-top:1.6em;border-bottom:2px solid #3b6ea8}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
th,td{border:1px solid #ccc;padding:.25em .55em;text-align:left;vertical-align:top}
th{background:#eef3fa} td code{font-size:.85em;color:#444}
.note{color:#666;font-size:.85em} .wrap{overflow-x:auto} .pic{max-width:260px;max-height:260px}
figure{display:inline-block;margin:.4em} figure img{max-width:36em}"""


def page_html(result: dict, worst=None, pictures=None, sample=None) -> str:
    """The page as a string (see the module docstring)."""
    sysline = (
        f"predictions <code>{html.escape(result['inputs']['pred'])}</code> ({html.escape(result['systems']['pred'])})"
        f" against ground truth <code>{html.escape(result['inputs']['gt'])}</code> "
        f"({html.escape(result['systems']['gt'])}); key: {html.escape(str(result['inputs']['key']))}"
    )
    al = result.get("align", {})
    align = ""
    if al.get("method") == "mean":
        align = (
            f"<p>aligned (--align mean, {html.escape(al.get('estimate', ''))}): removed "
            f"{al['offset_deg']:.3f} deg ("
            + ", ".join(f"{k} {v:.3f}" for k, v in al["offset_angles"].items())
            + f" in {html.escape(al['gt_system'])})</p>"
        )
    parts = [
        f"<h1>hpe evaluate</h1><p>{sysline}</p>{align}",
        "<h2>Rows</h2>",
        _counts(result),
        "<h2>Metrics</h2>",
        _metrics(result["metrics"]),
        (
            "<h2>Protocols</h2><p class='note'>each reproduces its peer's current evaluation code, named with "
            "repo@commit file:lines; raw-angle protocols compare the angles as written</p>"
        ),
        _protocols(result.get("protocols", {})),
    ]
    if result.get("by"):
        by = result["by"]
        parts += [
            f"<h2>By {html.escape(by['column'])}</h2>",
            _group_table(by["column"], by["groups"].items(), result["protocols"]),
        ]
    if result.get("yaw_bins"):
        parts += [
            "<h2>By GT yaw</h2>",
            _group_table(
                "GT yaw (deg)", [(f"[{b['lo']:g}, {b['hi']:g})", b) for b in result["yaw_bins"]], result["protocols"]
            ),
        ]
    figs = _figures(sample, result["systems"]["gt"])
    if figs:
        parts += ["<h2>Plots</h2>", figs]
    if worst is not None:
        parts += [
            f"<h2>Worst {len(worst)} rows (largest geodesic error)</h2>",
            "<p class='note'>the prediction is re-expressed by hpe in the GT system "
            f"({html.escape(result['systems']['gt'])}): the same rotation, stated as that system's primary Euler "
            "solution, so the per-angle errors compare like with like (a value past the range, e.g. yaw 107 in a "
            "[-90, 90] system, reads as the other solution, e.g. -141.7 / 72.6 / -158.9 for 38.3 / 107.4 / 21.1); "
            "the geodesic error does not depend on how a rotation is written. Which protocol re-expressed rows "
            "for its own score is in the protocols table (re-expressed)"
            + ("; pictures: GT and prediction drawn on the face" if pictures and any(pictures) else "")
            + "</p>",
            _worst(worst, pictures, result.get("systems")),
        ]

    notes = same_rotation_notes(result) + list(result.get("notes", []))
    if notes or result.get("rejects"):
        parts.append(
            "<h2>Notes</h2><ul>"
            + "".join(f"<li>{html.escape(n)}</li>" for n in notes)
            + "".join(f"<li>rejected: {html.escape(k)}: {v}</li>" for k, v in result.get("rejects", {}).items())
            + "</ul>"
        )
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>hpe evaluate</title>'
        f"<style>{CSS}</style></head><body>\n" + "\n".join(parts) + "\n</body></html>\n"
    )


def write_page(path, result: dict, worst=None, *, overwrite: bool = False, plots=None, pictures=None) -> None:
    """Write the page atomically; ``worst`` is a pandas DataFrame or pyarrow Table of the worst rows."""

    if worst is not None and not hasattr(worst, "iloc"):
        worst = worst.to_pandas()
    text = page_html(result, worst, pictures, plots)
    with AtomicFile(path, overwrite) as tmp:
        tmp.write_text(text, encoding="utf-8")


def data_uri(path) -> str:
    """A picture file as a data URI (for :func:`write_page`'s ``pictures``)."""

    p = Path(path)
    kind = "png" if p.suffix.lower() == ".png" else "jpeg"
    return f"data:image/{kind};base64," + base64.b64encode(p.read_bytes()).decode("ascii")
