"""Column maps, delimiters, headerless lists and the named label-list formats.

Everything here sits on top of :func:`hpe_cli.io.readers.open_table`: it
renames columns (``--columns-map pitch=Pitch,yaw=Yaw,roll=Roll``), reads
delimited text with or without a header (``--delimiter ';' --no-header
--names image,yaw,pitch,roll``), and reads the label lists the field ships
(``--input-format``):

``whenet``
    WHENet's ``annotation.txt``: ``image,yaw,pitch,roll`` per line, no header
    (the layout :mod:`hpe_cli.io.whenet_txt` writes, after WHENet's data
    preparation; angles in the ``whenet`` system).
``opal23``
    OPAL's annotation lists (``pcr-upm/opal23_headpose``, ``annotations/*_ann*.txt``,
    read by ``test/opal23_headpose_panoptic.py::load_annotations``): ``;``
    separated, a first line ``#;image;x_min;y_min;w;h;yaw;pitch;roll`` naming
    the fields after the ``#`` marker, ``@;NAME`` lines switching the database
    (skipped here), and in the AFLW2000 list ``#;image;identity;yaw;pitch;roll;pt_x;pt_y``
    with the landmark x/y pairs filling the rest of the line.
``img2pose-biwi``
    img2pose's ``evaluation/jupyter_notebooks/BIWI_annotations.txt``:
    ``path pitch yaw roll``, space separated, no header (its notebook reads it
    with ``pd.read_csv(delimiter=" ", header=None)``).
``celeba-pose``
    CelebAMask-HQ ``CelebAMask-HQ-pose-anno.txt``: a first line with the count,
    a second line ``Yaw Pitch Raw`` ('Raw' is the dataset's typo for roll),
    then ``<n>.jpg yaw pitch roll`` space separated.
``coco``
    COCO JSON in DirectMHP's schema (``images`` + ``annotations`` with
    ``euler_angles = [pitch, yaw, roll]`` and ``bbox = [x, y, w, h]``), one row
    per annotation.

Every row keeps its 1-based file line (header = line 1) in ``__line__`` when
asked (``with_lines=True``), so rejects can name it; for COCO JSON the number
is the 1-based position of the annotation in ``annotations``.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv

from ..datasets.jsonfile import load_json
from ..errors import HpeError
from .dataset_readers import READERS, input_format_names, register_reader
from .run_options import active_table_options  # noqa: F401
from .table_source import Reject, TableSource

LINE_COL = "__line__"
#: OPAL field names -> hpe column names
_OPAL_NAMES = {"x_min": "bbox_x", "y_min": "bbox_y", "w": "bbox_w", "h": "bbox_h"}
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\- ]*$")


# ------------------------------------------------------------------------------------------- column maps
def parse_columns_map(text) -> dict:
    """Parse ``"pitch=Pitch,yaw=Yaw"`` into ``{"Pitch": "pitch", "Yaw": "yaw"}`` (source -> hpe name).

    ``text`` may also be a mapping ``{hpe_name: source}`` (the Python API form).
    """
    if text is None or text == "" or text == {}:
        return {}
    if isinstance(text, dict):
        pairs = list(text.items())
    else:
        pairs = []
        for part in str(text).split(","):
            part = part.strip()
            if not part:
                continue
            if "=" not in part:
                raise HpeError(f"--columns-map: expected NAME=SOURCE pairs such as pitch=Pitch, got {part!r}")
            target, source = (s.strip() for s in part.split("=", 1))
            pairs.append((target, source))
    out, targets = {}, set()
    for target, source in pairs:
        if not target or not source:
            raise HpeError(f"--columns-map: expected NAME=SOURCE with both names non-empty, got {target}={source}")
        if target in targets:
            raise HpeError(f"--columns-map: {target!r} is mapped twice")
        if source in out:
            raise HpeError(f"--columns-map: source column {source!r} is mapped twice")
        targets.add(target)
        out[source] = target
    return out


class LenientMap(str):
    """A command-wide ``--columns-map``: applied to each input that has the source columns.

    With several inputs (``hpe evaluate PRED GT``) one map serves them all: an
    input is renamed when it has at least one of the mapped source columns,
    and left alone when it has none (or already has the target names).
    """


def apply_columns_map(src, columns):
    """A :class:`~hpe_cli.io.readers.TableSource` whose columns are renamed by ``columns``.

    The source columns must exist; a renamed column may not collide with a
    column that is kept under the same name.
    """
    mapping = parse_columns_map(columns)
    if not mapping:
        return src

    names = list(src.schema.names)
    if LINE_COL in mapping or LINE_COL in mapping.values():
        raise HpeError(f"--columns-map: {LINE_COL} is reserved for line numbers")
    missing = [s for s in mapping if s not in names]
    if isinstance(columns, LenientMap):
        # an input that already has the hpe name (a .mat folder's image and file) keeps it
        mapping = {k: v for k, v in mapping.items() if k in names and v not in names}
        if not mapping:
            return src
        missing = []
    if missing:
        raise HpeError(
            f"{src.path}: --columns-map names column(s) {', '.join(map(repr, missing))} that the table "
            f"does not have; found {', '.join(n for n in names if n != LINE_COL)}"
        )
    new = [mapping.get(n, n) for n in names]
    dup = sorted({n for n in new if new.count(n) > 1})
    if dup:
        raise HpeError(
            f"{src.path}: --columns-map would give two columns named {', '.join(dup)} (rename or drop the existing one)"
        )
    schema = pa.schema([f.with_name(n) for f, n in zip(src.schema, new)], metadata=src.schema.metadata)
    inner = src._batches

    def batches():
        for b, rejects in inner():
            yield b.rename_columns([mapping.get(n, n) for n in b.schema.names]), rejects

    return replace(src, schema=schema, _batches=batches)


# ------------------------------------------------------------------------------------------- text lists
def _first_lines(path: Path, n: int) -> list:
    out = []
    try:
        with open(path, encoding="utf-8", errors="replace", newline="") as fh:
            for _ in range(n):
                line = fh.readline()
                if not line:
                    break
                out.append(line.rstrip("\r\n"))
    except OSError as exc:
        raise HpeError(f"{path}: cannot read: {exc.strerror or exc}") from None
    return out


def _line_numbers(first_line: int, start: int, count: int, skipped: list) -> np.ndarray:
    """1-based file lines of data rows ``start .. start+count-1``.

    ``skipped`` are the (sorted) file lines that produced no row (comment and
    malformed lines the parser skipped). Row ``k`` sits on line
    ``first_line + k + #{j : skipped[j] - j <= first_line + k}``.
    """
    k = np.arange(start, start + count, dtype=np.int64) + first_line
    if not skipped:
        return k
    gaps = np.asarray(skipped, dtype=np.int64) - np.arange(len(skipped), dtype=np.int64)
    return k + np.searchsorted(gaps, k, side="right")


def _check_text_options(path: Path, delimiter, names):
    """The file exists and is not empty, the delimiter is one character, ``names`` are distinct; returns
    ``names`` stripped (or None)."""
    if not path.is_file():
        raise HpeError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise HpeError(f"{path}: empty file")
    if delimiter is None or len(delimiter) != 1 or delimiter in '\r\n"':
        raise HpeError(f"--delimiter: expected one character such as ',' ';' or '\\t', got {delimiter!r}")
    if names is not None:
        names = [str(n).strip() for n in names]
        if len(set(names)) != len(names) or not all(names):
            raise HpeError(f"--names: expected distinct non-empty names, got {','.join(names)}")
    return names


class _TextRows:
    """One delimited text file read by pyarrow's streaming CSV reader, with the lines it skipped (blank,
    comment and bad lines, for the line numbers) and the bad rows set aside as rejects."""

    def __init__(self, path: Path, delimiter, header, names, skip_lines, comment_prefixes, quoting, string_columns):

        self.path, self.delimiter = path, delimiter
        self.skipped: list = []
        self.bad: list = []
        self.prefixes = tuple(comment_prefixes)
        self.string_columns = list(string_columns)
        self.read_opts = pcsv.ReadOptions(
            use_threads=False,
            block_size=1 << 22,
            skip_rows=skip_lines,
            column_names=None if header else names,
            autogenerate_column_names=(not header and names is None),
        )
        self.parse_opts = pcsv.ParseOptions(
            delimiter=delimiter,
            ignore_empty_lines=False,
            invalid_row_handler=self.handler,
            quote_char='"' if quoting else False,
            newlines_in_values=False,
        )

    def handler(self, row):
        """pyarrow's invalid-row handler: note the line (skipped), and a non-blank, non-comment one as bad."""
        text = row.text or ""
        if row.number is not None:
            if text.strip() == "" or (self.prefixes and text.startswith(self.prefixes)):
                self.skipped.append(int(row.number))
            else:
                self.skipped.append(int(row.number))
                self.bad.append((int(row.number), row.expected_columns, row.actual_columns, text))
        return "skip"

    def make_reader(self):
        """A reader from the file's start, with the string columns declared (a probe finds the columns)."""

        probe = pcsv.open_csv(self.path, read_options=self.read_opts, parse_options=self.parse_opts)
        cols = probe.schema.names
        types = {c: pa.string() for c in self.string_columns if c in cols}
        self.skipped.clear()  # the probe parsed the first block too
        self.bad.clear()
        return pcsv.open_csv(
            self.path,
            read_options=self.read_opts,
            parse_options=self.parse_opts,
            convert_options=pcsv.ConvertOptions(column_types=types, strings_can_be_null=True),
        )

    def take_rejects(self) -> list:
        """The bad rows found since the last call, as rejects."""

        out = [
            Reject(line, f"expected {want} fields separated by {self.delimiter!r}, got {got}", text[:200])
            for line, want, got, text in self.bad
        ]
        self.bad.clear()
        return out

    def batches(self, first_reader: list, first_line: int, line_schema):
        """``(batch with __line__, rejects)``; ``first_reader`` holds the reader already opened, if unused."""

        rdr = first_reader.pop() if first_reader else self.make_reader()
        start = 0
        for b in rdr:
            n = b.num_rows
            lines = _line_numbers(first_line, start, n, self.skipped)
            start += n
            # an empty line parses as a row of nulls: it is not a row of the table
            empty = None
            for col in b.columns:
                v = col.is_null().to_numpy(zero_copy_only=False)
                empty = v if empty is None else (empty & v)
            if empty is not None and empty.any():
                keep = ~empty
                b = b.filter(pa.array(keep))
                lines = lines[keep]
            b = pa.RecordBatch.from_arrays(list(b.columns) + [pa.array(lines, type=pa.int64())], schema=line_schema)
            yield b, self.take_rejects()
        if self.bad:
            yield pa.RecordBatch.from_pylist([], schema=line_schema), self.take_rejects()


