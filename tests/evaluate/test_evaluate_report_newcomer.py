"""What the README tour's ``hpe evaluate`` shows a newcomer: why identical rotations score under Euler protocols,
no join internals unless -v, a yaw-bin table on every --report page, tables that need no sideways scroll, and
the worst rows saying who re-expressed the prediction (and the values as written when the rows carry them)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

from conftest import hpe as hpe_cmd
from hpe_cli.report.evaluate_page import page_html
from hpe_cli.report.evaluate_text import WIDTH, same_rotation_notes

ROOT = Path(__file__).resolve().parents[2]
LABELS = ROOT / "sample_data" / "labels_300wlp.csv"
AFLW = ROOT / "sample_data" / "aflw2000"


@pytest.fixture(scope="module")
def tour(tmp_path_factory):
    """The tour's two tables: 6drepnet labels converted from the 300W-LP sample, and the sample itself."""
    tmp = tmp_path_factory.mktemp("tour")
    pred = tmp / "labels_6d.parquet"
    r = hpe_cmd("convert", LABELS, "-o", pred, "--from", "300w_lp", "--to", "6drepnet", "-q")
    assert r.exit_code == 0, r.output
    return tmp, pred


def _evaluate(pred, *extra):
    r = hpe_cmd("evaluate", pred, LABELS, "--pred-system", "6drepnet", "--gt-system", "300w_lp", *extra)
    assert r.exit_code == 0, r.output
    return r.output


def test_identical_rotations_explain_the_euler_scores(tour):
    _, pred = tour
    out = _evaluate(pred)
    notes = [line for line in out.splitlines() if line.startswith("note: every prediction is its GT rotation")]
    assert len(notes) == 1, out
    assert "hopenet 0.711" in notes[0] and "directmhp 0.711" in notes[0] and "non_canonical" in notes[0]
    assert "opal23 " not in notes[0]  # a geodesic protocol scores 0 and is not named
    # the reason is real: the sample has rows that hpe audit counts as non-canonical / out of range
    import json

    audit = json.loads(hpe_cmd("audit", LABELS, "--json", "-", "-q").stdout)
    assert audit["non_canonical"] + audit["out_of_range"] >= 1


def test_no_note_when_rotations_differ():
    result = {"metrics": {"geodesic": {"max": 3.0}}, "protocols": {"hopenet": {"mean": 2.0, "units": "deg"}}}
    assert same_rotation_notes(result) == []
    result["metrics"]["geodesic"]["max"] = 1e-9
    assert len(same_rotation_notes(result)) == 1


def test_join_internals_only_with_verbose(tour, tmp_path):
    _, pred = tour
    shuffled = tmp_path / "shuffled.csv"  # another row order: a key join, not a streamed pairing
    pd.read_csv(LABELS).sample(frac=1.0, random_state=3).to_csv(shuffled, index=False)
    r = hpe_cmd("evaluate", pred, shuffled, "--pred-system", "6drepnet", "--gt-system", "300w_lp")
    assert r.exit_code == 0 and "partition" not in r.output and "hash join" not in r.output, r.output
    r = hpe_cmd("evaluate", pred, shuffled, "--pred-system", "6drepnet", "--gt-system", "300w_lp", "-v")
    assert r.exit_code == 0 and "joined by key in" in r.output


def test_group_tables_fit_the_terminal(tour):
    _, pred = tour
    out = _evaluate(pred, "--yaw-bins", "15")
    table = out[out.index("by GT yaw") :].split("note:")[0]
    assert max(len(line) for line in table.splitlines()) <= WIDTH
    for name in ("hopenet", "dad3dheads", "opentrack"):  # every protocol is still in it
        assert name[:10] in table


def test_report_always_has_its_yaw_table(tour, tmp_path):
    _, pred = tour
    page = tmp_path / "r.html"
    out = _evaluate(pred, "--report", page, "--worst", "3")
    text = page.read_text()
    assert "<h2>By GT yaw</h2>" in text and "[60, 90)" in text and "by GT yaw" in out
    assert "partition" not in text and "hash join" not in text
    assert "re-expressed by hpe in 300w_lp" in text
    head = text[text.index("<h2>By GT yaw</h2>") : text.index("<h2>Plots</h2>")]
    for table in head.split("<table")[1:]:  # no table of the section has more than 8 protocol columns
        assert table.split("</thead>")[0].count("(deg)") + table.split("</thead>")[0].count("(unitless)") <= 12


