"""Indexing hdFace3d.tar: the header scanner (fast path) against the stdlib tarfile path.

Oracles: CPython's ``tarfile`` (``_tar_frames_tarfile`` and ``TarFile.getmembers``) on archives
written by GNU tar (an independent writer) from the real Panoptic faces, on the real BIWI GNU tar,
on archives written by ``tarfile`` in ustar/GNU/pax formats, on hand-made headers, and on random
archives with random truncations and byte flips (Hypothesis): either both paths give the same
dict, or both raise the same message; the fast path either agrees or gives up (None).
"""

from __future__ import annotations

import gzip
import io
import shutil
import subprocess
import tarfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hpe_cli.datasets import panoptic as pan

ROOT = Path(__file__).resolve().parents[2]
REALDATA = ROOT.parent / "shared" / "realdata"
FACE = "hdFace3d/faceRecon3D_hd{:08d}.json"
LONG_DIR = "hdFace3d/" + "a" * 70 + "/" + "b" * 40  # a member under it is longer than 100 characters


def _outcome(fn, path):
    try:
        return "ok", fn(path)
    except Exception as exc:  # noqa: BLE001 - the two paths must fail alike, whatever the error
        return type(exc).__name__, str(exc)


def check_same(path, fast_taken=None):
    """tar_frames equals the tarfile path (result and dict order, or error); the fast path agrees or gives up."""
    slow = _outcome(pan._tar_frames_tarfile, path)
    got = _outcome(pan.tar_frames, path)
    assert got == slow
    if slow[0] == "ok":
        assert list(got[1]) == list(slow[1])
    fast = pan._tar_frames_fast(path)
    assert fast is None or (slow[0] == "ok" and fast == slow[1] and list(fast) == list(slow[1]))
    if fast_taken is not None:
        assert (fast is not None) == fast_taken
    return slow


def members_of(path):
    with tarfile.open(path, "r:") as tf:
        return [(m.name, m.isdir(), m.offset_data, m.size) for m in tf.getmembers()]


def write_tar(path, entries, fmt=tarfile.USTAR_FORMAT):
    """entries: (name, data bytes or None for a directory)."""
    with tarfile.open(path, "w", format=fmt) as tf:
        for name, data in entries:
            info = tarfile.TarInfo(name)
            info.mtime, info.mode = 1_600_000_000, 0o644
            if data is None:
                info.type, info.mode = tarfile.DIRTYPE, 0o755
                tf.addfile(info)
            else:
                info.size = len(data)
                tf.addfile(info, io.BytesIO(data))
    return path


def face_json(k: int, n: int = 300) -> bytes:
    return (b'{"version": 0.7, "people": [], "frame": %d}' % k).ljust(n, b" ")


# ------------------------------------------------------------------ real data
@pytest.mark.parametrize(
    "fmt,plain", [("gnu", True), ("oldgnu", True), ("ustar", True), ("posix", None), ("v7", False)]
)
def test_real_panoptic_faces_packed_by_gnu_tar(tmp_path, fmt, plain):
    src = REALDATA / "panoptic_160906_pizza1" / "hdFace3d"
    if not src.is_dir():
        pytest.skip("../shared/realdata/panoptic_160906_pizza1 is not available")
    if (
        shutil.which("tar") is None
        or b"GNU tar" not in subprocess.run(["tar", "--version"], capture_output=True).stdout
    ):
        pytest.skip("GNU tar is not installed")
    seq = tmp_path / "seq"
    shutil.copytree(src, seq / "hdFace3d")
    tar = tmp_path / "hdFace3d.tar"
    subprocess.run(["tar", f"--format={fmt}", "-cf", str(tar), "-C", str(seq), "hdFace3d"], check=True)
    status, frames = check_same(tar, fast_taken=plain)
    assert status == "ok" and len(frames) == 10 and min(frames) == 1147
    for k, ref in frames.items():  # the offsets point at the real files' bytes
        assert ref.read_bytes() == (src / f"faceRecon3D_hd{k:08d}.json").read_bytes()
    if plain:
        assert pan._scan_plain_tar(tar) == members_of(tar)  # the directory member too


def test_real_biwi_gnu_tar_members(tmp_path):
    tgz = REALDATA / "biwi" / "db_annotations.tgz"
    if not tgz.exists():
        pytest.skip("../shared/realdata/biwi is not available")
    tar = tmp_path / "db_annotations.tar"
    tar.write_bytes(gzip.decompress(tgz.read_bytes()))  # written by GNU tar in 2012 (gfanelli/biwi)
    found = pan._scan_plain_tar(tar)
    assert found is not None and len(found) > 1000
    assert found == members_of(tar)
    assert check_same(tar, fast_taken=True) == ("ok", {})