def _check_header(path: Path, schema, skip_lines: int) -> None:
    hdr = list(schema.names)
    if len(set(hdr)) != len(hdr):
        raise HpeError(
            f"{path}: line {skip_lines + 1}: the header names a column twice "
            f"({', '.join(sorted({h for h in hdr if hdr.count(h) > 1}))})"
        )


def open_text(
    path,
    batch_size: int = 262_144,
    *,
    delimiter: str = ",",
    header: bool = True,
    names=None,
    skip_lines: int = 0,
    comment_prefixes=(),
    quoting: bool = True,
    string_columns=(),
    with_lines: bool = False,
    system=None,
):
    """Stream a delimited text table.

    Parameters
    ----------
    delimiter : str
        One character (``"\\t"`` for tabs).
    header : bool
        The first line (after ``skip_lines``) names the columns; else ``names``
        (or ``f0, f1, ...``) name them.
    skip_lines : int
        Lines before the header or the data (counts, banners).
    comment_prefixes : tuple of str
        Lines starting with one of these (after the header) are skipped.
    string_columns : iterable of str
        Columns read as text whatever they look like (image names).
    with_lines : bool
        Add ``__line__`` (int64, 1-based file line of each row).
    """

    path = Path(path)
    names = _check_text_options(path, delimiter, names)
    rows = _TextRows(path, delimiter, header, names, skip_lines, comment_prefixes, quoting, string_columns)
    try:
        reader = rows.make_reader()
    except (pa.ArrowInvalid, OSError, UnicodeDecodeError) as exc:
        raise HpeError(f"{path}: cannot read: {' '.join(str(exc).split())[:300]}") from None
    schema = reader.schema
    if header:
        _check_header(path, schema, skip_lines)
    first_line = skip_lines + (2 if header else 1)
    line_schema = schema.append(pa.field(LINE_COL, pa.int64()))
    first_reader = [reader]

    def batches():
        return rows.batches(first_reader, first_line, line_schema)

    return TableSource(path, line_schema if with_lines else schema, None, batches, with_lines, "text", system=system)


