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

import os
from pathlib import Path

import numpy as np

from ..errors import HpeError


class VideoFrames:
    """Sequential access to the frames of one video.

    Parameters
    ----------
    video_path : str or Path
        An ``.mp4`` (anything OpenCV's ``VideoCapture`` opens).
    expected_size : (int, int), optional
        ``(width, height)`` the camera's calibration gives (``Cameras.width/height``,
        Panoptic's ``resolution``). When given, :meth:`read` first checks the video's
        frame size against it (:meth:`check_size`) and every decoded frame too: a
        1280x720 video of a camera calibrated at 1920x1080 is an error naming the
        video and both sizes, never crops from the wrong pixels.

    Examples
    --------
    >>> for frame, image, reason in VideoFrames("hdVideos/hd_00_08.mp4").read([0, 10, 20]):  # doctest: +SKIP
    ...     if image is None:
    ...         print(frame, reason)
    >>> VideoFrames("hdVideos/hd_00_08.mp4", expected_size=(1920, 1080)).check_size()  # doctest: +SKIP
    (1920, 1080)
    """

    def __init__(self, video_path, expected_size=None):
        self.path = Path(video_path)
        self.expected_size = None if expected_size is None else _size(expected_size, self.path)

    def size(self) -> tuple:
        """``(width, height)`` of the video's frames, as the container declares them."""
        cap = self._open()
        try:
            return _cap_size(cap)
        finally:
            cap.release()

    def check_size(self, expected_size=None) -> tuple:
        """Check the video's frame size against ``expected_size`` (default: the one given at construction).

        Returns
        -------
        (width, height)
            The video's size.

        Raises
        ------
        HpeError
            ``VIDEO: frames are 1280x720 pixels, but the calibration gives 1920x1080 for this camera ...``;
            or the video cannot be opened.
        """
        want = self.expected_size if expected_size is None else _size(expected_size, self.path)
        got = self.size()
        if want is not None and 0 in got:  # the container does not say: the first frame does
            cap = self._open()
            try:
                ok, image = cap.read()
            finally:
                cap.release()
            if not ok or image is None:
                raise HpeError(
                    f"{self.path}: no decodable frame to check against the calibration's {want[0]}x{want[1]}"
                )
            got = (image.shape[1], image.shape[0])
        if want is not None:
            self._compare(got, want)
        return got

    def _compare(self, got, want) -> None:
        if tuple(got) != tuple(want):
            raise HpeError(
                f"{self.path}: frames are {got[0]}x{got[1]} pixels, but the calibration gives "
                f"{want[0]}x{want[1]} for this camera; expected the camera's full-resolution video "
                "(crops and projections would use the wrong pixels)"
            )

    def frame_count(self) -> int:
        """The container's frame count (may be approximate; :meth:`read` does not rely on it)."""
        cap = self._open()
        try:
            import cv2

            return int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        finally:
            cap.release()

    def _open(self):

        # libav prints its own decoder complaints ("moov atom not found", "Error at MB") on stderr, past
        # hpe's one line; OpenCV reads this when its FFmpeg backend starts (the first capture of a process)
        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
        import cv2

        if not self.path.is_file():
            raise HpeError(f"{self.path}: no video {self.path.name}")
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise HpeError(
                f"{self.path}: cannot open the video {self.path.name} (truncated, or not a video OpenCV can decode)"
            )
        return cap

    def read(self, frame_numbers, seek: bool = False):
        """Yield ``(frame_number, image, reason)`` for each requested frame, ascending.

        Parameters
        ----------
        frame_numbers : iterable of int
            HD frame numbers (video frame index from 0); duplicates are
            yielded once; negative numbers are rejected.
        seek : bool
            Start at the first requested frame with one seek (``CAP_PROP_POS_FRAMES``: FFmpeg seeks to the
            key frame before it and decodes forward), then go on sequentially; used by ``hpe export`` to read
            a block of frames of a long video. A seek that does not land on the frame asked for (the
            position OpenCV reports differs) reads from frame 0 instead; a frame past the container's frame
            count is sought from its last counted frame, so the end is found by decoding (the count may be
            approximate) and reported as in sequential reading.

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
        want = self.expected_size
        try:
            if want is not None and 0 not in _cap_size(cap):  # 0: the container does not say (frames are checked)
                self._compare(_cap_size(cap), want)
            pos = 0  # index of the next frame grab() returns
            first = int(wanted[0])
            if seek and first > 0:
                target, pos = _seek(cap, first)
                if pos != target:  # the seek did not land where asked: decode from the start
                    cap.release()
                    cap, pos = self._open(), 0
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
                    if want is not None:
                        self._compare((image.shape[1], image.shape[0]), want)
                    yield f, image, ""
        finally:
            cap.release()


def _seek(cap, frame: int) -> tuple:
    """Seek ``cap`` to ``frame``, or to the last frame the container counts when that is before ``frame`` (the
    grabs from there find the real end, or the frames a low count missed). Returns ``(target, position OpenCV
    reports after the seek)``; -1 when the seek failed."""
    import cv2

    count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    target = count - 1 if 0 < count <= frame else frame
    if not cap.set(cv2.CAP_PROP_POS_FRAMES, target):
        return target, -1
    return target, int(cap.get(cv2.CAP_PROP_POS_FRAMES))


def _cap_size(cap) -> tuple:
    import cv2

    return int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))


def _size(value, path) -> tuple:
    """``(width, height)`` as two positive ints."""
    try:
        w, h = (int(v) for v in value)
    except (TypeError, ValueError):
        raise HpeError(f"{path}: expected_size: expected (width, height), got {value!r}") from None
    if w <= 0 or h <= 0:
        raise HpeError(f"{path}: expected_size: expected a positive (width, height), got {value!r}")
    return w, h


__all__ = ["VideoFrames"]
