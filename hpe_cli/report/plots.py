"""Audit plots: angle histograms, a yaw-pitch coverage map and an HTML page.

Histograms are accumulated batch by batch (:class:`AngleHistograms`), so a
table of any length is plotted in constant memory. Every file is staged in
the run's output transaction (committed with the run's other outputs, or
alone when there is none).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError
from ..io.writers import AtomicFile, check_output

#: histogram bin edges, degrees: 1-degree bins over [-180, 180]
EDGES_1D = np.linspace(-180.0, 180.0, 361)
#: coverage-map bin edges, degrees: 2-degree bins
EDGES_2D = np.linspace(-180.0, 180.0, 181)

PLOT_FILES = {
    "yaw": "yaw_hist.png",
    "pitch": "pitch_hist.png",
    "roll": "roll_hist.png",
    "coverage": "yaw_pitch_coverage.png",
    "html": "index.html",
}


class AngleHistograms:
    """Running histograms of ``(pitch, yaw, roll)`` in degrees.

    Values outside [-180, 180] are counted in ``outside`` (per angle) and
    left out of the bins; non-finite values are ignored.
    """

    def __init__(self):
        self.counts = {r: np.zeros(len(EDGES_1D) - 1, dtype=np.int64) for r in ("pitch", "yaw", "roll")}
        self.outside = {r: 0 for r in ("pitch", "yaw", "roll")}
        self.coverage = np.zeros((len(EDGES_2D) - 1, len(EDGES_2D) - 1), dtype=np.int64)  # [yaw, pitch]
        self.n = 0

    def add(self, pyr) -> None:
        pyr = np.asarray(pyr, dtype=np.float64).reshape(-1, 3)
        pyr = pyr[np.isfinite(pyr).all(axis=1)]
        self.n += len(pyr)
        for n, r in enumerate(("pitch", "yaw", "roll")):
            v = pyr[:, n]
            inside = (v >= -180.0) & (v <= 180.0)
            self.outside[r] += int((~inside).sum())
            self.counts[r] += np.histogram(v[inside], EDGES_1D)[0]
        ok = (np.abs(pyr[:, :2]) <= 180.0).all(axis=1)
        self.coverage += np.histogram2d(pyr[ok, 1], pyr[ok, 0], [EDGES_2D, EDGES_2D])[0].astype(np.int64)


def _save(fig, path, overwrite):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with AtomicFile(path, overwrite) as tmp:
        fig.savefig(tmp, format="png", dpi=100)


def plot_files(folder) -> dict:
    """Output paths of :func:`write_plots` in ``folder``."""
    folder = Path(folder)
    return {k: folder / v for k, v in PLOT_FILES.items()}


def write_plots(
    hist: AngleHistograms,
    folder,
    system,
    summary: dict,
    title: str = "hpe audit",
    overwrite: bool = False,
    pictures=None,
) -> dict:
    """Write the three histograms, the coverage map and ``index.html``.

    Parameters
    ----------
    hist : AngleHistograms
    folder : path
        Created if missing (its parent must exist).
    system : RotationSystem
        Its declared ranges are drawn as dashed lines.
    summary : dict
        Shown on the HTML page: check name -> count (and any other scalars).
    pictures : dict, optional
        Drawn flagged rows (:func:`hpe_cli.pipelines.draw.flagged_pictures`): shown on the page by
        check, each linking to its PNG; rows whose image was not found are listed.
    """
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    folder = Path(folder)
    if not folder.parent.exists():
        raise HpeError(f"{folder}: folder {folder.parent} does not exist")
    paths = plot_files(folder)
    if folder.exists():
        for p in paths.values():
            check_output(p, overwrite)
    for role in ("yaw", "pitch", "roll"):
        fig = Figure(figsize=(7, 3.2))
        ax = fig.add_subplot(1, 1, 1)
        ax.stairs(hist.counts[role], EDGES_1D, fill=True, color="#3b6ea8")
        lo, hi = system.ranges.get(role, (-180.0, 180.0))
        for v in (lo, hi):
            ax.axvline(v, color="#c0392b", linestyle="--", linewidth=1)
        ax.set_xlim(-180, 180)
        ax.set_xticks(np.arange(-180, 181, 45))
        ax.set_xlabel(f"{role} (degrees, {system.name}); dashed: declared range [{lo:g}, {hi:g}]")
        ax.set_ylabel("rows")
        extra = f", {hist.outside[role]} outside [-180, 180] not shown" if hist.outside[role] else ""
        ax.set_title(f"{role}: {hist.n} rows{extra}", fontsize=10)
        fig.tight_layout()
        _save(fig, paths[role], overwrite)
    fig = Figure(figsize=(6.4, 5.6))
    ax = fig.add_subplot(1, 1, 1)
    cov = hist.coverage.T.astype(float)  # rows = pitch, columns = yaw
    masked = np.ma.masked_where(cov == 0, cov)
    norm = LogNorm(vmin=1, vmax=max(1.0, cov.max())) if cov.max() > 1 else None
    im = ax.pcolormesh(EDGES_2D, EDGES_2D, masked, cmap="viridis", norm=norm, shading="flat")
    fig.colorbar(im, ax=ax, label="rows per 2x2 degree cell")
    (ylo, yhi), (plo, phi) = system.ranges.get("yaw", (-180, 180)), system.ranges.get("pitch", (-180, 180))
    ax.plot([ylo, yhi, yhi, ylo, ylo], [plo, plo, phi, phi, plo], "--", color="#c0392b", linewidth=1)
    ax.set_xlim(-180, 180)
    ax.set_ylim(-180, 180)
    ax.set_xticks(np.arange(-180, 181, 45))
    ax.set_yticks(np.arange(-180, 181, 45))
    ax.set_xlabel("yaw (degrees)")
    ax.set_ylabel("pitch (degrees)")
    ax.set_title(f"yaw-pitch coverage ({system.name}); dashed: declared range", fontsize=10)
    fig.tight_layout()
    _save(fig, paths["coverage"], overwrite)
    with AtomicFile(paths["html"], overwrite) as tmp:
        tmp.write_text(_page(title, summary, paths, pictures), encoding="utf-8")
    return paths


def _gallery(pictures) -> str:
    """The page's section of drawn flagged rows, by check; each picture links to its PNG."""
    if not pictures or not (pictures.get("pictures") or pictures.get("missing")):
        return ""
    import html  # lazy: start-up (html.entities), only a page needs it

    e = html.escape
    parts = [
        "<h2>Flagged rows, drawn</h2>",
        (
            "<p>The first rows of each check on their images: red points to the subject's left, green from "
            "forehead to chin, blue out of the nose. Each picture links to its PNG.</p>"
        ),
    ]
    by_check: dict = {}
    for p in pictures.get("pictures", []):
        by_check.setdefault(p["check"], []).append(p)
    for check, pics in by_check.items():
        figs = "\n".join(
            f'<figure><a href="{e(p["path"])}"><img class="row" src="{e(p["path"])}" '
            f'alt="{e(p["caption"])}"></a><figcaption>{e(p["caption"])}</figcaption></figure>'
            for p in pics
        )
        parts.append(f'<h3 id="check-{e(check)}">{e(check)}</h3>\n{figs}')
    missing = pictures.get("missing", [])
    if missing:
        items = "\n".join(f"<li>{e(c)}: {e(w)}: {e(r)}</li>" for c, w, r in missing)
        parts.append(f"<p>Not drawn (images under {e(str(pictures.get('root', '')))}):</p><ul>{items}</ul>")
    return "\n".join(parts)


