"""COCO and WHENet text made by workers (``format_unit``) against the one-process streaming writers.

Oracle: the same job run in this process with no parts (``CocoWriter`` / ``WhenetWriter`` fed unit by unit),
and, independently, ``json`` parsing of the COCO document checked against the Parquet labels of the same run.
Several sequences and many small units (4 frames each) so ids cross unit and sequence boundaries; with
``--min-change`` (units formatted from the rows it keeps), with ``--resume``, and on a Dask ``LocalCluster``.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import sample_data_script
from hpe_cli.errors import HpeError
from hpe_cli.pipelines import parts as folder
from hpe_cli.pipelines.relabel import panoptic as job
from hpe_cli.pipelines.relabel import plan as planning
from hpe_cli.pipelines.relabel import units
from hpe_cli.pipelines.relabel.options import RelabelPanopticOptions


@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    gen = sample_data_script()
    root = tmp_path_factory.mktemp("text")
    gen.make_synthetic(root / "seqA", n_frames=18, n_people=2, n_cameras=3, first_frame=3)
    gen.make_synthetic(root / "seqB", n_frames=10, n_people=2, n_cameras=3, seed=5, special=False)
    gen.pack_tar(root / "seqB")
    return planning.plan_many([root / "seqA", root / "seqB"], chunk_frames=4)


@pytest.mark.parametrize("fmt,suffix", [("coco", ".json"), ("whenet", ".txt")])
@pytest.mark.parametrize("min_change", [None, 30.0])
def test_worker_text_is_the_one_process_bytes(plans, tmp_path, fmt, suffix, min_change):
    opts = RelabelPanopticOptions(landmarks=True, min_change=min_change, system="whenet")
    assert sum(len(p.chunks) for p in plans) >= 6
    ref, two = tmp_path / f"ref{suffix}", tmp_path / f"two{suffix}"
    st1 = job.write_outputs(plans, ref, replace(opts, fmt=fmt, rejects=tmp_path / "r1.parquet"))
    st2 = job.write_outputs(plans, two, replace(opts, fmt=fmt, workers=2, rejects=tmp_path / "r2.parquet"))
    assert st1.views == st2.views and st1.views > 100
    assert ref.read_bytes() == two.read_bytes()
    assert (tmp_path / "r1.parquet").read_bytes() == (tmp_path / "r2.parquet").read_bytes()
    assert not folder.parts_dir_for(two).exists()
    if min_change:
        rej = pq.read_table(tmp_path / "r2.parquet").to_pandas()
        assert (rej["reason"] == "below --min-change").sum() > 0  # units were formatted from kept rows


def test_coco_from_workers_matches_the_labels(plans, tmp_path):
    """Independent check: parse the COCO document and compare it with the Parquet table of the same job."""
    opts = RelabelPanopticOptions(landmarks=True, system="whenet")
    tab = tmp_path / "t.parquet"
    job.write_outputs(plans, tab, opts)
    coco = tmp_path / "c.json"
    job.write_outputs(plans, coco, replace(opts, fmt="coco", workers=2))
    t = pq.read_table(tab).to_pandas()
    doc = json.loads(coco.read_text())
    anns = doc["annotations"]
    assert [a["id"] for a in anns] == list(range(1, len(t) + 1))
    images = {im["id"]: im for im in doc["images"]}
    assert len(images) == t["image"].nunique()
    assert [images[a["image_id"]]["file_name"] for a in anns] == t["image"].tolist()
    # image ids in order of first appearance
    first = list(dict.fromkeys(t["image"].tolist()))
    assert [images[i]["file_name"] for i in sorted(images)] == first
    box = np.array([a["bbox"] for a in anns])
    assert np.array_equal(box, t[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]].to_numpy())
    ang = np.array([a["euler_angles"] for a in anns])
    assert np.array_equal(ang, t[["pitch", "yaw", "roll"]].to_numpy())
    pts = np.array([a["face2d_pts"] for a in anns])
    xs = t[[f"lm{i}_x" for i in range(70)]].to_numpy()
    ok = np.isfinite(xs)
    assert np.array_equal(pts[:, 0][ok], xs[ok]) and (pts[:, 0][~ok] == -1).all()


@pytest.mark.parametrize("fmt,suffix", [("coco", ".json"), ("whenet", ".txt")])
def test_resume_formats_the_text_again(plans, tmp_path, fmt, suffix):
    opts = RelabelPanopticOptions(landmarks=False, system="whenet")
    ref, res = tmp_path / f"ref{suffix}", tmp_path / f"res{suffix}"
    job.write_outputs(plans, ref, replace(opts, fmt=fmt))
    parts = units.prepare_unit_parts(plans, opts.config(), fmt, res, resume=False)
    tasks = [units.unit_task(plans, opts.config(), u, parts) for u in units.make_units(plans)]
    for t in tasks[:3]:
        job.run_unit(t)
    Path(tasks[0]["stem"] + f".{fmt}.text").write_bytes(b"stale text of an interrupted run")
    job.write_outputs(plans, res, replace(opts, fmt=fmt, resume=True))
    assert res.read_bytes() == ref.read_bytes()
    assert not folder.parts_dir_for(res).exists()  # a finished run removes its parts


def test_text_on_a_local_dask_cluster(plans, tmp_path):
    pytest.importorskip("dask.distributed")
    opts = RelabelPanopticOptions(landmarks=False, system="whenet")
    ref, dsk = tmp_path / "ref.json", tmp_path / "dask.json"
    job.write_outputs(plans, ref, replace(opts, fmt="coco"))
    job.write_outputs(plans, dsk, replace(opts, fmt="coco", workers=2, scheduler="local"))
    assert ref.read_bytes() == dsk.read_bytes()


def test_a_failing_format_task_leaves_no_output(plans, tmp_path, monkeypatch):
    """A unit whose text cannot be made (here: a forced error) ends the run with that error and no output;
    a --resume run keeps its parts (and only them)."""
    opts = RelabelPanopticOptions(landmarks=False, system="whenet")
    out = tmp_path / "o.json"

    def broken(task):
        raise HpeError(f"{task['path']}: row {task['offset']}: expected something, got nothing")

    monkeypatch.setattr(job, "format_unit", broken)
    with pytest.raises(HpeError, match="row 0: expected something"):
        job.write_outputs(plans, out, replace(opts, fmt="coco", resume=True))  # parts, run in this process
    assert sorted(p.name for p in tmp_path.iterdir()) == [folder.parts_dir_for(out).name]
