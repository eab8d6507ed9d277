"""``hpe view``: the page's data, thumbnails (crop, whole frame, cache), rejects, joins and the API."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd

from conftest import hpe as hpe_cmd

from .conftest import page_data


def _images(folder, names, size=(320, 240)):
    """Smooth random texture: JPEG keeps it, and a crop shifted by a few pixels no longer matches."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    for n in names:
        img = cv2.GaussianBlur(rng.uniform(0, 255, (size[1], size[0], 3)), (0, 0), 3)
        img = (img - img.min()) / (img.max() - img.min()) * 255
        cv2.imwrite(str(folder / n), img.astype(np.uint8))


def _table(path, rows):
    pd.DataFrame(rows).to_csv(path, index=False)
    return path


ROWS = [
    {"image": "a.png", "pitch": 0.0, "yaw": 10.0, "roll": 0.0, "bbox_x": 100, "bbox_y": 60, "bbox_w": 80, "bbox_h": 90},
    {"image": "b.png", "pitch": 5.0, "yaw": -95.0, "roll": 3.0, "bbox_x": 20, "bbox_y": 30, "bbox_w": 60, "bbox_h": 60},
    {"image": "a.png", "pitch": -5.0, "yaw": 120.0, "roll": 0.0},  # no box: the whole frame
]


def test_help_has_examples():
    r = hpe_cmd("view", "--help")
    assert r.exit_code == 0 and "Examples:" in r.output and "hpe view" in r.output and "--rejects" in r.output


def test_thumbnails_crop_and_whole_frame(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS)
    page = tmp_path / "page"
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "-q")
    assert r.exit_code == 0, r.output
    d = page_data(page)
    assert d["meta"]["counts"]["whole_frame"] == 1 and d["meta"]["counts"]["shown"] == 3
    assert d["num"]["row"] == [2, 3, 4]  # CSV lines, header = line 1
    # row 1: the square crop 1.6 x the box's longer side around the box centre, resized to 128 px
    a = cv2.imread(str(tmp_path / "img" / "a.png"))
    side = 1.6 * 90
    cx, cy = 140, 105
    x0, y0 = int(np.floor(cx - side / 2)), int(np.floor(cy - side / 2))
    s = int(np.ceil(side))
    want = cv2.resize(a[y0 : y0 + s, x0 : x0 + s], (128, 128), interpolation=cv2.INTER_AREA)
    got = cv2.imread(str(page / "thumbs" / d["thumb"][0]))
    diff = np.abs(got.astype(int) - want.astype(int)).max(axis=2)
    assert np.median(diff) < 12 and (diff > 80).mean() > 0.005  # the same pixels, with the pose drawn over them
    shifted = cv2.resize(a[y0 + 8 : y0 + 8 + s, x0 : x0 + s], (128, 128), interpolation=cv2.INTER_AREA)
    assert np.median(np.abs(got.astype(int) - shifted.astype(int)).max(axis=2)) > 2 * np.median(diff)
    # row 3: the whole 320x240 frame letterboxed into 128x128 (grey bands above and below)
    whole = cv2.imread(str(page / "thumbs" / d["thumb"][2]))
    assert (whole[:10] == 48).all() and (whole[-10:] == 48).all()
    small = cv2.resize(a, (128, 96), interpolation=cv2.INTER_AREA)
    diff = np.median(np.abs(whole[16:112].astype(int) - small.astype(int)).max(axis=2))
    off = np.median(np.abs(whole[18:114].astype(int) - small.astype(int)).max(axis=2))
    assert diff < 16 and off > diff + 4, (diff, off)  # JPEG-level differences, and it is this placement


