"""The per-row evidence of ``hpe audit --consistency``, spilled to an unnamed temporary file (flat memory).

One fixed-size record per audited row, in input order (:data:`RECORD`, 61
bytes): its file line, |yaw|, landmark angle and residual, why it was not
landmark-checked, and the label and landmark-fit matrices in half precision (for
drawing only). The ranking streams the records back in chunks once the
table-wide expectation is known; ``-o`` reads them back in its batches. The file
is opened with :func:`tempfile.TemporaryFile` (unlinked at once: nothing is left
behind, even after a crash) in the system's temporary folder.
"""

from __future__ import annotations

import tempfile

import numpy as np

#: one row's record
RECORD = np.dtype(
    [
        ("line", "<i8"),
        ("abs_yaw", "<f4"),
        ("lm_angle", "<f8"),
        ("lm_res", "<f4"),
        ("lm_code", "u1"),
        ("A", "<f2", (9,)),
        ("F", "<f2", (9,)),
    ]
)


class RowSpill:
    """Append-only file of :data:`RECORD` rows with reads by row range or by a few row indices."""

    def __init__(self):

        self.f = tempfile.TemporaryFile(prefix="hpe_consistency_")
        self.n = 0

    @staticmethod
    def empty(n: int) -> np.ndarray:
        return np.zeros(n, dtype=RECORD)

    def append(self, rec) -> None:
        self.f.seek(0, 2)
        self.f.write(np.ascontiguousarray(rec, dtype=RECORD).tobytes())
        self.n += len(rec)

    def read(self, offset: int, n: int) -> np.ndarray:
        """Rows ``offset .. offset + n`` (clipped to the rows written)."""
        n = max(0, min(n, self.n - offset))
        self.f.seek(offset * RECORD.itemsize)
        return np.frombuffer(self.f.read(n * RECORD.itemsize), dtype=RECORD).copy()

    def take(self, idx) -> np.ndarray:
        """The rows ``idx`` (a few: one read each)."""
        out = self.empty(len(idx))
        for k, i in enumerate(np.asarray(idx, dtype=np.int64)):
            out[k] = self.read(int(i), 1)[0]
        return out

    def chunks(self, size: int = 1 << 18):
        """``(offset, records)`` over all rows, ``size`` rows at a time."""
        for off in range(0, self.n, size):
            yield off, self.read(off, size)

    def close(self) -> None:
        self.f.close()