# ------------------------------------------------------------ tarfile formats
def _mixed_entries():
    return [
        ("hdFace3d", None),
        ("hdFace3d/readme.txt", b"not a face\n"),
        (FACE.format(5), face_json(5)),
        ("other/faceRecon3D_hd00000003.json", face_json(3, 700)),
        (FACE.format(4), face_json(4, 512)),
        ("hdFace3d/faceRecon3D_hd00000009.json.bak", b"{}"),
        ("hdFace3d/sub/", None),
        (FACE.format(7), b""),
        (FACE.format(6), face_json(6, 2000)),
    ]


def _long_entries():
    return _mixed_entries() + [
        (LONG_DIR, None),
        (LONG_DIR + "/faceRecon3D_hd00000011.json", face_json(11)),
        ("hdFace3d/" + "c" * 95 + ".txt", b"x" * 10),
    ]


@pytest.mark.parametrize(
    "fmt,long,plain",
    [
        (tarfile.USTAR_FORMAT, False, True),
        (tarfile.USTAR_FORMAT, True, True),  # long names: the ustar prefix
        (tarfile.GNU_FORMAT, False, True),
        (tarfile.GNU_FORMAT, True, False),  # GNU long-name records: tarfile
        (tarfile.PAX_FORMAT, False, True),
        (tarfile.PAX_FORMAT, True, False),
    ],
)  # pax records: tarfile
def test_tarfile_formats(tmp_path, fmt, long, plain):
    tar = write_tar(tmp_path / "hdFace3d.tar", _long_entries() if long else _mixed_entries(), fmt)
    status, frames = check_same(tar, fast_taken=plain)
    assert status == "ok" and list(frames) == ([3, 4, 5, 6, 7, 11] if long else [3, 4, 5, 6, 7])
    assert frames[7].size == 0 and frames[6].size == 2000
    if long:
        assert frames[11].member == LONG_DIR + "/faceRecon3D_hd00000011.json"
    if plain:
        assert pan._scan_plain_tar(tar) == members_of(tar)


def test_fast_path_is_taken_on_a_plain_archive(tmp_path, monkeypatch):
    tar = write_tar(tmp_path / "hdFace3d.tar", _long_entries(), tarfile.USTAR_FORMAT)
    expected = pan.tar_frames(tar)

    def fail(path):
        raise AssertionError("the tarfile path ran")

    monkeypatch.setattr(pan, "_tar_frames_tarfile", fail)
    assert pan.tar_frames(tar) == expected and len(expected) == 6


# ------------------------------------------------------------ hand-made headers
def _chksum(head: bytearray, signed: bool = False) -> bytearray:
    head[148:156] = b" " * 8
    total = sum((b - 256 if signed and b > 127 else b) for b in head)
    head[148:156] = b"%06o\0 " % (total & 0o777777)
    return head


def _patched(tar: Path, member: int, changes: dict, signed: bool = False) -> Path:
    """Rewrite header number ``member`` (0-based) with {offset: bytes}, checksum recomputed."""
    data = bytearray(tar.read_bytes())
    off = [m[2] - 512 for m in members_of(tar)][member]
    head = data[off : off + 512]
    for at, value in changes.items():
        head[at : at + len(value)] = value
    data[off : off + 512] = _chksum(head, signed)
    tar.write_bytes(bytes(data))
    return tar


def _plain(tmp_path):
    return write_tar(
        tmp_path / "hdFace3d.tar", [("hdFace3d", None)] + [(FACE.format(k), face_json(k)) for k in (1, 2, 3)]
    )


@pytest.mark.parametrize(
    "member,changes,signed,plain",
    [
        (1, {0: "hdFace3d/é/faceRecon3D_hd00000001.json".encode() + b"\0"}, False, True),  # utf-8 name
        (1, {0: b"hdFace3d/\xff\xfe/faceRecon3D_hd00000001.json\0"}, False, True),  # surrogateescape
        (1, {0: b"hdFace3d/\xff/faceRecon3D_hd00000001.json\0"}, True, True),  # signed checksum (old tars)
        (1, {100: b"000644 \0", 108: b"000000 \0"}, False, True),  # bsdtar's digits, space, NUL
        (1, {124: b"00000000454 "}, False, True),  # size ended by a space
        (1, {100: b"   644 \0"}, False, False),  # leading spaces: tarfile's business
        (1, {100: b"0006 44\0"}, False, False),  # not a number for tarfile: unreadable header
        (2, {124: b"\x80" + bytes(10) + b"\x01"}, False, False),  # base-256 size
        (2, {156: b"2"}, False, False),  # a symlink
        (2, {156: b"\0"}, False, True),  # an old-style regular file
        (0, {156: b"\0", 0: b"hdFace3d/\0"}, False, True),  # V7: a file named "x/" is a directory
        (0, {124: b"00000000001\0"}, False, False),  # a directory with data
        (2, {257: b"ustar\0\0\0"}, False, False),  # other magic
        (2, {345: b"deep/prefix\0"}, False, True),  # a ustar prefix
        (3, {124: b"77777777777\0"}, False, False),  # a size past the end of the file
    ],
)
def test_hand_made_headers(tmp_path, member, changes, signed, plain):
    tar = _patched(_plain(tmp_path), member, changes, signed)
    check_same(tar, fast_taken=plain)


