"""Image names from tables under --images: a name that leaves the folder (``../``) is one clear error line
(draw: it would be written outside the output folder; augment and export: the name leaves --images);
a symbolic link inside --images is followed (datasets are often link farms); a dangling one is a reject."""

from __future__ import annotations

import os

from conftest import hpe

from .conftest import check_failed, make_images


def _setup(tmp_path):
    imgs = tmp_path / "imgs"
    make_images(imgs, ["a.jpg"], size=(80, 60))
    make_images(tmp_path, ["secret.jpg"], size=(80, 60))
    os.symlink(tmp_path / "secret.jpg", imgs / "link.jpg")
    os.symlink(tmp_path / "gone.jpg", imgs / "dangling.jpg")
    return imgs


def test_draw_refuses_a_name_leaving_the_folder(tmp_path):
    imgs = _setup(tmp_path)
    t = tmp_path / "t.csv"
    t.write_text("image,pitch,yaw,roll\na.jpg,1,2,3\n../secret.jpg,4,5,6\n")
    res = hpe("draw", t, "--images", imgs, "-o", tmp_path / "out")
    line = check_failed(res)
    assert "../secret.jpg" in line and "outside" in line, line
    assert not (tmp_path / "out").exists()


def test_augment_refuses_a_name_leaving_images(tmp_path):
    imgs = _setup(tmp_path)
    t = tmp_path / "t.csv"
    t.write_text("image,pitch,yaw,roll\na.jpg,1,2,3\n../secret.jpg,4,5,6\n")
    res = hpe(
        "augment",
        t,
        "-o",
        tmp_path / "a.csv",
        "--image-size",
        "80",
        "60",
        "--hflip",
        "--images",
        imgs,
        "--out-images",
        tmp_path / "ai",
    )
    line = check_failed(res, must_name=t)
    assert "../secret.jpg" in line
    assert not (tmp_path / "a.csv").exists() and not (tmp_path / "ai").exists()


def test_draw_follows_links_and_rejects_dangling_ones(tmp_path):
    imgs = _setup(tmp_path)
    t = tmp_path / "t.csv"
    t.write_text("image,pitch,yaw,roll\na.jpg,1,2,3\nlink.jpg,1,1,1\ndangling.jpg,1,1,1\n")
    res = hpe("draw", t, "--images", imgs, "-o", tmp_path / "out", "--rejects", tmp_path / "r.csv")
    assert res.exit_code == 0, res.output
    assert sorted(os.listdir(tmp_path / "out")) == ["a.jpg", "link.jpg"]
    assert "dangling.jpg" in (tmp_path / "r.csv").read_text()


def test_export_refuses_a_name_leaving_images(tmp_path):
    """``hpe export``: a relative image name that climbs out of --images is not read (nor copied into the
    export): one line without --rejects, a reject naming the name with it."""
    imgs = _setup(tmp_path)
    t = tmp_path / "t.csv"
    t.write_text(
        "image,pitch,yaw,roll,bbox_x,bbox_y,bbox_w,bbox_h\na.jpg,1,2,3,10,10,40,40\n../secret.jpg,4,5,6,10,10,40,40\n"
    )
    res = hpe("export", t, "--images", imgs, "--layout", "hf", "-o", tmp_path / "out")
    line = check_failed(res, must_name=t)
    assert "../secret.jpg" in line and "leaves the --images folder" in line, line
    assert not (tmp_path / "out").exists()
    res = hpe("export", t, "--images", imgs, "--layout", "hf", "-o", tmp_path / "out", "--rejects", tmp_path / "r.csv")
    assert res.exit_code == 0, res.output
    rej = (tmp_path / "r.csv").read_text()
    assert "../secret.jpg" in rej and "leaves the --images folder" in rej
    assert not any("secret" in p.name for p in (tmp_path / "out").rglob("*"))
