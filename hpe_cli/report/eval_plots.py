"""``hpe evaluate --plots``: error against GT yaw, geodesic CDF, error histograms and an HTML page.

Every file is written atomically (:class:`hpe_cli.io.writers.AtomicFile`).
``rows`` is what ``hpe evaluate`` keeps for plots: every pair up to 400,000 pairs, beyond that every k-th pair
(``rows.step``, k a power of two; :class:`hpe_cli.pipelines.evaluate.outputs.Sample`), and the figures say so.
Scatter plots show at most :data:`MAX_POINTS` of those rows (a fixed-seed sample); bin medians, the CDF and
the histograms use every row handed in. The report's numbers always use all pairs.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ..errors import HpeError
from ..io.writers import AtomicFile, check_output

MAX_POINTS = 20_000
EVAL_PLOT_FILES = {
    "error_vs_yaw": "error_vs_yaw.png",
    "geodesic_cdf": "geodesic_cdf.png",
    "error_hist": "error_hist.png",
    "html": "index.html",
}


def eval_plot_files(folder) -> dict:
    folder = Path(folder)
    return {k: folder / v for k, v in EVAL_PLOT_FILES.items()}


def check_plot_outputs(folder, overwrite: bool) -> None:
    """Fail early (before any work) if the plots folder cannot be written."""

    folder = Path(folder)
    if not folder.parent.exists():
        raise HpeError(f"{folder}: folder {folder.parent} does not exist")
    if folder.exists():
        if not folder.is_dir():
            raise HpeError(f"{folder}: exists and is not a folder")
        for p in eval_plot_files(folder).values():
            check_output(p, overwrite)


def _save(fig, path, overwrite):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with AtomicFile(path, overwrite) as tmp:
        fig.savefig(tmp, format="png", dpi=100)


def _bin_medians(x, y, edges):
    idx = np.searchsorted(edges, x, side="right") - 1
    idx = np.clip(idx, 0, len(edges) - 2)
    centres, med = [], []
    order = np.argsort(idx, kind="stable")
    si, sy = idx[order], y[order]
    bounds = np.searchsorted(si, np.arange(len(edges)))
    for k in range(len(edges) - 1):
        seg = sy[bounds[k] : bounds[k + 1]]
        if seg.size:
            centres.append(0.5 * (edges[k] + edges[k + 1]))
            med.append(float(np.median(seg)))
    return np.asarray(centres), np.asarray(med)


def _drawn(rows) -> str:
    """What the figures are drawn from: all pairs, or every k-th pair (a sample)."""
    step = getattr(rows, "step", 1)
    return f"{rows.n} pairs" if step == 1 else f"sample: every {step}-th pair, {rows.n} pairs"


def write_eval_plots(folder, rows, report: dict, gt_system, overwrite: bool = False) -> dict:
    """Write the three figures and ``index.html`` into ``folder`` (created if missing)."""
    from matplotlib.figure import Figure

    folder = Path(folder)
    check_plot_outputs(folder, overwrite)
    folder.mkdir(exist_ok=True)
    paths = eval_plot_files(folder)
    n = rows.n
    rng = np.random.default_rng(0)
    pick = np.sort(rng.choice(n, MAX_POINTS, replace=False)) if n > MAX_POINTS else np.arange(n)
    yaw = rows.gt_angles[:, 1]
    lo, hi = gt_system.ranges.get("yaw", (-180.0, 180.0))
    edges = np.linspace(lo, hi, max(2, int(round((hi - lo) / 5.0)) + 1))

    fig = Figure(figsize=(11, 7))
    series = [("geodesic", rows.geodesic)] + [
        (f"{a} error (wrapped)", rows.mae_wrapped[:, k]) for k, a in enumerate(("pitch", "yaw", "roll"))
    ]
    for k, (name, err) in enumerate(series):
        ax = fig.add_subplot(2, 2, k + 1)
        if n:
            ax.scatter(
                yaw[pick],
                err[pick],
                s=(3 if len(pick) > 2000 else 14),
                alpha=(0.3 if len(pick) > 2000 else 0.7),
                color="#3b6ea8",
                linewidths=0,
            )
            c, m = _bin_medians(yaw, err, edges)
            ax.plot(c, m, color="#c0392b", linewidth=1.5, label="median per 5-degree bin")
            ax.legend(fontsize=8, loc="upper left")
        ax.set_xlim(lo, hi)
        ax.set_xlabel(f"GT yaw (degrees, {gt_system.name})")
        ax.set_ylabel(f"{name} (degrees)")
    points = f", points: sample of {len(pick)}" if n > MAX_POINTS else ""
    fig.suptitle(f"errors against GT yaw ({_drawn(rows)}{points})", fontsize=10)
    fig.tight_layout()
    _save(fig, paths["error_vs_yaw"], overwrite)

    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.add_subplot(1, 1, 1)
    if n:
        g = np.sort(rows.geodesic)
        ax.plot(g, np.arange(1, n + 1) / n, color="#3b6ea8")
        for t in (5, 10, 15, 30):
            ax.axvline(t, color="#999", linestyle=":", linewidth=1)
        ax.set_xlim(0, max(30.0, float(np.percentile(g, 99))))
    ax.set_ylim(0, 1)
    ax.set_xlabel("geodesic error (degrees)")
    ax.set_ylabel("fraction of pairs within")
    ax.set_title(f"geodesic error CDF ({_drawn(rows)})", fontsize=10)
    fig.tight_layout()
    _save(fig, paths["geodesic_cdf"], overwrite)

    fig = Figure(figsize=(11, 3.4))
    for k, a in enumerate(("pitch", "yaw", "roll")):
        ax = fig.add_subplot(1, 3, k + 1)
        if n:
            ax.hist(rows.mae_wrapped[:, k], bins=np.linspace(0, 180, 181), color="#3b6ea8", log=True)
        ax.set_xlim(0, 180)
        ax.set_xlabel(f"{a} error (degrees, wrapped, {gt_system.name})")
        if k == 1:
            ax.set_title(_drawn(rows), fontsize=9)
        ax.set_ylabel("pairs")
    fig.tight_layout()
    _save(fig, paths["error_hist"], overwrite)

    with AtomicFile(paths["html"], overwrite) as tmp:
        tmp.write_text(_page(report, paths), encoding="utf-8")
    return paths


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.3f}"
    return html.escape(str(v))


def _page(report: dict, paths: dict) -> str:
    n = report["n"]
    counts = "".join(f"<tr><th>{html.escape(k)}</th><td>{v}</td></tr>" for k, v in n.items())
    m = report["metrics"]
    mrows = []
    for name, block in m.items():
        mrows.append(f"<tr><th>{name}</th><td>" + ", ".join(f"{k} {_fmt(v)}" for k, v in block.items()) + "</td></tr>")
    prows = []
    for name, p in report.get("protocols", {}).items():
        prows.append(
            "<tr>"
            + "".join(
                f"<td>{_fmt(x)}</td>"
                for x in (
                    name,
                    p.get("n"),
                    p.get("dropped"),
                    p.get("pitch"),
                    p.get("yaw"),
                    p.get("roll"),
                    p.get("mean"),
                    p.get("source"),
                    "; ".join(p.get("notes", [])),
                )
            )
            + "</tr>"
        )
    imgs = "\n".join(
        f'<figure><img src="{html.escape(paths[k].name)}" alt="{k}"><figcaption>{k}</figcaption></figure>'
        for k in ("error_vs_yaw", "geodesic_cdf", "error_hist")
    )
    sysline = html.escape(f"pred system {report['systems']['pred']}, GT system {report['systems']['gt']}")
    al = report.get("align", {})
    align = ""
    if al.get("method") == "mean":
        align = (
            f"<p>aligned: constant offset of {al['offset_deg']:.3f} degrees removed "
            f"({html.escape(', '.join(f'{k} {v:.3f}' for k, v in al['offset_angles'].items()))})</p>"
        )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>hpe evaluate</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:90em}} table{{border-collapse:collapse;margin:1em 0}}
th,td{{border:1px solid #ccc;padding:.2em .6em;text-align:left}}
figure{{display:inline-block;margin:.5em}} img{{max-width:60em}}</style></head>
<body><h1>hpe evaluate</h1><p>{sysline}</p>{align}
<table>{counts}</table>
<h2>Metrics (degrees; frobenius unitless)</h2><table>{"".join(mrows)}</table>
<h2>Protocols</h2><table><tr><th>protocol</th><th>n</th><th>dropped</th><th>pitch</th><th>yaw</th><th>roll</th>
<th>mean</th><th>source</th><th>notes</th></tr>{"".join(prows)}</table>
{imgs}
</body></html>
"""
