"""Drawing the planned pictures of ``hpe draw``: every face of an image at once, then the image (or a tile of a
contact sheet) into the run's staged folder."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ...geometry import draw as g
from ...io.images import ImageResolver
from ..pools import default_threads, run_in_order
from .rows import DEFAULT_LENGTH_FRACTION, write_image


@dataclass(frozen=True)
class Faces:
    """What is drawn for every row: the pose (canonical ``A``, caption ``angles``) and where (``centre``
    (N, 2) and ``length`` (N,) in pixels, NaN where the row does not say; ``from_td`` rows whose centre is
    ``tdx, tdy``, flipped to ``height - 1 - tdy`` when ``flip``)."""

    A: np.ndarray
    angles: np.ndarray
    centre: np.ndarray
    length: np.ndarray
    from_td: np.ndarray
    flip: bool


@dataclass
class Output:
    """Where the drawn pictures go: one file each under ``outdir`` (staged in ``stage``), or tiles of the
    contact sheets ``sheet_paths`` (``grid``: ``cols`` x ``cols`` tiles of ``tile`` pixels a sheet)."""

    stage: Path
    outdir: Path
    grid: bool = False
    cols: int = 6
    tile: int = 256
    sheet_paths: list = field(default_factory=list)
    tiles: list = field(default_factory=list)
    captions: list = field(default_factory=list)

    def prepare(self, img, rel):
        """The drawn picture ``img`` of output name ``rel``, on any thread: written (returns None), or shrunk to
        its tile (returned, for :meth:`keep` in input order)."""
        if not self.grid:
            write_image(img, self.stage / rel, self.outdir / rel)
            return None
        H, W = img.shape[:2]
        s = self.tile / max(H, W)
        small = cv2.resize(img, (max(1, int(W * s)), max(1, int(H * s))), interpolation=cv2.INTER_AREA)
        return small if s < 1 else img

    def keep(self, tile, rel):
        """Keep the ``tile`` that :meth:`prepare` made of ``rel`` (nothing without ``grid``); in input order."""
        if self.grid:
            self.tiles.append(tile)
            self.captions.append(str(rel))

    def finish(self) -> int:
        """Write the contact sheets; their number (0 without tiles)."""
        if not self.grid:
            return 0
        per_sheet = self.cols * self.cols
        for k, p in enumerate(self.sheet_paths):
            part = slice(k * per_sheet, (k + 1) * per_sheet)
            if self.tiles[part]:
                sheet = g.contact_sheet(self.tiles[part], self.cols, self.tile, self.captions[part])
                write_image(sheet, self.stage / p.relative_to(self.outdir), p)
        return len(self.sheet_paths) if self.tiles else 0


def pictures(plan, canvas):
    """Yield ``(plan entry, BGR image or None, reason)``; video frames are decoded once per video, in order."""
    if canvas is not None:
        for entry in plan:
            yield entry, g.blank_canvas(*canvas), ""
        return
    for k, img, why in ImageResolver.read([e[2] for e in plan]):
        yield plan[k], img, why


def draw_faces(img, rows, faces: Faces, options, on_canvas: bool):
    """Draw the poses of ``rows`` on ``img`` (in place) as ``options`` (a ``DrawOptions``) say."""
    H, W = img.shape[:2]
    r = np.asarray(rows)
    c = faces.centre[r].copy()
    flip_rows = faces.from_td[r] & faces.flip
    c[flip_rows, 1] = H - 1 - c[flip_rows, 1]
    missing = ~np.isfinite(c).all(axis=1)
    c[missing] = (W / 2.0, H / 2.0)
    Lr = np.where(np.isfinite(faces.length[r]), faces.length[r], DEFAULT_LENGTH_FRACTION * min(H, W))
    if options.style == "axes":
        g.render_axes(img, faces.A[r], c, Lr, options.thickness)
    else:
        g.render_cube(img, faces.A[r], c, Lr, options.thickness)
    if options.annotate:
        _captions(img, faces.angles[r], c, Lr, options.style, on_canvas)


def _captions(img, angles, c, Lr, style, on_canvas):
    """The angles above each face (dark ink on canvases, light on photographs)."""
    H, W = img.shape[:2]
    ink = ((0, 0, 0), (255, 255, 255)) if on_canvas else ((255, 255, 255), (0, 0, 0))
    for k, (p, y, rr) in enumerate(angles):
        above = (1.15 if style == "axes" else 1.8) * Lr[k]
        g.render_caption(
            img,
            f"p {p:.1f} y {y:.1f} r {rr:.1f}",
            (c[k, 0] - Lr[k], c[k, 1] - above),
            height_px=float(np.clip(Lr[k] / 6, 12.0, 0.05 * max(H, W) + 12.0)),
            colour=ink[0],
            outline=ink[1],
        )


def draw_all(plan, faces: Faces, out: Output, options, book, progress=None) -> dict:
    """Draw every planned picture; an unreadable one sets its rows aside in ``book``. Returns ``faces``,
    ``images``, ``sheets`` and ``rejects`` (reason -> rows).

    The pictures are drawn (and written, or shrunk to tiles) on ``options.threads`` threads
    (:func:`~hpe_cli.pipelines.pools.default_threads`) and taken in input order, so the output is the same
    whatever the number.
    """
    n = {"faces": 0, "images": 0}

    def work(picture):
        (_, rel, ref, rows), img, _why = picture
        if img is None:
            return None
        draw_faces(img, rows, faces, options, on_canvas=ref is None)
        return out.prepare(img, rel)

    def finish(picture, tile):
        (_, rel, _ref, rows), img, why = picture
        if img is None:
            book.add([(int(i), why) for i in rows])
            return
        n["faces"] += len(rows)
        n["images"] += 1
        out.keep(tile, rel)
        if progress is not None:
            progress.update(1)

    threads = default_threads(options.threads)
    run_in_order(((p,) for p in pictures(plan, options.canvas)), work, finish, threads)
    sheets = out.finish()
    return {"faces": n["faces"], "images": n["images"], "sheets": sheets, "rejects": book.counts()}
