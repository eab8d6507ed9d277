"""hpe_cli.io.images: every layout a label table's image names can take, and draw on the real Panoptic folder."""

import cv2
import numpy as np
import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.io.images import ImageResolver, image_size, jpeg_size, panoptic_view, resolve_image, video_path


def _img(path, w=64, h=48, value=100):
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), np.full((h, w, 3), value, np.uint8))
    return path


def _video(path, n=5, w=64, h=48):
    path.parent.mkdir(parents=True, exist_ok=True)
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, (w, h))
    for k in range(n):
        vw.write(np.full((h, w, 3), 40 * k, np.uint8))
    vw.release()
    return path


def test_panoptic_names_parse():
    assert panoptic_view("hdImgs/00_08/00_08_00001147.jpg") == ("hd", "00_08", 1147)
    assert panoptic_view("seq/hdImgs/hd_00_08/00001147.jpg") == ("hd", "00_08", 1147)
    assert panoptic_view("vgaImgs/01_02/01_02_00000007.jpg") == ("vga", "01_02", 7)
    assert panoptic_view("kinectImgs/50_01/50_01_00000003.jpg") == ("kinect", "50_01", 3)
    assert panoptic_view("images/a.jpg") is None


@pytest.mark.parametrize(
    "stored", ["hdImgs/00_08/00_08_00000012.jpg", "hdImgs/hd_00_08/00000012.jpg", "hdImgs/00_08/00000012.jpg"]
)
def test_every_hd_frame_layout(tmp_path, stored):
    want = _img(tmp_path / stored)
    # by the toolbox name relabel writes, and by camera/frame ids alone
    assert resolve_image(tmp_path, "hdImgs/00_08/00_08_00000012.jpg") == str(want)
    assert resolve_image(tmp_path, "", "", "00_08", 12) == str(want)
    # under a sequence folder
    seq = tmp_path / "multi"
    want2 = _img(seq / "160906_pizza1" / stored)
    assert resolve_image(seq, "hdImgs/00_08/00_08_00000012.jpg", "160906_pizza1") == str(want2)


def test_vga_kinect_frames_and_videos(tmp_path):
    v = _img(tmp_path / "vgaImgs" / "01_02" / "01_02_00000007.jpg")
    k = _img(tmp_path / "kinectImgs" / "50_01" / "50_01_00000003.jpg")
    assert resolve_image(tmp_path, "vgaImgs/01_02/01_02_00000007.jpg") == str(v)
    assert resolve_image(tmp_path, "", "", "50_01", 3) == str(k)
    hv = _video(tmp_path / "hdVideos" / "hd_00_03.mp4")
    kv = _video(tmp_path / "kinectVideos" / "kinect_50_02.mp4")
    assert video_path(tmp_path, "", "00_03") == str(hv)
    assert video_path(tmp_path, "", "50_02") == str(kv)
    r = ImageResolver(tmp_path)
    ref = r.find("hdImgs/00_03/00_03_00000002.jpg")
    assert ref.video == str(hv) and ref.frame == 2 and image_size(ref) == (64, 48)
    refs = [r.find("", camera="00_03", frame=f) for f in (3, 1)] + [ImageResolver(tmp_path).find(str(v))]
    got = {i: (img, why) for i, img, why in ImageResolver.read(refs)}
    # the video's grey levels are 40 * frame (mp4 is lossy: compare the mean)
    assert abs(got[0][0].mean() - 120) < 6 and abs(got[1][0].mean() - 40) < 6 and got[2][0].mean() == 100
    past = list(ImageResolver.read([r.find("", camera="00_03", frame=50)]))
    assert past[0][1] is None and "past the end" in past[0][2]


def test_mat_stem_absolute_and_relative(tmp_path):
    jpg = _img(tmp_path / "aflw" / "image00050.jpg")
    (tmp_path / "aflw" / "image00050.mat").write_bytes(b"")
    assert resolve_image(tmp_path / "aflw", "image00050.mat") == str(jpg)
    assert resolve_image(tmp_path / "aflw", "image00050") == str(jpg)
    assert resolve_image(tmp_path, "aflw/image00050.jpg") == str(jpg)
    assert resolve_image(tmp_path / "elsewhere", str(jpg)) == str(jpg)  # absolute: as is
    # an absolute name that does not exist: its base name under the root
    assert resolve_image(tmp_path / "aflw", "/no/such/dir/image00050.jpg") == str(jpg)
    assert resolve_image(tmp_path, "nope.jpg") is None


def test_sizes_from_headers(tmp_path):
    j = _img(tmp_path / "a.jpg", 33, 21)
    p = _img(tmp_path / "b.png", 35, 22)
    from hpe_cli.io.images import ImageRef

    assert jpeg_size(j.read_bytes()) == (33, 21)
    assert image_size(ImageRef(path=str(j))) == (33, 21) and image_size(ImageRef(path=str(p))) == (35, 22)


