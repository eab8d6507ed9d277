"""Which picture each row of a label table is drawn on, and the rows set aside (``hpe draw``).

Every input and output is checked before anything is drawn: rows naming the same picture are grouped, each
picture is found (:class:`hpe_cli.io.images.ImageResolver`) and given its output name, and :class:`RejectBook`
collects the rows that cannot be drawn, numbered as the input numbers them.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import HpeError
from ...io.images import ImageResolver, row_ids
from ...io.rejects import fail_all_rejected
from ...io.transaction import note_input
from .rows import WRITABLE, row_numbers, safe_relative


def group_rows(names, usable, limit):
    """``[(name, rows)]`` of the ``usable`` rows by image name, in order of first appearance; the first ``limit``
    images only when ``limit`` is given."""
    codes, uniques = pd.factorize(names[usable], sort=False)
    order = np.argsort(codes, kind="stable")
    cuts = np.flatnonzero(np.diff(codes[order])) + 1
    items = list(zip(uniques.tolist(), np.split(usable[order], cuts))) if usable.size else []
    return items[:limit] if limit else items


def check_output_exists(path, overwrite):
    """Refuse an existing output ``path`` unless ``overwrite``."""
    if path.exists() and not overwrite:
        raise HpeError(f"{path}: already exists (use --overwrite to replace it)")


def plan_images(items, *, img_root, outdir, canvas, frame, where, overwrite, check_exists=True):
    """Resolve each image and its output name; ``(plan, bad_rows)``.

    ``plan`` is a list of ``[name, rel, ref, rows]`` (``ref`` an :class:`hpe_cli.io.images.ImageRef` or None on
    canvases). Rows naming the same picture (even by different names, e.g. ``a.mat`` and ``a.jpg``) are drawn
    together on it; two different pictures that would be written to the same output name are an error naming
    a row of each.
    """
    resolver = ImageResolver(img_root)
    seqs, cams, frs = row_ids(frame)
    plan, bad_rows, by_rel = [], [], {}
    for name, rows in items:
        i0 = int(rows[0])
        rel = safe_relative(name, where(i0))
        ref = None
        if canvas is None:
            ref = resolver.find(name, seqs[i0], cams[i0], frs[i0])
            if ref is None:
                bad_rows.extend((int(i), f"image not found: {resolver.tried(name, seqs[i0])}") for i in rows)
                continue
            note_input(ref.path or ref.video)  # an image read is an input: no output may replace it
        elif rel.suffix.lower() not in WRITABLE:
            rel = rel.with_name(rel.name + ".png")
        key = str(rel)
        if key in by_rel:
            other = by_rel[key]
            if ref is not None and other[2] is not None and other[2].key == ref.key:
                other[3] = np.sort(np.concatenate([other[3], rows]))
                continue
            raise HpeError(
                f"{where(i0)}: image {name!r} would be written to {outdir / rel}, as "
                f"{other[0]!r} of {where(int(other[3][0])).split(': ', 1)[-1]} is: two different "
                "pictures for one output file (give the images distinct names)"
            )
        dst = outdir / rel
        if ref is not None and ref.path is not None and dst.resolve() == Path(ref.path).resolve():
            raise HpeError(f"{dst}: refusing to overwrite an input image (choose another output folder)")
        if check_exists:
            check_output_exists(dst, overwrite)
        entry = [name, rel, ref, np.asarray(rows)]
        by_rel[key] = entry
        plan.append(entry)
    return plan, bad_rows


class RejectBook:
    """Rejected rows of a draw run: numbered as the input numbers them, checked before anything is drawn.

    ``rejects`` a :class:`hpe_cli.io.Rejects`; ``frame`` the table's columns; ``src`` the
    :class:`~hpe_cli.io.table_source.TableSource`; ``lines`` its line numbers; ``where`` the row namer.
    """

    def __init__(self, rejects, frame, src, lines, where):
        self.rejects, self.frame, self.src, self.lines, self.where = rejects, frame, src, lines, where
        self.rows: list = []

    def add(self, bad):
        """Set aside ``bad`` (``[(row, reason)]``); without a rejects file (or with ``--strict``) the first one is
        the run's error."""
        if not bad:
            return
        bad = sorted(bad)
        self.rows += bad
        idx = np.array([i for i, _ in bad])
        why = [w for _, w in bad]
        if self.rejects.path is None or self.rejects.strict:  # fail before drawing anything
            extra = (
                f" ({len(bad) - 1} more; use --rejects FILE to skip them)"
                if len(bad) > 1
                else " (use --rejects FILE to skip it)"
            )
            raise HpeError(f"{self.where(idx[0])}: {why[0]}{extra if not self.rejects.strict else ''}")
        cols = {c: self.frame[c].to_numpy()[idx] for c in self.frame.columns}
        if Path(self.src.path).is_dir() and "file" in cols:  # a .mat file is one record: named as messages do
            cols["file"] = np.array([self.where(i) for i in idx], dtype=object)
        else:
            cols = {"row": row_numbers(self.src, self.lines, idx), **cols}
        self.rejects.add(cols, why)

    def counts(self) -> dict:
        """Rejected rows by reason (the text before the first colon)."""
        return dict(Counter(why.split(":")[0] for _, why in self.rows))

    def finish(self, drawn):
        """Write the rejects file; a run that drew nothing because every row was rejected is an error."""
        if drawn == 0 and self.rows:  # the rejects file is still written: it says why
            fail_all_rejected(
                self.rejects,
                f"{self.src.path}: nothing drawn: all {len(self.rows)} row(s) rejected "
                f"(first: {self.where(self.rows[0][0]).split(': ', 1)[-1]}: {self.rows[0][1]})",
            )
        self.rejects.finish()
