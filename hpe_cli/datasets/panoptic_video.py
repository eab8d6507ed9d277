"""Frames of a CMU Panoptic HD video (``hdVideos/hd_00_XX.mp4``) by HD frame number.

panoptic-toolbox's ``scripts/hdImgsExtractor.sh`` extracts every frame with
``ffmpeg -i hdVideos/hd_00_XX.mp4 -start_number 0 hdImgs/00_XX/00_XX_%08d.jpg``,
so image ``k`` is the video's frame ``k`` counted from 0, and that is the HD
frame number of ``hdFace3d/faceRecon3D_hd%08d.json`` (WHENet's
``prepare_images.py`` reads the video the same way). :class:`VideoFrames`
decodes a video once, sequentially: it ``grab()``s the frames it does not
need (demuxed and decoded but not converted) and ``retrieve()``s only the
ones asked for.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HpeError


class VideoFrames:
    """Sequential access to the frames of one video.

    Parameters
    ----------
    video_path : str or Path
        An ``.mp4`` (anything OpenCV's ``VideoCapture`` opens).

    Examples
    --------
    >>> for frame, image, reason in VideoFrames("hdVideos/hd_00_08.mp4").read([0, 10, 20]):  # doctest: +SKIP
    ...     if image is None:
    ...         print(frame, reason)
    """

    def __init__(self, video_path):
        self.path = Path(video_path)

    def frame_count(self) -> int:
        """The container's frame count (may be approximate; :meth:`read` does not rely on it)."""
        cap = self._open()
        try:
            import cv2

            return int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        finally:
            cap.release()

    def _open(self):
        import cv2

        if not self.path.is_file():
            raise HpeError(f"{self.path}: no video {self.path.name}")
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise HpeError(f"{self.path}: cannot open the video {self.path.name} (truncated, or not a video "
                           "OpenCV can decode)")
        return cap

    def read(self, frame_numbers):
        """Yield ``(frame_number, image, reason)`` for each requested frame, ascending.

        Parameters
        ----------
        frame_numbers : iterable of int
            HD frame numbers (video frame index from 0); duplicates are
            yielded once; negative numbers are rejected.

        Yields
        ------
        frame_number : int
        image : ndarray (H, W, 3) uint8 BGR, or None
        reason : str
            ``""`` when ``image`` is given, else why not (``"past the end of
            the video (N frames)"``, ``"frame could not be decoded"``,
            ``"negative frame number"``).
        """
        wanted = np.unique(np.asarray(list(frame_numbers), dtype=np.int64))
        if wanted.size == 0:
            return
        neg = wanted[wanted < 0]
        for f in neg:
            yield int(f), None, "negative frame number"
        wanted = wanted[wanted >= 0]
        if wanted.size == 0:
            return
        try:
            cap = self._open()
        except HpeError as exc:
            reason = str(exc).split(": ", 1)[-1]
            for f in wanted.tolist():
                yield f, None, reason
            return
        try:
            pos = 0  # index of the next frame grab() returns
            for f in wanted.tolist():
                ended = False
                while pos < f:
                    if not cap.grab():
                        ended = True
                        break
                    pos += 1
                if ended or not cap.grab():
                    yield f, None, f"past the end of the video ({pos} frames)"
                    for g in wanted[wanted > f].tolist():
                        yield g, None, f"past the end of the video ({pos} frames)"
                    return
                pos += 1
                ok, image = cap.retrieve()
                if not ok or image is None:
                    yield f, None, "frame could not be decoded"
                else:
                    yield f, image, ""
        finally:
            cap.release()


__all__ = ["VideoFrames"]