def test_draw_real_panoptic_folder(realdata, tmp_path):
    """relabel-panoptic -> draw on the real pizza1 folder (hdImgs/hd_00_XX/ layout): every image that exists is
    drawn, the projected axes start inside the image, and a run with all images missing exits 1."""
    seq = realdata / "panoptic_160906_pizza1"
    labels = tmp_path / "pizza.parquet"
    res = hpe("relabel-panoptic", seq, "-o", labels, "--cameras", "00_00,00_08,00_01", "--frames", "1147:1148")
    assert res.exit_code == 0, res.output
    out = tmp_path / "drawn"
    res = hpe("draw", labels, "--images", seq, "-o", out, "--rejects", tmp_path / "rej.csv", "--thickness", "3")
    assert res.exit_code == 0, res.output
    t = pd.read_parquet(labels)
    drawn = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.jpg"))
    assert drawn == ["hdImgs/00_00/00_00_00001147.jpg", "hdImgs/00_08/00_08_00001147.jpg"]
    rej = pd.read_csv(tmp_path / "rej.csv")
    assert set(rej["camera"].astype(str).str.zfill(5)) <= {"00_01"} and len(rej) == (t["camera"] == "00_01").sum()
    assert rej["row"].min() >= 1  # 1-based Parquet rows
    # the drawing changed pixels at each face's box centre (where the lines start), and nowhere near the corners
    for cam in ("00_00", "00_08"):
        orig = cv2.imread(str(seq / "hdImgs" / f"hd_{cam}" / "00001147.jpg")).astype(int)
        new = cv2.imread(str(out / "hdImgs" / cam / f"{cam}_00001147.jpg")).astype(int)
        assert orig.shape == new.shape == (1080, 1920, 3)
        for _, r in t[t["camera"] == cam].iterrows():
            u, v = int(r.bbox_x + r.bbox_w / 2), int(r.bbox_y + r.bbox_h / 2)
            assert 0 <= u < 1920 and 0 <= v < 1080
            assert np.abs(new[v - 3 : v + 4, u - 3 : u + 4] - orig[v - 3 : v + 4, u - 3 : u + 4]).max() > 60
    none = tmp_path / "none.parquet"
    t[t["camera"] == "00_01"].to_parquet(none)
    res = hpe("draw", none, "--images", seq, "-o", tmp_path / "d2", "--rejects", tmp_path / "rej2.csv")
    assert res.exit_code == 1 and "nothing drawn" in res.output
    assert not (tmp_path / "d2").exists()
    assert (tmp_path / "rej2.csv").exists()  # the one output that says why is still written (issue 35)


def test_draw_video_frames(tmp_path):
    """Rows naming extracted frames that only exist in hdVideos/ are drawn from the video."""
    _video(tmp_path / "seq" / "hdVideos" / "hd_00_03.mp4", n=6, w=96, h=64)
    pd.DataFrame(
        {
            "image": ["hdImgs/00_03/00_03_00000001.jpg", "hdImgs/00_03/00_03_00000004.jpg"],
            "camera": ["00_03", "00_03"],
            "frame": [1, 4],
            "pitch": 0.0,
            "yaw": 0.0,
            "roll": 0.0,
        }
    ).to_parquet(tmp_path / "l.parquet")
    res = hpe(
        "draw",
        tmp_path / "l.parquet",
        "-o",
        tmp_path / "d",
        "--images",
        tmp_path / "seq",
        "--length",
        20,
        "--thickness",
        3,
    )
    assert res.exit_code == 0, res.output
    for f in (1, 4):
        img = cv2.imread(str(tmp_path / "d" / "hdImgs" / "00_03" / f"00_03_{f:08d}.jpg"))
        assert img.shape == (64, 96, 3)
        assert abs(img[5:15, 5:15].mean() - 40 * f) < 8  # the right frame (grey level 40 * frame)
        assert img[32, 58, 2] > 180 and img[32, 58, 1] < 90  # the red line from the centre (47.5, 31.5)


def test_draw_same_picture_by_two_names_and_two_pictures_for_one_name(tmp_path):
    a = _img(tmp_path / "imgs" / "face.jpg")
    _img(tmp_path / "other" / "face.jpg", value=30)
    (tmp_path / "imgs" / "face.mat").write_bytes(b"")
    t = pd.DataFrame(
        {
            "image": ["face.jpg", "face.mat"],
            "tdx": [20.0, 44.0],
            "tdy": 24.0,
            "size": 10.0,
            "pitch": 0.0,
            "yaw": 0.0,
            "roll": 0.0,
        }
    )
    t.to_csv(tmp_path / "l.csv", index=False)
    # face.mat names the same picture as face.jpg: both faces on one image
    res = hpe("draw", tmp_path / "l.csv", "-o", tmp_path / "d", "--images", tmp_path / "imgs", "--thickness", 2)
    assert res.exit_code == 0, res.output
    assert "drew 2 faces" in res.output and [p.name for p in (tmp_path / "d").iterdir()] == ["face.jpg"]
    img = cv2.imread(str(tmp_path / "d" / "face.jpg"))
    assert img[24, 27, 2] > 150 and img[24, 51, 2] > 150  # both red lines
    # an absolute name of another picture with the same base name: an error naming both rows, nothing written
    t.loc[1, "image"] = str(tmp_path / "other" / "face.jpg")
    t.to_csv(tmp_path / "l2.csv", index=False)
    res = hpe("draw", tmp_path / "l2.csv", "-o", tmp_path / "d2", "--images", tmp_path / "imgs")
    assert res.exit_code == 1 and "line 3" in res.output and "line 2" in res.output
    assert "two different pictures for one output file" in res.output and not (tmp_path / "d2").exists()
    assert a.is_file()