def test_rerun_on_a_grown_table_reuses_thumbnails(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS[:2])
    page = tmp_path / "page"
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img")
    assert r.exit_code == 0 and "2 thumbnails made, 0 reused" in r.output, r.output
    first = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in (page / "thumbs").iterdir()}
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img")
    assert r.exit_code == 1 and "index.html: exists (use --overwrite" in r.output
    _table(src, ROWS)  # the table grew by one row
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--overwrite")
    assert r.exit_code == 0 and "1 thumbnails made, 2 reused" in r.output, r.output
    for name, (mtime, blob) in first.items():  # untouched
        p = page / "thumbs" / name
        assert p.stat().st_mtime_ns == mtime and p.read_bytes() == blob
    assert len(list((page / "thumbs").iterdir())) == 3
    # a changed label makes a new picture for that row only
    rows = [dict(r) for r in ROWS]
    rows[1]["yaw"] = -80.0
    _table(src, rows)
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--overwrite")
    assert "1 thumbnails made, 2 reused" in r.output, r.output


def test_missing_and_unreadable_images_are_rejects(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    (tmp_path / "img" / "bad.png").write_bytes(b"not a picture")
    rows = ROWS + [dict(ROWS[0], image="gone.png"), dict(ROWS[0], image="bad.png")]
    src = _table(tmp_path / "in.csv", rows)
    page = tmp_path / "page"
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img")
    assert r.exit_code == 1 and not page.exists()
    assert r.output.strip().splitlines()[-1].startswith(f"Error: {src}: line 5: image not found"), r.output
    rej = tmp_path / "rej.csv"
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--rejects", rej)
    assert r.exit_code == 0, r.output
    assert "rejected: 1 image not found; 1 not a readable image" in r.output
    got = pd.read_csv(rej)
    assert got[["row", "image", "reason"]].values.tolist() == [
        [5, "gone.png", "image not found"],
        [6, "bad.png", "not a readable image"],
    ]
    d = page_data(page)
    status = [d["cat"]["status"]["values"][k] for k in d["cat"]["status"]["codes"]]
    assert status == ["ok", "ok", "ok", "image not found", "not a readable image"]
    assert d["thumb"][3] is None and d["thumb"][4] is None


def test_two_tables_without_a_common_key_are_a_usage_error(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS[:2])
    other = _table(tmp_path / "other.csv", [{"name": "a.png", "pitch": 0.0, "yaw": 0.0, "roll": 0.0}])
    r = hpe_cmd("view", src, other, "-o", tmp_path / "page", "--images", tmp_path / "img")
    assert r.exit_code == 2 and "no key column shared" in r.output and "Traceback" not in r.output, r.output
    assert not (tmp_path / "page").exists()


def test_other_rows_joined_by_key_with_the_angle(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", [ROWS[0], dict(ROWS[1], yaw=-60.0)])
    other = _table(
        tmp_path / "other.csv",
        [
            {"image": "b.png", "pitch": 5.0, "yaw": -60.0, "roll": 33.0},
            {"image": "a.png", "pitch": 0, "yaw": 10, "roll": 0},
        ],
    )
    page = tmp_path / "page"
    r = hpe_cmd("view", src, other, "-o", page, "--images", tmp_path / "img")
    assert r.exit_code == 0 and "2 rows paired with" in r.output, r.output
    d = page_data(page)
    assert d["num"]["angle"] == [0.0, 30.0]  # a pure roll difference of 30 degrees
    assert d["num"]["other_roll"][1] == 33.0


def test_api_writes_the_same_page(tmp_path):
    import hpe_cli as hpe

    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS)
    r = hpe_cmd("view", src, "-o", tmp_path / "cli", "--images", tmp_path / "img", "-q")
    assert r.exit_code == 0
    s = hpe.view_file(src, tmp_path / "api", images=tmp_path / "img")
    assert s["shown"] == 3 and s["whole_frame"] == 1
    for name in ("rows.js", "index.html", "view.js", "rows/00000.js"):
        a = (tmp_path / "cli" / name).read_text().replace(str(tmp_path / "cli"), "")
        b = (tmp_path / "api" / name).read_text().replace(str(tmp_path / "api"), "")
        assert a == b, name
    assert sorted(p.name for p in (tmp_path / "cli" / "thumbs").iterdir()) == sorted(
        p.name for p in (tmp_path / "api" / "thumbs").iterdir()
    )


def test_page_loads_nothing_from_the_network(tmp_path):
    """No CDN, no remote font: the only URL in the page's files is the SVG namespace (a name, never fetched)."""
    import re

    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS)
    page = tmp_path / "page"
    assert hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "-q").exit_code == 0
    for name in ("index.html", "view.js", "view.css"):
        text = (page / name).read_text()
        urls = set(re.findall(r"(?:https?:)?//[\w.-]+\.[a-z]{2,}[^\s\"')]*", text))
        assert urls <= {"http://www.w3.org/2000/svg"}, (name, urls)
        assert "fetch(" not in text and "XMLHttpRequest" not in text and "import(" not in text