def _opal23(path, batch_size, with_lines):
    first = _first_lines(path, 2)
    if not first or not first[0].startswith("#;"):
        raise HpeError(
            f"{path}: line 1: expected OPAL's header '#;image;...;yaw;pitch;roll', "
            f"got {(first[0] if first else '')[:80]!r}"
        )
    fields = [f.strip() for f in first[0].split(";")[1:]]
    base = [_OPAL_NAMES.get(f, f) for f in fields]
    if len(base) >= 2 and base[-2] == "pt_x" and base[-1].startswith("pt_y"):
        base = base[:-2]
        data = [ln for ln in _first_lines(path, 50)[1:] if ln and not ln.startswith(("@", "#"))]
        n_extra = (len(data[0].split(";")) - len(base)) if data else 0
        if n_extra < 0 or n_extra % 2:
            raise HpeError(
                f"{path}: line 2: expected {len(base)} fields then x;y landmark pairs, got {len(base) + n_extra} fields"
            )
        base += [f"lm{i}_{a}" for i in range(n_extra // 2) for a in "xy"]
    for need in ("image", "yaw", "pitch", "roll"):
        if need not in base:
            raise HpeError(f"{path}: line 1: expected a field named {need!r} in OPAL's header, got {';'.join(fields)}")
    return open_text(
        path,
        batch_size,
        delimiter=";",
        header=False,
        names=base,
        skip_lines=1,
        comment_prefixes=("@", "#"),
        quoting=False,
        string_columns=("image", "identity"),
        with_lines=with_lines,
        system=None,
    )


def _celeba(path, batch_size, with_lines):
    first = _first_lines(path, 2)
    try:
        int(first[0].strip())
        ok = len(first) == 2 and [w.lower() for w in first[1].split()] == ["yaw", "pitch", "raw"]
    except (ValueError, IndexError):
        ok = False
    if not ok:
        got = " / ".join(first)[:80]
        raise HpeError(f"{path}: line 1: expected CelebAMask-HQ's count line then 'Yaw Pitch Raw', got {got!r}")
    return open_text(
        path,
        batch_size,
        delimiter=" ",
        header=False,
        names=["image", "yaw", "pitch", "roll"],
        skip_lines=2,
        quoting=False,
        string_columns=("image",),
        with_lines=with_lines,
        system=None,
    )


# ------------------------------------------------------------------------------------------- COCO JSON
def is_coco(doc) -> bool:
    return isinstance(doc, dict) and isinstance(doc.get("images"), list) and isinstance(doc.get("annotations"), list)


def coco_system(doc):
    """The system a COCO file written by ``hpe`` names in ``info["hpe:system"]``, else None."""
    info = doc.get("info") if isinstance(doc, dict) else None
    name = info.get("hpe:system") if isinstance(info, dict) else None
    return name if isinstance(name, str) and name else None


def coco_frame(doc, path="<coco>"):
    """One row per COCO annotation (DirectMHP's schema) as a pandas DataFrame.

    Columns: ``image`` (the image's ``file_name``), ``image_id``,
    ``annotation_id``, ``image_width``, ``image_height``, ``bbox_x, bbox_y,
    bbox_w, bbox_h`` (``bbox = [x, y, w, h]``), ``pitch, yaw, roll``
    (``euler_angles = [pitch, yaw, roll]``, degrees), ``lm{i}_x, lm{i}_y``
    from ``face2d_pts = [[x...], [y...]]`` when every annotation has the same
    number of points (-1 = missing, read as NaN), and ``__line__`` = the
    1-based position of the annotation.
    """
    import pandas as pd

    if not is_coco(doc):
        raise HpeError(f"{path}: expected a COCO object with 'images' and 'annotations' lists")
    images = {}
    for k, im in enumerate(doc["images"]):
        if not isinstance(im, dict) or "id" not in im or "file_name" not in im:
            raise HpeError(f"{path}: images[{k}]: expected an object with 'id' and 'file_name'")
        images[im["id"]] = im
    anns = doc["annotations"]
    n = len(anns)
    cols = {"image": [], "image_id": [], "annotation_id": [], "image_width": [], "image_height": []}
    box = np.full((n, 4), np.nan)
    ang = np.full((n, 3), np.nan)
    pts = []
    for k, a in enumerate(anns):
        where = f"{path}: annotation {k + 1}"
        if not isinstance(a, dict):
            raise HpeError(f"{where}: expected an object, got {type(a).__name__}")
        im = images.get(a.get("image_id"))
        if im is None:
            raise HpeError(f"{where}: image_id {a.get('image_id')!r} is not in 'images'")
        cols["image"].append(str(im["file_name"]))
        cols["image_id"].append(a.get("image_id"))
        cols["annotation_id"].append(a.get("id"))
        cols["image_width"].append(im.get("width"))
        cols["image_height"].append(im.get("height"))
        b, e = a.get("bbox"), a.get("euler_angles")
        if b is not None:
            if not (isinstance(b, list) and len(b) == 4):
                raise HpeError(f"{where}: expected bbox [x, y, w, h], got {str(b)[:60]}")
            box[k] = [np.nan if v is None else v for v in b]
        if e is not None:
            if not (isinstance(e, list) and len(e) == 3):
                raise HpeError(f"{where}: expected euler_angles [pitch, yaw, roll], got {str(e)[:60]}")
            ang[k] = [np.nan if v is None else v for v in e]
        pts.append(a.get("face2d_pts"))
    frame = pd.DataFrame(cols)
    for i, c in enumerate(("bbox_x", "bbox_y", "bbox_w", "bbox_h")):
        frame[c] = box[:, i]
    for i, c in enumerate(("pitch", "yaw", "roll")):
        frame[c] = ang[:, i]
    sizes = {len(p[0]) for p in pts if isinstance(p, list) and len(p) == 2 and isinstance(p[0], list)}
    if n and len(sizes) == 1 and all(isinstance(p, list) and len(p) == 2 for p in pts):
        L = sizes.pop()
        if L and all(len(p[0]) == L and len(p[1]) == L for p in pts):
            xy = np.asarray(pts, dtype=np.float64)  # (n, 2, L)
            xy = np.where((xy[:, :1] == -1) | (xy[:, 1:] == -1), np.nan, xy)
            extra = {}
            for i in range(L):
                extra[f"lm{i}_x"], extra[f"lm{i}_y"] = xy[:, 0, i], xy[:, 1, i]
            frame = pd.concat([frame, pd.DataFrame(extra)], axis=1)
    frame[LINE_COL] = np.arange(1, n + 1, dtype=np.int64)
    return frame


def _frame_source(path, frame, batch_size, with_lines, system=None):

    table = pa.Table.from_pandas(frame, preserve_index=False)  # carries __line__
    schema = table.schema if with_lines else table.schema.remove(table.schema.get_field_index(LINE_COL))

    def batches():
        for b in table.to_batches(max_chunksize=batch_size):
            yield b, []

    return TableSource(Path(path), schema, table.num_rows, batches, with_lines, "json", system=system, unit="row")


# ------------------------------------------------------------------------------------------- dispatch
def open_formatted(
    path,
    batch_size: int = 262_144,
    *,
    input_format=None,
    delimiter=None,
    header: bool = True,
    names=None,
    with_lines: bool = False,
):
    """Open ``path`` as the named input format or as delimited text; None when neither is asked for.

    ``input_format`` names a reader of :data:`~hpe_cli.io.dataset_readers.READERS` with ``input_format`` set;
    ``delimiter``/``header=False``/``names`` read delimited text. Without them this returns None: the readers'
    own detection (``.json`` with COCO keys, ``annotation.txt``, ``CelebAMask-HQ-pose-anno.txt``, a ``.txt``
    whose first line starts with ``#;``, the dataset folders) or the core Parquet/CSV reader takes the path.
    """
    path = Path(path)
    if input_format is not None and input_format not in input_format_names():
        raise HpeError(f"--input-format: expected one of {', '.join(input_format_names())}, got {input_format!r}")
    if input_format is not None and (delimiter is not None or not header or names):
        raise HpeError(
            f"--input-format {input_format} fixes the delimiter and the column names; "
            "drop --delimiter/--no-header/--names (use --columns-map to rename)"
        )
    if input_format is not None:
        if not path.is_file():
            raise HpeError(f"{path}: --input-format {input_format} reads a file, got a folder")
        src = READERS[input_format].open(path, batch_size=batch_size, with_lines=with_lines)
        if src is None:
            raise HpeError(f"{path}: --input-format {input_format} cannot read this file")
        return src
    if delimiter is None and header and not names:
        return None
    if not path.is_file():
        raise HpeError(f"{path}: --delimiter/--no-header/--names apply to a text file, not a folder")
    if path.suffix.lower() in (".parquet", ".pq"):
        raise HpeError(f"{path}: --delimiter/--no-header/--names apply to delimited text, not Parquet")
    if names and header:
        raise HpeError("--names goes with --no-header (with a header line, use --columns-map to rename)")
    delim = delimiter if delimiter is not None else ("\t" if path.suffix.lower() == ".tsv" else ",")
    return open_text(
        path,
        batch_size,
        delimiter=delim,
        header=header,
        names=names,
        string_columns=("image", "file"),
        with_lines=with_lines,
    )


# ------------------------------------------------------------------------------- the named label lists
def _named(file_name: str):
    """``detect`` of a list known by its file name (case-insensitive)."""
    return lambda path: path.is_file() and path.name.lower() == file_name


#: file names the lists above are known by (a ``.txt`` among them is never sniffed as OPAL's)
_LIST_NAMES = ("annotation.txt", "celebamask-hq-pose-anno.txt", "biwi_annotations.txt")


def _is_opal23(path: Path) -> bool:
    if not (path.is_file() and path.name.lower().endswith(".txt")) or path.name.lower() in _LIST_NAMES:
        return False
    first = _first_lines(path, 1)
    return bool(first) and first[0].startswith("#;")


@register_reader(
    "whenet",
    _named("annotation.txt"),
    system="whenet",
    key=("image",),
    doc="WHENet's ``annotation.txt``: ``image,yaw,pitch,roll`` per line, no header",
    input_format=True,
)
def open_whenet_list(path, *, batch_size: int, with_lines: bool = False):
    return open_text(
        path,
        batch_size,
        delimiter=",",
        header=False,
        names=["image", "yaw", "pitch", "roll"],
        quoting=False,
        string_columns=("image",),
        with_lines=with_lines,
        system="whenet",
    )


@register_reader(
    "opal23",
    _is_opal23,
    key=("image",),
    doc="OPAL's annotation lists: ``;`` separated, a first line ``#;image;...;yaw;pitch;roll``",
    input_format=True,
)
def open_opal23_list(path, *, batch_size: int, with_lines: bool = False):
    return _opal23(path, batch_size, with_lines)


@register_reader(
    "img2pose-biwi",
    _named("biwi_annotations.txt"),
    system="300w_lp",
    key=("image",),
    doc="img2pose's ``BIWI_annotations.txt``: ``path pitch yaw roll``, space separated",
    input_format=True,
)
def open_img2pose_biwi_list(path, *, batch_size: int, with_lines: bool = False):
    return open_text(
        path,
        batch_size,
        delimiter=" ",
        header=False,
        names=["image", "pitch", "yaw", "roll"],
        quoting=False,
        string_columns=("image",),
        with_lines=with_lines,
        system="300w_lp",
    )


@register_reader(
    "celeba-pose",
    _named("celebamask-hq-pose-anno.txt"),
    key=("image",),
    doc="CelebAMask-HQ ``CelebAMask-HQ-pose-anno.txt``: count line, ``Yaw Pitch Raw``, then one image a line",
    input_format=True,
)
def open_celeba_list(path, *, batch_size: int, with_lines: bool = False):
    return _celeba(path, batch_size, with_lines)


@register_reader(
    "coco",
    lambda path: path.is_file() and path.name.lower().endswith(".json"),
    key=("image", "annotation_id"),
    doc="COCO JSON in DirectMHP's schema (``euler_angles``, ``bbox``), one row per annotation",
    input_format=True,
)
def open_coco(path, *, batch_size: int, with_lines: bool = False):
    """A COCO file; None for DAD-3DHeads metadata (its reader takes it); any other JSON is an error."""
    doc = load_json(path)
    if is_coco(doc):
        return _frame_source(path, coco_frame(doc, path), batch_size, with_lines, coco_system(doc))
    from ..datasets.dad3dheads import is_dad_metadata  # lazy: start-up

    if is_dad_metadata(doc):
        return None  # a dataset reader takes it
    raise HpeError(
        f"{path}: expected COCO JSON (an object with 'images' and 'annotations'), "
        f"got {type(doc).__name__} with keys "
        f"{', '.join(list(doc)[:8]) if isinstance(doc, dict) else '-'}"
    )
