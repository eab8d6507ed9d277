"""io.background.BackgroundFile: order, appended files (kernel copy and buffered fallback), errors, abort."""

import errno
import os

import pytest

from hpe_cli.io.background import BackgroundFile


def test_writes_and_appended_files_keep_their_order(tmp_path):
    parts = []
    for k in range(5):
        p = tmp_path / f"p{k}"
        p.write_bytes(bytes([65 + k]) * (1000 + 37 * k))
        parts.append(p)
    out = tmp_path / "out"
    bf = BackgroundFile(open(out, "wb"), depth=2)
    expect = b""
    for k, p in enumerate(parts):
        bf.write(b"<%d>" % k)
        bf.write(memoryview(b"xyz")[1:])
        bf.copy_from(p)
        p.unlink()  # opened by copy_from: the part may go at once
        expect += b"<%d>" % k + b"yz" + bytes([65 + k]) * (1000 + 37 * k)
    bf.close()
    assert out.read_bytes() == expect


def test_buffered_fallback_when_the_kernel_cannot_copy(tmp_path, monkeypatch):
    def no_copy(*a, **k):
        raise OSError(errno.EXDEV, "cross-device")

    monkeypatch.setattr(os, "copy_file_range", no_copy, raising=False)
    src = tmp_path / "src"
    src.write_bytes(os.urandom(3 << 20))
    out = tmp_path / "out"
    bf = BackgroundFile(open(out, "wb"))
    bf.write(b"head")
    bf.copy_from(src)
    bf.write(b"tail")
    bf.close()
    assert out.read_bytes() == b"head" + src.read_bytes() + b"tail"


class _Full:
    """A file whose second write fails with ENOSPC."""

    def __init__(self):
        self.n = 0
        self.closed = False

    def write(self, data):
        self.n += 1
        if self.n >= 2:
            raise OSError(errno.ENOSPC, "No space left on device")

    def close(self):
        self.closed = True


def test_a_failed_write_is_raised_in_the_caller():
    bf = BackgroundFile(_Full(), depth=1)
    bf.write(b"a")
    bf.write(b"b")  # fails in the thread
    with pytest.raises(OSError) as e:
        bf.write(b"c")  # waits for "b": its error comes back here
        bf.close()
    assert e.value.errno == errno.ENOSPC
    bf.abort()
    assert bf.fh.closed


def test_abort_never_raises_and_closes():
    bf = BackgroundFile(_Full(), depth=4)
    for _ in range(4):
        bf.write(b"x")
    bf.abort()
    assert bf.fh.closed


class _Slow:
    """A file that holds every write until released, and records how many bytes were queued at once."""

    def __init__(self, bf_ref):
        import threading

        self.gate = threading.Event()
        self.bf_ref = bf_ref
        self.data = []
        self.closed = False

    def write(self, data):
        self.gate.wait(5)
        self.data.append(bytes(data))

    def close(self):
        self.closed = True


@pytest.mark.parametrize("depth,max_bytes,sizes", [(8, 100, [40] * 10), (3, 10**6, [5] * 10), (8, 100, [250, 10, 10])])
def test_the_queue_is_bounded_in_writes_and_bytes(depth, max_bytes, sizes):
    """At most ``depth`` writes and ``max_bytes`` bytes wait (a bigger write goes alone), and order is kept."""
    import threading

    holder = []
    fh = _Slow(holder)
    bf = BackgroundFile(fh, depth=depth, max_bytes=max_bytes)
    seen = []

    def writer():
        for k, n in enumerate(sizes):
            bf.write(bytes([k]) * n)
            seen.append((len(bf._pending), bf._queued))

    t = threading.Thread(target=writer)
    t.start()
    t.join(0.3)  # the writer is blocked by the bounds while the file holds every write
    assert t.is_alive() == (len(sizes) > depth or sum(sizes) > max_bytes)
    fh.gate.set()
    t.join(5)
    bf.close()
    assert fh.data == [bytes([k]) * n for k, n in enumerate(sizes)]
    for count, queued in seen:
        assert count <= depth
        assert queued <= max(max_bytes, max(sizes))