def test_rows_with_unusable_labels_are_rejects_and_stay_in_the_page(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    rows = [ROWS[0], dict(ROWS[1], yaw=float("nan"))]
    src = _table(tmp_path / "in.csv", rows)
    page, rej = tmp_path / "page", tmp_path / "rej.csv"
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img")
    assert r.exit_code == 1 and f"{src}: line 3:" in r.output and not page.exists(), r.output
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--rejects", rej)
    assert r.exit_code == 0, r.output
    got = pd.read_csv(rej)
    assert got["row"].tolist() == [3] and got["reason"].iloc[0]
    d = page_data(page)
    assert d["meta"]["n"] == 2 and d["thumb"][1] is None
    assert d["cat"]["status"]["values"][d["cat"]["status"]["codes"][1]] == got["reason"].iloc[0]


def test_other_rows_without_a_match_or_a_pose_are_rejects(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS[:2])
    other = _table(
        tmp_path / "other.csv",
        [
            {"image": "a.png", "pitch": 0.0, "yaw": 10.0, "roll": 0.0},
            {"image": "b.png", "pitch": 0.0, "yaw": float("nan"), "roll": 0.0},
            {"image": "c.png", "pitch": 0.0, "yaw": 0.0, "roll": 0.0},
        ],
    )
    r = hpe_cmd("view", src, other, "-o", tmp_path / "page", "--images", tmp_path / "img")
    assert r.exit_code == 1 and f"{other}: line" in r.output, r.output
    rej = tmp_path / "rej.csv"
    r = hpe_cmd("view", src, other, "-o", tmp_path / "page", "--images", tmp_path / "img", "--rejects", rej)
    assert r.exit_code == 0, r.output
    got = pd.read_csv(rej).sort_values("row")
    assert got["row"].tolist() == [3, 4] and got["table"].tolist() == [str(other)] * 2
    assert got["reason"].iloc[1] == f"no row of {src} with this key"
    d = page_data(tmp_path / "page")
    assert d["num"]["angle"][0] == 0.0 and d["num"]["angle"][1] is None


def test_no_frames(tmp_path):
    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS)
    page = tmp_path / "page"
    assert hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--no-frames", "-q").exit_code == 0
    d = page_data(page)
    assert [im["f"] for im in d["images"]] == [None, None] and all(d["thumb"])
    assert not list((page / "frames").iterdir()) if (page / "frames").exists() else True


