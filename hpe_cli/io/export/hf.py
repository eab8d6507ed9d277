"""Hugging Face ``datasets`` layout: Parquet shards with an Image column and a dataset card, as a pose dataset.

Followed: huggingface/datasets (the ``datasets.load_dataset("parquet", data_files=...)`` / ``load_dataset(folder)``
path): ``features/image.py`` (an image is a struct ``{bytes: binary, path: string}``, decoded on access),
``features/features.py`` (``Array2D(shape, dtype)`` stored as a list of lists; ``Value``; ``Sequence``), and
``arrow_writer``/``io/parquet``: a Parquet file's schema metadata key ``huggingface`` holds
``{"info": {"features": {...}}}``, which ``load_dataset`` reads back to restore the feature types. Shards are
``data/<split>-NNNNN-of-MMMMM.parquet`` (the Hub's naming, one split per set of files); the card ``README.md``
has the YAML header (``configs`` with the split files, ``dataset_info`` with the features and splits, the task:
``keypoint-detection`` / ``pose-estimation`` with a ``head-pose`` regression tag) and then the labels in words.

Each row: ``image`` (the crop), ``rotation`` (3 x 3, the rotation matrix of the named system), ``pitch``, ``yaw``,
``roll`` (degrees, the same system), ``landmarks_x/y`` in the **crop's** pixels (the written image), the head
box and the crop box in the source frame's pixels (``bbox_*``, ``crop_x0..y1``) and the source-frame landmarks
under ``source_landmarks_x/y``.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ...io.layout import landmark_count
from . import LAYOUTS
from .base import Layout

SHARD_ROWS = 5000
ANGLE_COLS = ["pitch", "yaw", "roll"]
MATRIX_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]
META_STR = ["source", "image_file", "sequence", "camera", "split"]
META_INT = ["frame", "person_id", "crop_x0", "crop_y0", "crop_x1", "crop_y1", "image_width", "image_height"]
BOX = ["bbox_x", "bbox_y", "bbox_w", "bbox_h"]
LANDMARKS = ("landmarks_x", "landmarks_y", "source_landmarks_x", "source_landmarks_y")
LOADER = (
    "huggingface/datasets load_dataset('parquet' or folder): features/image.py (Image struct), "
    "features/features.py (Array2D, Value, Sequence), the 'huggingface' schema metadata"
)


def _features(n_lm: int) -> dict:
    f = {"image": {"_type": "Image"}}
    for c in META_STR:
        f[c] = {"dtype": "string", "_type": "Value"}
    for c in META_INT:
        f[c] = {"dtype": "int64", "_type": "Value"}
    for c in BOX + ANGLE_COLS:
        f[c] = {"dtype": "float64", "_type": "Value"}
    f["rotation"] = {"shape": [3, 3], "dtype": "float64", "_type": "Array2D"}
    if n_lm:
        for c in LANDMARKS:
            f[c] = {"feature": {"dtype": "float64", "_type": "Value"}, "_type": "Sequence"}
    return f


def crop_points(rows, n_lm: int):
    """Landmarks (x, y arrays, (N, L)) in the written crop's pixels: shift by the crop box, scale by the resize
    (``cv2.resize`` maps pixel centres by ``x' = (x + 0.5) * W' / W - 0.5``)."""
    xs = rows[[f"lm{i}_x" for i in range(n_lm)]].to_numpy(dtype=np.float64)
    ys = rows[[f"lm{i}_y" for i in range(n_lm)]].to_numpy(dtype=np.float64)
    box = rows[["crop_x0", "crop_y0", "crop_x1", "crop_y1"]].to_numpy(dtype=np.float64)
    sx = rows["out_w"].to_numpy(dtype=np.float64) / (box[:, 2] - box[:, 0])
    sy = rows["out_h"].to_numpy(dtype=np.float64) / (box[:, 3] - box[:, 1])
    cx = (xs - box[:, :1] + 0.5) * sx[:, None] - 0.5
    cy = (ys - box[:, 1:2] + 0.5) * sy[:, None] - 0.5
    return (xs, ys), (cx, cy)


@LAYOUTS.register()
class HFLayout(Layout):
    name = "hf"
    writes_card = True
    system = None
    loader = LOADER
    pixels = "jpeg"
    uses_landmarks = True

    def open(self, root, splits):
        super().open(root, splits)
        (self.root / "data").mkdir(parents=True, exist_ok=True)
        self._writers = {}
        self._shards = {}
        self._rows = {}
        self._n_lm = None

    def _schema(self):

        fields = [pa.field("image", pa.struct([pa.field("bytes", pa.binary()), pa.field("path", pa.string())]))]
        fields += [pa.field(c, pa.string()) for c in META_STR]
        fields += [pa.field(c, pa.int64()) for c in META_INT]
        fields += [pa.field(c, pa.float64()) for c in BOX + ANGLE_COLS]
        fields += [pa.field("rotation", pa.list_(pa.list_(pa.float64())))]
        if self._n_lm:
            fields += [pa.field(c, pa.list_(pa.float64())) for c in LANDMARKS]
        meta = {"huggingface": json.dumps({"info": {"features": _features(self._n_lm)}})}
        return pa.schema(fields, metadata=meta)

    def add_pixels(self, split, rows, payloads):

        if self._n_lm is None:
            self._n_lm = landmark_count(rows.columns)
        files = rows["file"].tolist()
        cols = {
            "image": pa.array(
                [{"bytes": b, "path": f} for b, f in zip(payloads, files)],
                type=pa.struct([pa.field("bytes", pa.binary()), pa.field("path", pa.string())]),
            )
        }
        for c in META_STR:
            cols[c] = pa.array(rows[c if c != "image_file" else "image"].astype(str).tolist(), pa.string())
        for c in META_INT:
            cols[c] = pa.array(rows[c].to_numpy(dtype=np.int64))
        for c in BOX + ANGLE_COLS:
            cols[c] = pa.array(rows[c].to_numpy(dtype=np.float64))
        m = rows[MATRIX_COLS].to_numpy(dtype=np.float64)
        inner = pa.ListArray.from_arrays(np.arange(0, 9 * len(m) + 1, 3, dtype=np.int32), pa.array(m.reshape(-1)))
        cols["rotation"] = pa.ListArray.from_arrays(np.arange(0, 3 * len(m) + 1, 3, dtype=np.int32), inner)
        if self._n_lm:
            (xs, ys), (cx, cy) = crop_points(rows, self._n_lm)
            for c, v in zip(LANDMARKS, (cx, cy, xs, ys)):
                cols[c] = pa.array(list(v), pa.list_(pa.float64()))
        self._write(split, pa.Table.from_pydict(cols, schema=self._schema()))

    def _write(self, split, table):

        w = self._writers.get(split)
        if w is None or self._rows[split] >= SHARD_ROWS:
            if w is not None:
                w.close()
            k = self._shards.get(split, 0)
            self._shards[split] = k + 1
            self._rows[split] = 0
            w = self._writers[split] = pq.ParquetWriter(self.root / "data" / f".{split}-{k:05d}.parquet", table.schema)
        w.write_table(table)
        self._rows[split] += table.num_rows

    def abort(self):
        for w in getattr(self, "_writers", {}).values():
            try:
                w.close()
            except Exception:
                pass

    def finish(self, exported, final_root):
        for w in self._writers.values():
            w.close()
        for split, n in self._shards.items():
            for k in range(n):
                (self.root / "data" / f".{split}-{k:05d}.parquet").rename(
                    self.root / "data" / f"{split}-{k:05d}-of-{n:05d}.parquet"
                )
        self.card = None
        return [f"read by {self.loader}"]

    def write_card(self, exported, system, sampling: list, sources: dict, final_root) -> None:
        """The dataset card: YAML header (task, configs, features, splits), then the labels in words."""
        counts = exported["split"].value_counts().sort_index()
        y = _card_header(counts, self._n_lm or 0, self.root)
        y += [
            "# Head-pose crops exported by `hpe export --layout hf`",
            "",
            "A head-pose estimation (regression) dataset: each row is one head crop and its 3-D head rotation.",
            "",
        ]
        d = system.describe()
        y += [
            "## Labels",
            "",
            (
                f"`rotation` (3 x 3) is the head's rotation matrix and `pitch`, `yaw`, `roll` (degrees) its angles, "
                f"both in the rotation system `{system.name}`:"
            ),
            "",
        ]
        y += [f"- {k}: {v}" for k, v in d.items()]
        y += [
            "",
            (
                "Compare rotations through the matrix, not the angles (angles wrap and have two solutions). The "
                f"canonical 300W-LP matrix of a row is `get_system('{system.name}').to_canonical(rotation)` in "
                "`hpe`. `datasets.load_dataset(folder)` reads `rotation` as `Array2D((3, 3))` (this card's "
                "features); `load_dataset('parquet', ...)` as a 3 x 3 nested list."
            ),
            "",
            "## Pixels",
            "",
            (
                "`image` is the crop. `landmarks_x/y` are in the crop's pixels (the written image, after the "
                "resize); `source_landmarks_x/y`, `bbox_*` (the head box) and `crop_x0..crop_y1` (the crop's box, "
                "exclusive ends) are in the source frame's pixels (`image_file`, `image_width` x `image_height`). "
                "Parts of the crop outside the frame are padded with a constant."
            ),
            "",
            "## Sampling",
            "",
        ]
        y += [f"- {s}" for s in sampling] or ["- none: every usable label is exported"]
        y += ["", "## Sources and licences", ""]
        for src, note in sources.items():
            y += [f"- `{src}`: {note}"]
        y += [""]
        (self.root / "README.md").write_text("\n".join(y), encoding="utf-8")


def _size_category(n: int) -> str:
    for hi, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"), (1_000_000, "100K<n<1M")):
        if n < hi:
            return name
    return "1M<n<10M"


def _card_header(counts, n_lm: int, root) -> list:
    """The card's YAML header: task, size, configs (split files), features and splits."""
    y = [
        "---",
        "license: other",
        "pretty_name: Head pose crops (hpe export)",
        "task_categories:",
        "- keypoint-detection",
        "task_ids:",
        "- pose-estimation",
        "tags:",
        "- head-pose",
        "- head-pose-estimation",
        "- rotation-regression",
        "size_categories:",
        f"- {_size_category(int(counts.sum()))}",
        "configs:",
        "- config_name: default",
        "  data_files:",
    ]
    for split in counts.index:
        y += [f"  - split: {split}", f"    path: data/{split}-*"]
    y += ["dataset_info:", "  features:"]
    for name, f in _features(n_lm).items():
        if f["_type"] == "Image":
            y += [f"  - name: {name}", "    dtype: image"]
        elif f["_type"] == "Sequence":
            y += [f"  - name: {name}", "    sequence: float64"]
        elif f["_type"] == "Array2D":
            y += [
                f"  - name: {name}",
                "    dtype:",
                "      array2_d:",
                "        shape:",
                "        - 3",
                "        - 3",
                "        dtype: float64",
            ]
        else:
            y += [f"  - name: {name}", f"    dtype: {f['dtype']}"]
    y += ["  splits:"]
    for split, n in counts.items():
        nbytes = sum(f.stat().st_size for f in (root / "data").glob(f"{split}-*.parquet"))
        y += [f"  - name: {split}", f"    num_bytes: {nbytes}", f"    num_examples: {int(n)}"]
    return y + ["---", ""]