def test_worst_rows_show_written_values_when_present():
    frame = pd.DataFrame(
        {
            "image": ["a.jpg"],
            **{f"gt_{a}": [v] for a, v in zip(("pitch", "yaw", "roll"), (40.0, 70.0, 20.0))},
            **{f"pred_{a}": [v] for a, v in zip(("pitch", "yaw", "roll"), (-141.7, 72.6, -158.9))},
            **{f"pred_written_{a}": [v] for a, v in zip(("pitch", "yaw", "roll"), (38.3, 107.4, 21.1))},
            **{f"err_{a}": [1.0] for a in ("pitch", "yaw", "roll")},
            "geodesic": [41.8],
            "frobenius": [0.1],
        }
    )
    result = {
        "n": {"pairs": 1},
        "metrics": {
            "geodesic": dict.fromkeys(
                ["mean", "median", "p90", "p95", "max", "within_5", "within_10", "within_15", "within_30"], 1.0
            ),
            "maev": {"mean": 1.0, "left": 1.0, "down": 1.0, "front": 1.0},
            "frobenius": {"mean": 0.1},
            "mae_wrapped": {"mean": 1.0, "pitch": 1.0, "yaw": 1.0, "roll": 1.0},
            "mae_best_of_two": {"mean": 1.0, "pitch": 1.0, "yaw": 1.0, "roll": 1.0},
        },
        "protocols": {},
        "systems": {"pred": "whenet", "gt": "300w_lp"},
        "inputs": {"pred": "p.csv", "gt": "g.csv", "key": ["image"], "paired": "joined in memory"},
    }
    text = page_html(result, frame)
    assert "pred as written p / y / r (whenet)" in text and "38.3 / 107.4 / 21.1" in text
    assert "-141.7 / 72.6 / -158.9" in text and "re-expressed by hpe in 300w_lp" in text
    assert "joined in memory" not in text


def test_report_needs_no_sideways_scroll_at_1280px(tour, tmp_path):
    browser = next(
        (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None
    )
    if browser is None:
        pytest.skip("no chromium installed")
    _, pred = tour
    page = tmp_path / "r.html"
    _evaluate(pred, "--report", page, "--worst", "3", "--yaw-bins", "15", "--by", "image")
    probe = tmp_path / "probe.html"
    script = (
        "<script>window.addEventListener('load',()=>{const w=[...document.querySelectorAll('.wrap')]"
        ".filter(e=>e.scrollWidth>e.clientWidth+1&&!e.querySelector('table.worst,table.protocols'))"
        ".map(e=>e.previousElementSibling?e.previousElementSibling.textContent:'?');"
        "document.body.setAttribute('data-scroll',JSON.stringify(w));});</script>"
    )
    probe.write_text(page.read_text().replace("</body>", script + "</body>"))
    r = subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--window-size=1280,900",
            "--virtual-time-budget=3000",
            "--dump-dom",
            probe.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    import re

    m = re.search(r'data-scroll="([^"]*)"', r.stdout)
    assert m is not None, r.stderr[-500:]
    scrolled = m.group(1).replace("&quot;", '"')
    assert "By GT yaw" not in scrolled and "By image" not in scrolled, scrolled


def test_worst_rows_carry_the_prediction_as_written_end_to_end(tmp_path):
    """A prediction written with yaw beyond 90 (WHENet's range) is re-expressed in 300W-LP's system for the
    per-angle errors; the page's worst rows show it as written too, with its system, beside the re-expressed one
    (the same rotation: checked with SciPy from both triples)."""
    from scipy.spatial.transform import Rotation

    import hpe_cli as hpe

    gt = pd.read_csv(LABELS).head(5)
    gt.to_csv(tmp_path / "gt.csv", index=False)
    pred = gt[["image"]].copy()
    pred["pitch"], pred["yaw"], pred["roll"] = 38.3, 107.4, 21.1
    pred.to_csv(tmp_path / "pred.csv", index=False)
    page = tmp_path / "r.html"
    r = hpe_cmd(
        "evaluate", tmp_path / "pred.csv", tmp_path / "gt.csv", "--pred-system", "whenet", "--gt-system", "300w_lp",
        "--report", page, "--worst", "5",
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    text = page.read_text()
    assert "pred as written p / y / r (whenet)" in text and text.count("38.3 / 107.4 / 21.1") >= 5
    shown = hpe.convert([[38.3, 107.4, 21.1]], "whenet", "300w_lp").primary[0]
    assert f"{shown[0]:.1f} / {shown[1]:.1f} / {shown[2]:.1f}" in text
    A = hpe.convert([[38.3, 107.4, 21.1]], "whenet", "300w_lp").matrix[0]
    B = hpe.convert([shown], "300w_lp", "300w_lp").matrix[0]
    assert Rotation.from_matrix(A.T @ B).magnitude() < 1e-3  # the two triples are one rotation (to 0.1 deg print)
