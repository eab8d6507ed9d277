"""Arrow arrays built from numpy buffers (``io.layout``) and the worker path that never imports pandas.

The oracle is pyarrow's own conversion (``pa.array`` / ``to_numpy``), which
the buffer-built arrays must equal value for value and type for type; the
image paths are checked against ``datasets.panoptic.image_path``.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from conftest import sample_data_script
from hpe_cli.datasets import panoptic as pan
from hpe_cli.io.layout import arrow_table, arrow_to_numpy, numpy_to_arrow, string_array
from hpe_cli.pipelines.parts import parts_dir_for
from hpe_cli.pipelines.relabel import panoptic as job
from hpe_cli.pipelines.relabel import plan as planning
from hpe_cli.pipelines.relabel.options import RelabelPanopticOptions

ROOT = Path(__file__).resolve().parents[2]


def _same(a: pa.Array, b: pa.Array) -> bool:
    """Equal type, nulls and values (NaN equal to NaN, bit for bit)."""
    if a.type != b.type or len(a) != len(b) or a.null_count != b.null_count:
        return False
    if pa.types.is_floating(a.type):
        x = a.to_numpy(zero_copy_only=False)
        y = b.to_numpy(zero_copy_only=False)
        return np.array_equal(x, y, equal_nan=True) and np.array_equal(np.signbit(x), np.signbit(y))
    return a.to_pylist() == b.to_pylist()


@settings(max_examples=150, deadline=None)
@given(st.lists(st.one_of(st.none(), st.text(max_size=12)), max_size=40))
def test_string_array_is_pa_array(values):
    assert _same(string_array(values), pa.array(values, type=pa.string()))
    obj = np.array(values + ["x"], dtype=object)[:-1]  # an object array, even when empty
    assert _same(numpy_to_arrow(obj), pa.array(obj, type=pa.string()))


def test_string_array_leaves_other_objects_to_pa_array():
    with pytest.raises(pa.ArrowTypeError):
        string_array(["a", 1.5])
    assert string_array([b"bytes"]).to_pylist() == ["bytes"]  # pa.array's own rule for bytes


@settings(max_examples=150, deadline=None)
@given(
    hnp.arrays(
        st.sampled_from(
            [
                np.float64,
                np.float32,
                np.int64,
                np.int32,
                np.int16,
                np.int8,
                np.uint8,
                np.uint16,
                np.uint32,
                np.uint64,
                np.bool_,
            ]
        ),
        st.integers(0, 50),
    ),
    st.integers(1, 3),
)
def test_numpy_to_arrow_is_pa_array(v, step):
    v = v[::step]  # strided views too
    assert _same(numpy_to_arrow(v), pa.array(v))
    t = arrow_table({"a": v, "b": np.arange(len(v))})
    assert _same(t.column("a").combine_chunks(), pa.array(v))


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.one_of(st.none(), st.floats(allow_nan=True), st.integers(-(2**40), 2**40).map(float)), max_size=30),
    st.integers(0, 5),
    st.sampled_from(["float64", "float32", "int64"]),
)
def test_arrow_to_numpy_is_to_numpy(values, cut, typ):
    if typ == "int64":  # exact in float64 (a safe cast refuses others, as the oracle does)
        values = [None if x is None or not np.isfinite(x) else int(x) % 2**40 for x in values]
    arr = pa.array(values, type=getattr(pa, typ)()).slice(min(cut, len(values)))
    chunked = pa.chunked_array([arr, arr.slice(len(arr) // 2)], type=arr.type)
    for col in (arr, chunked):
        want = col.to_numpy() if isinstance(col, pa.ChunkedArray) else col.to_numpy(zero_copy_only=False)
        got = arrow_to_numpy(col)
        assert got.dtype == want.dtype and np.array_equal(got, want, equal_nan=True)
        want64 = col.cast(pa.float64())
        want64 = want64.to_numpy() if isinstance(col, pa.ChunkedArray) else want64.to_numpy(zero_copy_only=False)
        got64 = arrow_to_numpy(col, np.float64)
        assert got64.dtype == np.float64 and np.array_equal(got64, want64, equal_nan=True)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 4), st.integers(0, 10**9)), max_size=60))
def test_image_paths_are_panoptic_paths(rows):
    # _image_paths reads only a camera's name and type
    cams = SimpleNamespace(
        names=np.array(["00_00", "00_08", "01_01", "50_01", "30"], dtype=object),
        types=np.array(["hd", "hd", "vga", "kinect-color", "hd"], dtype=object),
    )
    ci = np.array([c for c, _ in rows], dtype=np.int64)
    frames = np.array([f for _, f in rows], dtype=np.int64)
    got = planning.image_paths(cams, ci, frames)
    assert got.type == pa.string()
    assert got.to_pylist() == [pan.image_path(cams.names[c], f, cams.types[c]) for c, f in rows]


def test_a_unit_never_imports_pandas(tmp_path):
    """A worker's unit (compute, labels and rejects parts, COCO and WHENet text) runs without pandas, so no
    worker spends 0.3 s importing it; and the one-process job does not either."""
    gen = sample_data_script()
    seq = tmp_path / "seq"
    gen.make_synthetic(seq, n_frames=6, n_people=2, n_cameras=3)
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        from pathlib import Path
        from hpe_cli.pipelines.relabel import panoptic as job, plan as planning, units
        from hpe_cli.pipelines.relabel.options import RelabelPanopticOptions
        p = planning.plan({str(seq)!r})
        for lm in (False, True):
            opts = RelabelPanopticOptions(landmarks=lm, system="whenet")
            t = units.unit_task([p], opts.config(), (0, 0), {str(tmp_path)!r})
            units.run_unit(t)
            for fmt in ("coco", "whenet"):
                n = job.format_unit({{"fmt": fmt, "labels": t["stem"] + ".labels.arrow", "text": t["stem"] + ".t",
                                     "path": "o", "offset": 0, "first_id": 1, "image_ids": list(range(1, 10 ** 4))}})
                assert n > 0
            job.write_outputs(p, Path({str(tmp_path)!r}) / f"one{{lm}}.parquet", opts)
        print("pandas" in sys.modules)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "False"


def test_a_borrowed_pool_gives_the_same_output(tmp_path):
    """The CLI starts the pool before planning and lends it to the job: same bytes as the job's own pool."""
    gen = sample_data_script()
    seq = tmp_path / "seq"
    gen.make_synthetic(seq, n_frames=12, n_people=2, n_cameras=3)
    opts = RelabelPanopticOptions(landmarks=True, system="whenet")
    p = planning.plan(seq, chunk_frames=3)
    own, lent = tmp_path / "own.json", tmp_path / "lent.json"
    job.write_outputs(p, own, replace(opts, fmt="coco", workers=2))
    with job.worker_pool(2) as pool:
        job.write_outputs(planning.plan(seq, chunk_frames=3), lent, replace(opts, fmt="coco", workers=2), pool=pool)
        # the pool outlives the job and takes another
        job.write_outputs(p, tmp_path / "again.parquet", replace(opts, workers=2), pool=pool)
    assert own.read_bytes() == lent.read_bytes()
    assert not parts_dir_for(lent).exists()
