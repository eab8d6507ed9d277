"""The dataset readers of :data:`~hpe_cli.io.dataset_readers.READERS`: folders and archives read as label tables.

Each registers itself here (the datasets layer reads the files, it does not know the io registry): the
300W-LP/AFLW2000 ``.mat`` files, the 300W-LP root or zip, DAD-3DHeads and BIWI. The dataset modules are imported
when a reader's ``detect`` or ``open`` runs: a plain CSV or Parquet input (``hpe convert labels.csv``) loads none.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import HpeError
from .dataset_readers import register_reader
from .readers import frame_source, stream_source


def _is_mat(path: Path) -> bool:
    if path.is_file():
        return path.name.lower().endswith(".mat")
    return path.is_dir() and any(path.glob("*.mat"))


@register_reader(
    "mat",
    _is_mat,
    system="300w_lp",
    key=("file",),
    landmarks="ibug68",
    doc="300W-LP/AFLW2000 ``.mat`` files (``Pose_Para`` angles in degrees, ``pt2d``/``pt3d_68`` landmarks): one "
    "file or a folder of them; a row is named by its file",
)
def open_mat(path: Path, *, batch_size: int, with_lines: bool = False):
    from ..datasets.mat import read_mat_dir  # lazy: start-up

    return frame_source(path, read_mat_dir(path), batch_size, with_lines)


def _is_w300lp(path: Path) -> bool:
    if path.is_file():
        return path.name.lower().endswith(".zip")
    if not path.is_dir():
        return False
    from ..datasets.w300lp import is_w300lp_root  # lazy: start-up

    return is_w300lp_root(path)


@register_reader(
    "300w-lp",
    _is_w300lp,
    system="300w_lp",
    key=("image",),
    landmarks="ibug68",
    doc="the 300W-LP root (its AFW/HELEN/IBUG/LFPW folders and ``landmarks/``) or ``300W-LP.zip``, streamed",
)
def open_300w_lp(path: Path, *, batch_size: int, with_lines: bool = False):
    from ..datasets.w300lp import is_w300lp_zip, open_w300lp  # lazy: start-up

    if path.is_file() and not is_w300lp_zip(path):
        raise HpeError(f"{path}: expected a 300W-LP zip with AFW/HELEN/IBUG/LFPW .mat members")
    return stream_source(path, open_w300lp(path), with_lines)


def _is_dad3dheads(path: Path) -> bool:
    if not (path.is_dir() or path.suffix.lower() == ".json"):
        return False
    from ..datasets.dad3dheads import is_dad3dheads  # lazy: start-up

    return is_dad3dheads(path)


@register_reader(
    "dad3dheads",
    _is_dad3dheads,
    system="dad3dheads",
    key=("item_id",),
    doc="DAD-3DHeads: the root, a subset folder or a ``<subset>.json`` metadata file (model-view matrices)",
)
def open_dad3dheads(path: Path, *, batch_size: int, with_lines: bool = False):
    from ..datasets.dad3dheads import read_dad3dheads  # lazy: start-up

    return frame_source(path, read_dad3dheads(path), batch_size, with_lines)


def _is_biwi(path: Path) -> bool:
    name = path.name.lower()
    if path.is_file():
        return name.endswith((".tgz", ".tar.gz")) or (
            name.startswith("frame_") and name.endswith(("_pose.txt", "_pose.bin"))
        )
    return path.is_dir() and next(path.rglob("frame_*_pose.*"), None) is not None


@register_reader(
    "biwi",
    _is_biwi,
    system="biwi",
    key=("sequence", "frame"),
    doc="BIWI pose files ``frame_XXXXX_pose.txt``/``.bin`` (a folder, one file) or ``db_annotations.tgz``; a row "
    "is named by its file",
)
def open_biwi(path: Path, *, batch_size: int, with_lines: bool = False):
    from ..datasets.biwi import read_biwi  # lazy: start-up

    bad: list = []  # unreadable or invalid pose files: rejects of the commands that read the table
    table = read_biwi(path, bad=bad)
    out = table[["file", "sequence", "frame", "pitch", "yaw", "roll", "center_x", "center_y", "center_z"]].copy()
    # the key of each row: sequence + frame, and the RGB frame they label (BIWI's NN/frame_XXXXX_rgb.png)
    out.insert(1, "image", [f"{s}/frame_{int(f):05d}_rgb.png" for s, f in zip(out["sequence"], out["frame"])])
    out.attrs["system"] = "biwi"
    out.attrs["one_record_files"] = True
    out.attrs["bad_files"] = [(b["file"], b["reason"]) for b in bad]
    return frame_source(path, out, batch_size, with_lines)