def _page(title, summary, paths, pictures=None) -> str:
    import html  # lazy: start-up (html.entities), only a page needs it

    drawn = {p["check"] for p in (pictures or {}).get("pictures", [])}

    def cell(k, v):  # a check with pictures links to them
        text = html.escape(str(v))
        return f'<a href="#check-{html.escape(str(k))}">{text}</a>' if k in drawn else text

    rows = "\n".join(f"<tr><th>{html.escape(str(k))}</th><td>{cell(k, v)}</td></tr>" for k, v in summary.items())
    imgs = "\n".join(
        f'<figure><img src="{html.escape(paths[k].name)}" alt="{k}"><figcaption>{k}</figcaption></figure>'
        for k in ("yaw", "pitch", "roll", "coverage")
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:75em}} table{{border-collapse:collapse}}
th,td{{border:1px solid #ccc;padding:.2em .6em;text-align:left}} td{{text-align:right}}
figure{{display:inline-block;margin:.5em;vertical-align:top}} img{{max-width:44em}}
img.row{{max-width:20em;max-height:20em}} figcaption{{font-size:.85em;max-width:24em}}</style></head>
<body><h1>{html.escape(title)}</h1>
<table>
{rows}
</table>
{imgs}
{_gallery(pictures)}
</body></html>
"""
