"""The ``--consistency`` page of ``hpe audit --plots``: counts, score distributions, cameras, worst rows drawn.

Written as ``consistency/index.html`` in the plots folder with ``scores.png``
(histograms of the landmark angle, the view angle and the score) and the pictures
of :mod:`hpe_cli.pipelines.draw.consistency`. Pure formatting: the caller stages the files.
"""

from __future__ import annotations

import html


def score_figure(hists: dict, path) -> None:
    """Histograms of ``landmark_angle``, ``view_angle`` and ``consistency_score`` as a PNG.

    ``hists``: ``{column: {"counts", "edges", "median", "n"} or None}``, binned by
    the caller (:func:`hpe_cli.pipelines.draw.consistency.score_histograms`).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 3.2))
    FigureCanvasAgg(fig)
    for k, (col, unit) in enumerate(
        (("landmark_angle", "degrees"), ("view_angle", "degrees"), ("consistency_score", "x expected"))
    ):
        ax = fig.add_subplot(1, 3, k + 1)
        h = hists.get(col)
        if h:
            ax.stairs(h["counts"], h["edges"], fill=True, color="#34699a")
            ax.axvline(h["median"], color="#c0392b", linewidth=1)
        ax.set_title(f"{col}: {h['n'] if h else 0} rows (red: median)", fontsize=9)
        ax.set_xlabel(unit)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def page_html(title: str, report: dict, pictures: dict) -> str:
    """The page: the report's counts and settings, the histograms, the named cameras, the drawn rows."""
    e = html.escape
    top = {k: report[k] for k in ("rows", "checked", "not_checked", "suspects")}
    lm, views, time = report.get("landmarks", {}), report.get("views", {}), report.get("time", {})
    top["landmarks"] = (
        f"{lm.get('checked', 0)} checked ({lm.get('scheme')}; median {lm.get('angle_deg', {}).get('median')} deg)"
    )
    top["views"] = f"{views.get('checked', 0)} checked" + (f" ({views['reason']})" if views.get("reason") else "")
    top["time"] = f"{time.get('checked', 0)} checked" + (f" ({time['reason']})" if time.get("reason") else "")
    rows = "\n".join(f"<tr><th>{e(str(k))}</th><td>{e(str(v))}</td></tr>" for k, v in top.items())
    why = "\n".join(f"<li>{e(k)}: {v}</li>" for k, v in report.get("not_checked_reasons", {}).items())
    cams = views.get("cameras", [])
    cam_rows = "\n".join(
        f"<tr><th>{e(str(c['camera']))}</th><td>{c['rows']}</td><td>{c['offset_deg']:.3g}</td>"
        f"<td>{e(str(c['rotvec_deg']))}</td><td>{'yes' if c['significant'] else ''}</td></tr>"
        for c in cams
    )
    cam_table = (
        "<h2>Cameras: median offset of their labels from the consensus</h2><table><tr><th>camera</th><th>rows</th>"
        f"<th>offset (deg)</th><th>rotation vector (deg)</th><th>named</th></tr>{cam_rows}</table>"
        if cams
        else ""
    )
    figs = "\n".join(
        f'<figure><a href="{e(p["path"])}"><img class="row" src="{e(p["path"])}" alt="{e(p["caption"])}"></a>'
        f"<figcaption>{e(p['caption'])}</figcaption></figure>"
        for p in pictures.get("pictures", [])
    )
    missing = "\n".join(f"<li>{e(w)}: {e(r)}</li>" for w, r in pictures.get("missing", []))
    s = report.get("settings", {})
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:75em}} table{{border-collapse:collapse}}
th,td{{border:1px solid #ccc;padding:.2em .6em;text-align:left}}
figure{{display:inline-block;margin:.5em;vertical-align:top}} img{{max-width:60em}}
img.row{{max-width:22em;max-height:22em}} figcaption{{font-size:.85em;max-width:24em}}</style></head>
<body><h1>{e(title)}</h1>
<p>Each label against independent evidence: its 2-D landmarks ({e(str(lm.get("model")))}; {e(str(lm.get("points")))}),
the other calibrated views of the head, its neighbours in time. Score: {e(str(s.get("score")))}; suspects score
above {s.get("suspect_score")}. Rows no check applies to are not checked, never consistent.</p>
<table>
{rows}
</table>
{"<h2>Not checked</h2><ul>" + why + "</ul>" if why else ""}
<figure><img src="scores.png" alt="score distributions"></figure>
{cam_table}
<h2>Worst rows</h2>
<p>Solid: the label's axes; dashed: the rotation fitted to the landmarks (white dots); red to the subject's
left, green forehead to chin, blue out of the nose.</p>
{figs or "<p>No suspects.</p>"}
{"<p>Not drawn:</p><ul>" + missing + "</ul>" if missing else ""}
</body></html>
"""
