"""Hugging Face ``datasets`` layout: Parquet shards with an Image column and a dataset card.

Followed: the ``datasets`` library's ``Image`` feature storage (``datasets/features/image.py``): an image
is a struct ``{bytes: binary, path: string}``; a Parquet file's schema metadata key ``huggingface`` holds
``{"info": {"features": {...}}}`` (``_type: Image`` for the image, ``_type: Value`` with a ``dtype`` for the
others), which ``datasets.load_dataset("parquet", ...)`` and ``load_dataset(folder)`` read back, decoding the
column as images. Shards are ``data/<split>-NNNNN-of-MMMMM.parquet`` (the Hub's naming, one split per set of
files), and the dataset card ``README.md`` has the YAML header (``configs`` with the split files,
``dataset_info`` with the features and splits) and then the rotation system in words.
"""
from __future__ import annotations

import json

import numpy as np

from .base import Layout

SHARD_ROWS = 5000
LABEL_COLS = ["pitch", "yaw", "roll"] + [f"r{i}{j}" for i in range(3) for j in range(3)]
META_STR = ["source", "image_file", "sequence", "camera", "split"]
META_INT = ["frame", "person_id", "crop_x0", "crop_y0", "crop_x1", "crop_y1", "image_width", "image_height"]
BOX = ["bbox_x", "bbox_y", "bbox_w", "bbox_h"]


def _features(n_lm: int) -> dict:
    f = {"image": {"_type": "Image"}}
    for c in META_STR:
        f[c] = {"dtype": "string", "_type": "Value"}
    for c in META_INT:
        f[c] = {"dtype": "int64", "_type": "Value"}
    for c in BOX + LABEL_COLS:
        f[c] = {"dtype": "float64", "_type": "Value"}
    if n_lm:
        for c in ("landmarks_x", "landmarks_y"):
            f[c] = {"feature": {"dtype": "float64", "_type": "Value"}, "_type": "Sequence"}
    return f


class HFLayout(Layout):
    name = "hf"
    system = None
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
        import pyarrow as pa

        fields = [pa.field("image", pa.struct([pa.field("bytes", pa.binary()), pa.field("path", pa.string())]))]
        fields += [pa.field(c, pa.string()) for c in META_STR]
        fields += [pa.field(c, pa.int64()) for c in META_INT]
        fields += [pa.field(c, pa.float64()) for c in BOX + LABEL_COLS]
        if self._n_lm:
            fields += [pa.field(c, pa.list_(pa.float64())) for c in ("landmarks_x", "landmarks_y")]
        meta = {"huggingface": json.dumps({"info": {"features": _features(self._n_lm)}})}
        return pa.schema(fields, metadata=meta)

    def add_pixels(self, split, rows, payloads):
        import pyarrow as pa
        import pyarrow.parquet as pq

        from ...io.layout import landmark_count

        if self._n_lm is None:
            self._n_lm = landmark_count(rows.columns)
        files = rows["file"].tolist()
        cols = {"image": pa.array([{"bytes": b, "path": f} for b, f in zip(payloads, files)],
                                  type=pa.struct([pa.field("bytes", pa.binary()), pa.field("path", pa.string())]))}
        for c in META_STR:
            cols[c] = pa.array(rows[c if c != "image_file" else "image"].astype(str).tolist(), pa.string())
        for c in META_INT:
            cols[c] = pa.array(rows[c].to_numpy(dtype=np.int64))
        for c in BOX + LABEL_COLS:
            cols[c] = pa.array(rows[c].to_numpy(dtype=np.float64))
        if self._n_lm:
            for a in "xy":
                v = rows[[f"lm{i}_{a}" for i in range(self._n_lm)]].to_numpy(dtype=np.float64)
                cols[f"landmarks_{a}"] = pa.array(list(v), pa.list_(pa.float64()))
        table = pa.Table.from_pydict(cols, schema=self._schema())
        w = self._writers.get(split)
        if w is None or self._rows[split] >= SHARD_ROWS:
            if w is not None:
                w.close()
            k = self._shards.get(split, 0)
            self._shards[split] = k + 1
            self._rows[split] = 0
            w = self._writers[split] = pq.ParquetWriter(self.root / "data" / f".{split}-{k:05d}.parquet",
                                                        table.schema)
        w.write_table(table)
        self._rows[split] += len(rows)

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
                    self.root / "data" / f"{split}-{k:05d}-of-{n:05d}.parquet")
        self.card = None
        return []

    def write_card(self, exported, system, sampling: list, sources: dict, final_root) -> None:
        """The dataset card: YAML header (configs, features, splits), then the labels in words."""
        n_lm = self._n_lm or 0
        counts = exported["split"].value_counts().sort_index()
        y = ["---", "license: other", "task_categories:", "- image-classification", "tags:", "- head-pose",
             "configs:", "- config_name: default", "  data_files:"]
        for split in counts.index:
            y += [f"  - split: {split}", f"    path: data/{split}-*"]
        y += ["dataset_info:", "  features:"]
        for name, f in _features(n_lm).items():
            if f["_type"] == "Image":
                y += [f"  - name: {name}", "    dtype: image"]
            elif f["_type"] == "Sequence":
                y += [f"  - name: {name}", "    sequence: float64"]
            else:
                y += [f"  - name: {name}", f"    dtype: {f['dtype']}"]
        y += ["  splits:"]
        for split, n in counts.items():
            nbytes = sum(f.stat().st_size for f in (self.root / "data").glob(f"{split}-*.parquet"))
            y += [f"  - name: {split}", f"    num_bytes: {nbytes}", f"    num_examples: {int(n)}"]
        y += ["---", "", "# Head-pose crops exported by `hpe export --layout hf`", ""]
        d = system.describe()
        y += ["## Labels", "",
              f"`pitch`, `yaw`, `roll` (degrees) and the matrix `r00..r22` are in the rotation system "
              f"`{system.name}`:", ""]
        y += [f"- {k}: {v}" for k, v in d.items()]
        y += ["", "Compare rotations through the matrix, not the angles. The canonical 300W-LP matrix of a row is "
              f"`get_system('{system.name}').to_canonical(R)` in `hpe`.", "",
              "`bbox_*` is the head box and `crop_x0..crop_y1` the crop's box (exclusive ends) in the source "
              "frame's pixels; parts of the crop outside the frame are padded with a constant. "
              "`landmarks_x/y` are in the source frame's pixels.", "", "## Sampling", ""]
        y += [f"- {s}" for s in sampling] or ["- none: every usable label is exported"]
        y += ["", "## Sources and licences", ""]
        for src, note in sources.items():
            y += [f"- `{src}`: {note}"]
        y += [""]
        (self.root / "README.md").write_text("\n".join(y), encoding="utf-8")