def test_directory_with_a_size_falls_back(tmp_path):
    # tarfile reads the next header right after a directory's, whatever its size says: here the
    # size (512) would skip the empty member after it, and the walk would land on a valid header
    tar = write_tar(
        tmp_path / "hdFace3d.tar", [("hdFace3d", None), (FACE.format(1), b""), (FACE.format(2), face_json(2))]
    )
    _patched(tar, 0, {124: b"00000001000\0"})
    assert list(check_same(tar, fast_taken=False)[1]) == [1, 2]


def test_damaged_archives_fall_back_with_the_same_errors(tmp_path):
    tar = _plain(tmp_path)
    data = tar.read_bytes()
    refs = list(pan.tar_frames(tar).values())
    end = refs[-1].offset + 512  # the first end-of-archive block
    cases = {
        "one zero block": (data[: end + 512], True),
        "no end blocks": (data[:end], False),
        "cut in the last member": (data[: refs[-1].offset + 100], False),
        "cut in a header": (data[: refs[-1].offset - 200], False),
        "garbage after the end": (data + b"x", False),
        "bad checksum": (data[: refs[1].offset - 512 + 150] + b"9" + data[refs[1].offset - 512 + 151 :], False),
        "empty": (b"", False),
        "not a tar": (b"not a tar at all" * 100, False),
        "zeros only": (bytes(4096), True),
    }
    for name, (raw, plain) in cases.items():
        tar.write_bytes(raw)
        check_same(tar, fast_taken=plain)
    write_tar(tar, [(FACE.format(6), b"{}"), ("x/faceRecon3D_hd6.json", b"{}")])
    assert check_same(tar, fast_taken=False)[0] == "HpeError"  # duplicates: tarfile's message


# ------------------------------------------------------------------ property
_NAMES = st.one_of(
    st.builds(lambda k, w: f"hdFace3d/faceRecon3D_hd{k:0{w}d}.json", st.integers(0, 40), st.sampled_from([1, 8])),
    st.builds(lambda k: f"{LONG_DIR}/faceRecon3D_hd{k:08d}.json", st.integers(0, 40)),
    st.sampled_from(
        [
            "hdFace3d/readme.txt",
            "faceRecon3D_hd00000001.json",
            "hdFace3d/é.json",
            "hdFace3d/" + "d" * 120 + "/faceRecon3D_hd00000002.json",
        ]
    ),
)
_ENTRY = st.tuples(_NAMES, st.one_of(st.none(), st.integers(0, 2000)))
_MUTATION = st.one_of(
    st.just(None),
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), st.lists(st.tuples(st.floats(0, 1), st.integers(1, 255)), min_size=1, max_size=4)),
    st.tuples(
        st.just("flip header"),
        st.lists(st.tuples(st.integers(0, 8), st.integers(0, 511), st.integers(1, 255)), min_size=1, max_size=3),
    ),
)


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(
    entries=st.lists(_ENTRY, max_size=9),
    fmt=st.sampled_from([tarfile.USTAR_FORMAT, tarfile.GNU_FORMAT, tarfile.PAX_FORMAT]),
    mutation=_MUTATION,
)
def test_random_archives_agree_with_tarfile(tmp_path_factory, entries, fmt, mutation):
    tar = tmp_path_factory.mktemp("prop") / "hdFace3d.tar"
    try:
        write_tar(tar, [(n, None if s is None else bytes([s % 251]) * s) for n, s in entries], fmt)
    except ValueError:  # a name ustar cannot hold
        return
    data = bytearray(tar.read_bytes())
    if mutation is not None and data:
        if mutation[0] == "truncate":
            data = data[: int(mutation[1] * len(data))]
        elif mutation[0] == "flip":
            for at, x in mutation[1]:
                data[min(int(at * len(data)), len(data) - 1)] ^= x
        else:  # inside a member header, where the checks matter
            heads = [m[2] - 512 for m in members_of(tar)] or [0]
            for which, at, x in mutation[1]:
                data[heads[which % len(heads)] + at] ^= x
    tar.write_bytes(bytes(data))
    check_same(tar)
