"""Export options and the names shared by the stages."""

from __future__ import annotations

from dataclasses import dataclass, field

A_COLS = [f"a{i}{j}" for i in range(3) for j in range(3)]
MATRIX_COLS = [f"r{i}{j}" for i in range(3) for j in range(3)]
META = ["source", "input", "row", "image", "sequence", "camera", "frame", "person_id", "subject"]
SPLIT_NAMES = {1: ["train"], 2: ["train", "val"], 3: ["train", "val", "test"]}
LICENCES = {
    "cmu_panoptic": "CMU Panoptic Studio (domedb.perception.cs.cmu.edu): non-commercial research use; cite Joo et "
    "al. Labels relabelled by hpe from the 3-D face landmarks.",
    "agora": "AGORA (agora.is.tue.mpg.de): its licence allows non-commercial scientific research only.",
    "300w_lp": "300W-LP / AFLW2000-3D (3DDFA, Zhu et al.): research use only; images from 300W/AFLW keep their "
    "original terms.",
    "biwi": "BIWI Kinect Head Pose (ETH Zurich): research use only.",
    "table": "a label table: check the licence of the dataset it came from.",
}
NO_VIDEO = "no image (hdImgs missing; video source not available)"
NO_FILES = "no image (neither hdImgs/<cam>/<cam>_<frame>.jpg nor hdVideos/hd_<cam>.mp4 found)"


@dataclass
class ExportOptions:
    layout: str
    images: tuple = ()
    system: object = None
    input_system: object = None
    radians: bool = False
    form: str | None = None
    trainer: str | None = None
    crop_scale: float | None = None
    square: bool | None = None
    size: int | None = None
    quality: int = 95
    pad_value: int = 0
    min_inside: float = 0.5
    split: str | None = None
    split_file: str | None = None
    exclude: str | None = None
    min_change: float | None = None
    balance: str | None = None
    seed: int = 0
    drop_images_with_rejects: bool = False
    workers: int = 1
    scheduler: str | None = None
    resume: bool = False
    overwrite: bool = False
    rejects: str | None = None
    strict: bool = False
    quiet: bool = True
    sampling_notes: list = field(default_factory=list)
