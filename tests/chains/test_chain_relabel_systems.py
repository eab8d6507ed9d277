"""relabel-panoptic (3 systems) -> audit / convert with no system option -> audit: the system travels with the file.

The labels a relabel writes in system X are read back in X by every command
without being told (``hpe:system`` metadata): convert's matrices equal the
relabel's own ``r00..r22`` (geodesic < 1e-6 degrees), audit flags nothing on
the synthetic sequence, and the convert output audits clean in its new system.
A COCO file (whenet angles, ``info["hpe:system"]``) is read back the same way.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.rotation import get_system
from hpe_cli.rotation.distances import geodesic_deg

from .conftest import PIZZA

ROOT = Path(__file__).resolve().parents[2]
SYNTH = ROOT / "sample_data" / "panoptic_synth"
MAT = [f"r{i}{j}" for i in range(3) for j in range(3)]
CHECKS = ("gimbal_lock", "near_gimbal", "non_canonical", "out_of_range", "non_finite", "not_rotation", "duplicates")


def canonical(frame, system):
    s = get_system(system)
    return s.to_canonical(frame[MAT].to_numpy().reshape(-1, 3, 3))


@pytest.mark.parametrize("system", ["300w_lp", "scipy_zyx", "6drepnet"])
def test_relabel_then_audit_and_convert_without_system(tmp_path, system):
    lab = tmp_path / "labels.parquet"
    hpe("relabel-panoptic", SYNTH, "-o", lab, "--system", system, "-q", ok=True)
    relabel = pd.read_parquet(lab)
    # the relabel's matrices are its angles' matrices in X: an independent check of what it wrote
    R_angles = get_system(system).from_angles(relabel[["pitch", "yaw", "roll"]].to_numpy())
    assert geodesic_deg(R_angles, relabel[MAT].to_numpy().reshape(-1, 3, 3)).max() < 1e-6

    res = hpe("audit", lab, "--json", "-", ok=True)
    rep = json.loads(res.stdout)
    assert rep["system"] == system and rep["system_origin"] == "file metadata"
    assert rep["rows"] == len(relabel) and all(rep[c] == 0 for c in CHECKS), rep
    assert f"system {system} (file metadata)" in res.stderr

    same = tmp_path / "same.parquet"
    res = hpe("convert", lab, "-o", same, "--to", system, ok=True)
    assert f"from {system} (file metadata)" in res.stderr
    back = pd.read_parquet(same)
    assert geodesic_deg(back[MAT].to_numpy().reshape(-1, 3, 3), relabel[MAT].to_numpy().reshape(-1, 3, 3)).max() < 1e-6

    # convert -> audit: the new file names its new system
    other = "whenet" if system != "whenet" else "300w_lp"
    conv = tmp_path / "conv.parquet"
    hpe("convert", lab, "-o", conv, "--to", "300w_lp", "-q", ok=True)
    c = pd.read_parquet(conv)
    assert geodesic_deg(canonical(c, "300w_lp"), canonical(relabel, system)).max() < 1e-6
    rep2 = json.loads(hpe("audit", conv, "--json", "-", "-q", ok=True).stdout)
    assert rep2["system"] == "300w_lp" and rep2["system_origin"] == "file metadata"
    assert all(rep2[k] == 0 for k in CHECKS if k not in ("non_canonical",)), rep2
    # an explicit, disagreeing system is a usage error naming both; --reinterpret-as overrides
    res = hpe("audit", lab, "--system", other, code=2)
    assert system in res.output and other in res.output and res.output.count("\n") == 1
    hpe("audit", lab, "--system", other, "--reinterpret-as", other, "-q", ok=True)


def test_coco_and_whenet_files_carry_their_system(tmp_path):
    coco = tmp_path / "train.json"
    hpe("relabel-panoptic", SYNTH, "-o", coco, "--format", "coco", "-q", ok=True)
    assert json.loads(coco.read_text())["info"]["hpe:system"] == "whenet"
    rep = json.loads(hpe("audit", coco, "--json", "-", "-q", ok=True).stdout)
    assert rep["system"] == "whenet" and rep["system_origin"] == "file metadata"
    # rows with no whenet solution (|pitch|, |roll| < 90) are the only flags: the system's documented range
    assert rep["out_of_range"] == rep["details"]["flagged"]
    table = tmp_path / "w.parquet"
    hpe("relabel-panoptic", SYNTH, "-o", table, "--system", "whenet", "-q", ok=True)
    rep_t = json.loads(hpe("audit", table, "--json", "-", "-q", ok=True).stdout)
    assert rep_t["out_of_range"] == rep["out_of_range"] and rep_t["rows"] == rep["rows"]
    out = tmp_path / "c.parquet"
    hpe("convert", coco, "-o", out, "--to", "300w_lp", "-q", ok=True)
    ref = pd.read_parquet(table).sort_values(["image", "bbox_x"]).reset_index(drop=True)
    got = pd.read_parquet(out).sort_values(["image", "bbox_x"]).reset_index(drop=True)
    assert geodesic_deg(canonical(got, "300w_lp"), canonical(ref, "whenet")).max() < 1e-6


@pytest.mark.skipif(not PIZZA.exists(), reason="real Panoptic sample absent")
def test_real_pizza_scipy_zyx_audits_clean(tmp_path):
    lab = tmp_path / "pizza.parquet"
    hpe("relabel-panoptic", PIZZA, "-o", lab, "--system", "scipy_zyx", "-q", ok=True)
    rep = json.loads(hpe("audit", lab, "--json", "-", "-q", ok=True).stdout)
    assert rep["system"] == "scipy_zyx" and rep["details"]["flagged"] == 0 and rep["rows"] > 1000


@pytest.mark.skipif(not PIZZA.exists(), reason="real Panoptic sample absent")
def test_relabel_in_two_systems_then_draw_without_system_draws_the_same_pixels(tmp_path):
    """relabel-panoptic -> draw with no --system, on the real pizza1 frames: the same heads labelled in 300w_lp and
    in scipy_zyx draw the very same pictures (draw reads each file in its own system), and reading the scipy_zyx
    file as 300w_lp (what draw did before the metadata rule) draws different axes."""
    import cv2
    import numpy as np

    pics = {}
    for system in ("300w_lp", "scipy_zyx"):
        lab = tmp_path / f"{system}.parquet"
        hpe(
            "relabel-panoptic",
            PIZZA,
            "-o",
            lab,
            "--system",
            system,
            "--cameras",
            "00_00,00_08",
            "--frames",
            "1147:1148",
            "-q",
            ok=True,
        )
        out = tmp_path / f"draw_{system}"
        res = hpe("draw", lab, "--images", PIZZA, "-o", out, ok=True)
        assert f"system {system} (file metadata" in res.stderr, res.stderr
        pics[system] = {p.relative_to(out): cv2.imread(str(p)) for p in sorted(out.rglob("*.jpg"))}
    assert pics["300w_lp"] and pics["300w_lp"].keys() == pics["scipy_zyx"].keys()
    for name, img in pics["300w_lp"].items():
        other = pics["scipy_zyx"][name]
        assert img.shape == other.shape
        # the same lines on the same frame (JPEG noise only)
        assert np.abs(img.astype(int) - other.astype(int)).mean() < 0.5, name
    wrong = tmp_path / "wrong"
    hpe("draw", tmp_path / "scipy_zyx.parquet", "--images", PIZZA, "-o", wrong, "--reinterpret-as", "300w_lp", ok=True)
    diffs = [
        np.abs(cv2.imread(str(wrong / n)).astype(int) - img.astype(int)).max() for n, img in pics["300w_lp"].items()
    ]
    assert max(diffs) > 100  # the axes point elsewhere: the seam this rule closes