def test_also_in_angles_and_bad_names(tmp_path):
    """``--also-in``: each row's angles in the named systems (rows.js ``systems``), the labels' own system
    skipped; the API takes names; an unknown name is a usage error (exit 2) naming it."""
    from scipy.spatial.transform import Rotation

    import hpe_cli as hpe

    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS)
    r = hpe_cmd("view", src, "-o", tmp_path / "p", "--images", tmp_path / "img", "--also-in", "6drepnet, 300w_lp,3ddfa_v2",
            "-q")  # fmt: skip
    assert r.exit_code == 0, r.output
    d = page_data(tmp_path / "p")
    assert d["meta"]["systems"] == ["300w_lp", "6drepnet", "3ddfa_v2"] and set(d["systems"]) == {"6drepnet", "3ddfa_v2"}

    # 3ddfa_v2's published A = Rz(r) Ry(y).T Rx(p) of the page's angles is 300W-LP's A = Rx(p).T Ry(y).T Rz(r).T
    def R(axis, v):
        return Rotation.from_euler(axis, np.asarray(v, float)[:, None], degrees=True).as_matrix()

    def T(M):
        return np.swapaxes(M, 1, 2)

    own = [[r_[k] for r_ in ROWS] for k in ("pitch", "yaw", "roll")]
    p, y, r_ = (d["systems"]["3ddfa_v2"][k] for k in ("pitch", "yaw", "roll"))
    A1 = T(R("x", own[0])) @ T(R("y", own[1])) @ T(R("z", own[2]))
    assert np.abs(R("z", r_) @ T(R("y", y)) @ R("x", p) - A1).max() < 1e-4
    assert not np.allclose(np.array([p, y, r_]), np.array(own), atol=0.1)  # and the angles differ
    # 6DRepNet names the same angles as 300W-LP (its get_R is A.T); yaw 120 comes back as its in-range twin
    p, y, r_ = (d["systems"]["6drepnet"][k] for k in ("pitch", "yaw", "roll"))
    assert np.abs(T(R("x", p)) @ T(R("y", y)) @ T(R("z", r_)) - A1).max() < 1e-4 and max(np.abs(y)) <= 90
    s = hpe.view_file(src, tmp_path / "api", images=tmp_path / "img", also_in=["6drepnet", "3ddfa_v2"])
    assert s["shown"] == 3
    assert (tmp_path / "api" / "rows.js").read_text() == (tmp_path / "p" / "rows.js").read_text().replace(
        str(tmp_path / "p"), str(tmp_path / "api")
    )
    r = hpe_cmd("view", src, "-o", tmp_path / "q", "--also-in", "6drepnet,nope")
    assert r.exit_code == 2 and "nope" in r.output and not (tmp_path / "q").exists()


def test_rerun_that_drops_rows_prunes_stale_files(tmp_path, monkeypatch):
    """A rerun on a table that lost rows (and images) removes the thumbnails, frames and ``rows/`` files the new
    page no longer references, with the commit: a failing commit leaves the earlier page whole; files the
    command does not write are left alone."""
    from hpe_cli.io import transaction as tx
    from hpe_cli.report import view_page

    monkeypatch.setattr(view_page, "CHUNK", 2)  # 3 rows: rows/00000.js and rows/00001.js
    _images(tmp_path / "img", ["a.png", "b.png"])
    src = _table(tmp_path / "in.csv", ROWS)
    page = tmp_path / "page"
    assert hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "-q").exit_code == 0
    first = page_data(page)
    (page / "notes.txt").write_text("mine")
    (page / "thumbs" / "mine.jpg").write_bytes(b"mine")

    def files():
        return {str(p.relative_to(page)): p.read_bytes() for p in page.rglob("*") if p.is_file()}

    before = files()
    assert {"rows/00000.js", "rows/00001.js"} <= set(before) and len(list((page / "frames").iterdir())) == 2
    _table(src, ROWS[:1])  # only a.png's first row is left
    # a commit that fails after the removals: nothing changes
    real = tx.unplace_file

    def unplace(path, undo, backups):
        real(path, undo, backups)
        if path.name.endswith(".js"):
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(tx, "unplace_file", unplace)
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--overwrite", "-q")
    assert r.exit_code == 1 and "no space left" in r.output.lower(), r.output
    assert files() == before and not [p for p in page.rglob(".hpe-*")]
    monkeypatch.setattr(tx, "unplace_file", real)
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--overwrite")
    assert r.exit_code == 0, r.output
    # 2 thumbnails, b.png's frame and rows/00001.js
    assert "0 thumbnails made, 1 reused" in r.output and "4 files of the earlier page no longer used: removed" in (
        r.output
    ), r.output
    d = page_data(page)
    assert sorted(p.name for p in (page / "thumbs").iterdir()) == sorted([d["thumb"][0], "mine.jpg"])
    assert d["thumb"][0] == first["thumb"][0]
    assert [p.name for p in (page / "frames").iterdir()] == [d["images"][0]["f"]]
    assert sorted(p.name for p in (page / "rows").iterdir()) == ["00000.js"]
    assert (page / "notes.txt").read_text() == "mine" and not [p for p in page.rglob(".hpe-*")]
    # --no-frames: the frames go too
    r = hpe_cmd("view", src, "-o", page, "--images", tmp_path / "img", "--overwrite", "--no-frames", "-q")
    assert r.exit_code == 0 and list((page / "frames").iterdir()) == []
