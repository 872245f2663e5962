"""stereovo.sequences.kitti: the KITTI loader on a folder written in KITTI's layout, and its errors."""

from __future__ import annotations

import os
import shutil
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest

from stereovo.estimation import estimate_motion
from stereovo.metrics import frame_metrics
from stereovo.sequences import KittiOdometry
from tests.support.images import write_image_folder, write_kitti


pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")


@pytest.fixture(scope="module")
def kitti_root(tmp_path_factory, short):
    root = tmp_path_factory.mktemp("kitti")
    write_kitti(root, short, "07")
    return root


def test_kitti_loader_reads_the_rig_the_images_and_the_poses(kitti_root, short):
    seq = KittiOdometry(kitti_root, 7)
    cam, ref = seq.camera, short.camera
    assert (cam.width, cam.height) == (ref.width, ref.height)
    assert cam.fx == pytest.approx(ref.fx) and cam.cx == pytest.approx(ref.cx) and cam.cy == pytest.approx(ref.cy)
    assert cam.baseline == pytest.approx(ref.baseline)
    assert len(seq) == 3 and np.allclose(seq.true_poses, short.true_poses, atol=1e-9)
    for k in range(4):
        assert np.array_equal(seq.images(k)[0], short.images(k)[0])
    frame = seq.frame(2)
    assert np.array_equal(frame.prev, short.frame(2).prev)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, noise_sigma=0.5, rng=np.random.default_rng(0))
    metrics = frame_metrics(est, frame.truth)
    assert metrics.success and frame.truth.inlier.mean() > 0.6


def test_kitti_loader_takes_a_sequence_folder_and_a_range(kitti_root):
    seq = KittiOdometry(kitti_root / "sequences" / "07", None, start=1)
    assert len(seq) == 2 and seq.poses_file is not None  # ../../poses/07.txt
    assert np.allclose(seq.true_poses[0], np.eye(4))


def test_kitti_errors_name_the_file(tmp_path, short):
    with pytest.raises(FileNotFoundError, match="no folder"):
        KittiOdometry(tmp_path / "missing")
    folder = write_kitti(tmp_path, short, "01")
    with pytest.raises(FileNotFoundError, match="no sequence folder"):
        KittiOdometry(tmp_path, "02")
    calib = folder / "calib.txt"
    text = calib.read_text()
    calib.write_text(text.replace("P1:", "P9:"))
    with pytest.raises(ValueError, match=r"calib.txt: no P1 line"):
        KittiOdometry(tmp_path, "01")
    calib.write_text(text.replace("P1:", "P1: oops"))
    with pytest.raises(ValueError, match=r"calib.txt, line 2: P1 must be 12 numbers"):
        KittiOdometry(tmp_path, "01")
    calib.write_text(text)
    (folder / "image_1" / "000003.png").unlink()
    with pytest.raises(ValueError, match="4 left images but 3 right images"):
        KittiOdometry(tmp_path, "01")


def test_kitti_pose_and_calibration_lines_need_twelve_finite_numbers(tmp_path):
    from stereovo.sequences.kitti import read_calibration, read_poses

    poses = tmp_path / "00.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n\n1 0 0 0 0 1 0 0 0 0 1 2.5\n")
    assert read_poses(poses).shape == (2, 4, 4) and read_poses(poses)[1, 2, 3] == 2.5
    for line, message in (("1 0 0 0 0 1 0 0 0 0 1 x", r"line 1: a pose must be 12 numbers, got '1 0 0 0 0 1 0 0 0 0 1 x'$"),
                          ("1 0 0 0 0 1 0 0 0 0 1", r"line 1: a pose must be 12 finite numbers, got 11$"),
                          ("1 0 0 0 0 1 0 0 0 0 1 nan", r"line 1: a pose must be 12 finite numbers, got 12$"),
                          # finite, but no camera pose: the drift's SVD failed far from the file
                          ("1e308 0 0 1e308 0 1e308 0 0 0 0 1e308 0", r"line 1: a pose must be a rotation and a position"),
                          ("0 0 0 0 0 0 0 0 0 0 0 0", r"line 1: a pose must be a rotation"),
                          ("-1 0 0 0 0 1 0 0 0 0 1 0", r"line 1: a pose must be a rotation"),
                          ("1 0 0 1e300 0 1 0 0 0 0 1 0", r"within 1e\+07 m, got '1 0 0 1e300")):
        poses.write_text(line + "\n")
        with pytest.raises(ValueError, match=message):
            read_poses(poses)
    calib = tmp_path / "calib.txt"
    calib.write_text("P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: 700 0 600 -378 0 700 180 0 0 0 1 inf\n")
    with pytest.raises(ValueError, match=r"calib.txt, line 2: P1 must be 12 finite numbers, got 12$"):
        read_calibration(calib)
    calib.write_text("P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: 700 0 600 -378 0 700 180 0 0 0 1 0\n"
                     "P1: 700 0 600 -700 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt, line 3: a second P1 line$"):
        read_calibration(calib)


@pytest.mark.parametrize("p0, message", [
    ("700 0.5 600 0 0 700 180 0 0 0 1 0", r"P0\[0, 1\] is 0.5; a rectified pair's projection has 0 there"),
    ("700 0 600 0 0 700 180 0 0 0 2 0", r"P0\[2, 2\] is 2; a rectified pair's projection has 1 there"),
    ("700 0 600 0 0 700 180 3 0 0 1 0", r"P0\[1, 3\] is 3;"),
    ("700 0 600 0 0 700 180 0 0 0 1 0.1", r"P0\[2, 3\] is 0.1;"),
    ("-700 0 600 0 0 700 180 0 0 0 1 0", r"P0 has focal lengths fx=-700, fy=700 px; both must be at least 1 px"),
])
def test_kitti_calibration_must_be_a_rectified_pair(tmp_path, p0, message):
    """A projection of another form would be read as some other camera: skew, a scaled third row, a
    vertical or depth offset and a negative focal length are refused, naming the file and the entry."""
    from stereovo.sequences.kitti import read_calibration

    calib = tmp_path / "calib.txt"
    calib.write_text(f"P0: {p0}\nP1: 700 0 600 -378 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt: " + message):
        read_calibration(calib)
    calib.write_text(f"P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: {p0.replace(' 600 0 ', ' 600 -378 ', 1)}\n")
    with pytest.raises(ValueError, match=r"calib.txt: " + message.replace("P0", "P1")):
        read_calibration(calib)


def test_kitti_calibration_absurd_numbers_are_refused_naming_the_file(tmp_path):
    from stereovo.sequences.kitti import read_calibration

    calib = tmp_path / "calib.txt"
    calib.write_text("P0: 700 0 nan 0 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match="12 finite numbers"):
        read_calibration(calib)
    calib.write_text("P0: 1e-30 0 600 0 0 1e-30 180 0 0 0 1 0\nP1: 1e-30 0 600 -1e-30 0 1e-30 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt: P0 has focal lengths fx=1e-30, fy=1e-30 px; both must be at least 1 px"):
        read_calibration(calib)
    calib.write_text("P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: 700 0 600 -2.1e300 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt: P1 puts the right camera at baseline 3e\+297 m; expected in \(0, 1e\+07\]"):
        read_calibration(calib)


def test_kitti_principal_point_outside_the_images_is_refused(tmp_path, short):
    """A calibration written for another image size (the principal point off the images) is refused
    by the loader, which knows the images' size; the file is named with the point and the size."""
    folder = write_kitti(tmp_path, short, "03")
    calib = folder / "calib.txt"
    lines = calib.read_text().splitlines()
    numbers = lines[0].split()[1:]
    cx = float(numbers[2])
    calib.write_text("\n".join(line.replace(f" {numbers[2]} ", f" {cx + 5000:g} ", 1) for line in lines) + "\n")
    with pytest.raises(ValueError, match=r"calib.txt puts the principal point at \(\d+(\.\d+)?, [\d.]+\) px, "
                                         r"outside the \d+x\d+ images of .*image_0"):
        KittiOdometry(tmp_path, "03")


def test_a_calibration_or_pose_file_of_one_endless_line_is_refused_naming_it(tmp_path):
    """A calib.txt of one line of 100 MB was read whole into memory (a MemoryError for a larger one): a line
    is read up to MAX_LINE characters, and a longer one refused, naming the file and the line."""
    folder = write_image_folder(tmp_path / "seq", poses=True)
    calib = folder / "calib.txt"
    good = calib.read_text()
    calib.write_text(good + "# " + "x" * 100_000)
    with pytest.raises(ValueError, match=r"seq/calib.txt, line 3: longer than 4096 characters \(MAX_LINE\); a line "
                                         r"holds one entry of 12 numbers$"):
        KittiOdometry(folder, None)
    calib.write_text(good + "# " + "x" * 4000 + "\n")
    (folder / "poses.txt").write_text("1 " * 10_000)
    with pytest.raises(ValueError, match=r"seq/poses.txt, line 1: longer than 4096 characters"):
        KittiOdometry(folder, None)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_calibration_or_pose_file_that_is_not_a_regular_file_is_refused_naming_it(tmp_path):
    """A poses.txt that was a broken link was passed over in silence (a run without ground truth), a
    calib.txt that was a FIFO was said to be missing: each is refused, named, as what it is."""
    folder = write_image_folder(tmp_path / "seq")
    (folder / "poses.txt").symlink_to("nowhere.txt")
    with pytest.raises(ValueError, match=r"seq/poses.txt: not a readable text file \(a link that leads to no file: "
                                         r"No such file or directory\)$"):
        KittiOdometry(folder, None)
    (folder / "poses.txt").unlink()
    calib = folder / "calib.txt"
    calib.unlink()
    os.mkfifo(calib)
    with pytest.raises(ValueError, match=r"seq/calib.txt: not a regular file \(a FIFO: reading it would wait for a "
                                         r"writer\)$"):
        KittiOdometry(folder, None)
    calib.unlink()
    with pytest.raises(FileNotFoundError, match=r"KittiOdometry: no calibration file .*seq/calib.txt$"):
        KittiOdometry(folder, None)


# ---------------------------------------------------------------- hostile image files


def _png_header(width: int, height: int, bit_depth: int = 8, colour: int = 0) -> bytes:
    """A PNG of a header and 64 zero bytes of data: a decoder allocates the declared image before it
    finds the data missing (``colour`` 0 grey, 6 RGBA)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, bit_depth, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
            + chunk(b"IEND", b""))


@pytest.fixture
def decoded(monkeypatch):
    """The names of the files OpenCV's imread is asked to decode, in order."""
    import cv2

    names: list[str] = []
    real = cv2.imread

    def imread(path, *args):
        names.append(Path(path).name)
        return real(path, *args)

    monkeypatch.setattr(cv2, "imread", imread)
    return names


@pytest.mark.parametrize("width, height, declared", [
    (8000, 7000, r"a 8000x7000 image \(56,000,000 pixels\)"),  # under Pillow's own limit
    (10000, 10000, r"a 10000x10000 image \(100,000,000 pixels\)"),  # Pillow warns
    # Pillow refuses, without the size, over twice its Image.MAX_IMAGE_PIXELS; OpenCV raised cv2.error
    (100000, 100000, r"an image of more than \d{3},\d{3},\d{3} pixels"),
])
def test_an_image_over_the_pixel_cap_is_refused_from_its_header(tmp_path, decoded, width, height, declared):
    """A header declaring a huge image made OpenCV allocate it (8 GiB for 69 bytes claiming 32768x32768
    16-bit RGBA) or raise its own cv2.error: it is refused from the header, naming the file and the
    size, before any decoding, and no warning of Pillow's leaks."""
    folder = write_image_folder(tmp_path / "seq")
    (folder / "image_0" / "000000.png").write_bytes(_png_header(width, height))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"seq/image_0/000000.png: declares " + declared + r"; images of at most "
                                             r"50,000,000 pixels are read \(MAX_IMAGE_PIXELS\)$"):
            KittiOdometry(folder, None)
    assert decoded == []


def test_loading_a_folder_leaves_the_warnings_filters_as_they_were(tmp_path):
    """Pillow warns of an image over its own limit and refuses one over twice it; the loader hears neither
    outside the header read: the caller's warnings filters are the same after, and Pillow's warning still
    reaches the caller when the caller opens such an image."""
    from PIL import Image

    folder = write_image_folder(tmp_path / "seq")
    (folder / "image_1" / "000001.png").write_bytes(_png_header(10000, 10000))  # Pillow warns
    (folder / "image_1" / "000002.png").write_bytes(_png_header(100000, 100000))  # Pillow refuses
    before = list(warnings.filters)
    sequence = KittiOdometry(folder, None)
    for k in (1, 2):
        with pytest.raises(ValueError, match=rf"image pair {k}: .*seq/image_1/00000{k}.png: declares "):
            sequence.images(k)
    assert warnings.filters == before
    with pytest.warns(Image.DecompressionBombWarning):
        Image.open(folder / "image_1" / "000001.png").close()


def test_an_image_under_the_cap_that_a_lowered_pillow_limit_refuses_names_pillows_limit(tmp_path, monkeypatch):
    """Someone lowered Pillow's Image.MAX_IMAGE_PIXELS below the loader's: the image it refuses, without
    its size, is refused naming Pillow's limit, not said to be over MAX_IMAGE_PIXELS."""
    from PIL import Image

    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)
    folder = write_image_folder(tmp_path / "seq")  # 128x96: 12,288 pixels
    with pytest.raises(ValueError, match=r"seq/image_0/000000.png: not a readable image \(Pillow refuses images of "
                                         r"more than 2,000 pixels: twice its Image.MAX_IMAGE_PIXELS, 1,000\)$"):
        KittiOdometry(folder, None)


def test_an_image_opencv_cannot_allocate_is_refused_naming_the_file(tmp_path, monkeypatch):
    """OpenCV 5 raises cv2.error (not None) for an image over its own pixel limit or one it cannot
    allocate: the loader says "not a readable image" of the file, as of any other. (The cap is lifted
    here so that the header reaches OpenCV.)"""
    from PIL import Image

    import stereovo.sequences.kitti as kitti

    monkeypatch.setattr(kitti, "MAX_IMAGE_PIXELS", 10**12, raising=False)
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", None)
    folder = write_image_folder(tmp_path / "seq")
    (folder / "image_0" / "000000.png").write_bytes(_png_header(100000, 100000))
    with pytest.raises(ValueError, match=r"seq/image_0/000000.png: not a readable image \(OpenCV: .*PIXELS"):
        KittiOdometry(folder, None)


def test_a_later_image_of_another_size_is_refused_from_its_header(tmp_path, decoded):
    """No frame costs more than the first: an image declaring another size than the sequence's first is
    refused, naming it and both sizes, before OpenCV decodes it."""
    folder = write_image_folder(tmp_path / "seq")  # 128x96
    (folder / "image_1" / "000002.png").write_bytes(_png_header(4000, 3000))
    sequence = KittiOdometry(folder, None)
    assert sequence.images(1)[1].shape == (96, 128)
    with pytest.raises(ValueError, match=r"KittiOdometry: image pair 2: .*seq/image_1/000002.png: a 4000x3000 "
                                         r"image; the sequence's images are 128x96$"):
        sequence.images(2)
    assert decoded[-1] == "000002.png" and len(decoded) == 4  # the first image, pair 1 and pair 2's left only


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_an_entry_named_like_an_image_that_is_not_a_regular_file_is_refused_before_reading(tmp_path, decoded):
    """A FIFO named 000001.png made imread wait for a writer forever; a directory or a link loop so
    named read as nothing. Each is refused when the folder is listed, named, before anything reads it."""
    folder = write_image_folder(tmp_path / "seq")
    fifo = folder / "image_0" / "000001.png"
    fifo.unlink()
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match=r"seq/image_0/000001.png: not a regular file \(a FIFO"):
        KittiOdometry(folder, None)
    fifo.unlink()
    fifo.mkdir()
    with pytest.raises(ValueError, match=r"seq/image_0/000001.png: not a regular file \(a directory\)$"):
        KittiOdometry(folder, None)
    fifo.rmdir()
    fifo.symlink_to(fifo.name)  # a link to itself
    with pytest.raises(ValueError, match=r"seq/image_0/000001.png: not a regular file \(a link that leads to no "
                                         r"file: .*symbolic links\)$"):
        KittiOdometry(folder, None)
    assert decoded == []
    # a dot-file ('.png', a link loop too) is no image's name: skipped, as any hidden file
    (folder / "image_1" / ".png").symlink_to(".png")
    fifo.unlink()
    (folder / "image_1" / "000001.png").rename(folder / "image_1" / "000001.bak")
    assert len(KittiOdometry(folder, None)) == 1  # image pairs 000000 and 000002


def test_left_and_right_images_are_paired_by_name(tmp_path):
    """image_1/000001.png renamed 000009.png paired left 1 with right 2 (and left 2 with right 9)
    without a word: a left image without a right one of its name is refused, naming both files."""
    folder = write_image_folder(tmp_path / "seq")
    (folder / "image_1" / "000001.png").rename(folder / "image_1" / "000009.png")
    with pytest.raises(ValueError, match=r"KittiOdometry: .*seq/image_0/000001.png has no right image of its name "
                                         r"in .*seq/image_1 \(the one in its place, in name order, is 000002.png\)"):
        KittiOdometry(folder, None)
    (folder / "image_1" / "000009.png").rename(folder / "image_1" / "000001.jpg")  # (a PNG named .jpg)
    assert len(KittiOdometry(folder, None)) == 2  # one name, another suffix: a pair


def test_jpegs_baseline_progressive_and_with_data_after_their_end_give_frames(kitti_root, tmp_path):
    """Cameras and tools append data after a JPEG's end-of-image marker, which OpenCV and Pillow read past:
    such files, progressive ones and one with an EXIF thumbnail are read as OpenCV decodes them, and give
    frames whose motion is found."""
    import cv2

    from tests.support.jpegs import exif_with_thumbnail, jpeg_bytes

    root = tmp_path / "kitti"
    shutil.copytree(kitti_root, root)
    folder = root / "sequences" / "07"
    tail = np.random.default_rng(2).integers(0, 256, 1024, np.uint8).tobytes()
    thumbnail = jpeg_bytes(np.full((16, 16), 128, np.uint8))
    written = {}
    for k, side, options, after in ((1, 0, {}, tail), (1, 1, {"progressive": True}, tail),
                                    (2, 0, {"exif": exif_with_thumbnail(thumbnail)}, b""),
                                    (2, 1, {"progressive": True}, b"\0" * 64)):
        png = folder / f"image_{side}" / f"{k:06d}.png"
        data = jpeg_bytes(cv2.imread(str(png), cv2.IMREAD_UNCHANGED), quality=95, **options) + after
        png.unlink()
        png.with_suffix(".jpg").write_bytes(data)
        written[k, side] = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    sequence = KittiOdometry(root, 7)
    for (k, side), image in written.items():
        assert np.array_equal(sequence.images(k)[side], image)
    for k in (1, 2):
        frame = sequence.frame(k)
        est = estimate_motion(frame.prev, frame.curr, frame.camera, noise_sigma=0.5, rng=np.random.default_rng(0))
        assert frame_metrics(est, frame.truth).success


def _jpeg_folder(tmp_path: Path, data: bytes) -> Path:
    """A noise folder whose image_0/000001 is the JPEG ``data`` (a 128x96 image, or part of one)."""
    folder = write_image_folder(tmp_path / "seq")
    (folder / "image_0" / "000001.png").unlink()
    (folder / "image_0" / "000001.jpg").write_bytes(data)
    return folder


def _cut(kind: str) -> tuple[bytes, str]:
    """A 128x96 JPEG cut at ``kind``'s point, and the message (a pattern) that refuses it."""
    from tests.support.jpegs import exif_with_thumbnail, jpeg_bytes, smooth_noise

    image = smooth_noise(96, 128)
    baseline, progressive = jpeg_bytes(image), jpeg_bytes(image, progressive=True)
    scans = [i for i in range(len(progressive)) if progressive.startswith(b"\xff\xda", i)]
    table = progressive.index(b"\xff\xc4", scans[0] + 2)
    thumbnail = jpeg_bytes(smooth_noise(16, 16, 1))
    exif = jpeg_bytes(image, exif=exif_with_thumbnail(thumbnail))
    in_scan = r"a truncated JPEG \(its \d+ bytes end in the entropy-coded data of scan {}, before the end-of-image " \
              r"marker FF D9\)$"
    return {
        "in the scan": (baseline[:len(baseline) // 2], in_scan.format(1)),
        "before the end marker": (baseline[:-2], in_scan.format(1)),
        "between FF and D9": (baseline[:-1], in_scan.format(1)),
        "in the third of six scans": (progressive[:scans[2] + 40], in_scan.format(3)),
        "in a table between scans": (progressive[:table + 8], r"a truncated JPEG \(its \d+ bytes end inside the "
                                     r"segment of marker FF C4 at byte \d+, which declares \d+ bytes, before the "
                                     r"end-of-image marker FF D9\)$"),
        # the thumbnail's own end marker, inside APP1, does not end the file
        "in the main scan after an EXIF thumbnail": (exif[:(exif.index(thumbnail) + len(thumbnail) + len(exif)) // 2],
                                                     in_scan.format(1)),
        # (Pillow reads the header up to the first scan, and refuses it first)
        "in the header's tables": (baseline[:300], r"not a readable image \(Pillow: .+\)$"),
    }[kind]


@pytest.mark.parametrize("kind", ["in the scan", "before the end marker", "between FF and D9",
                                  "in the third of six scans", "in a table between scans",
                                  "in the main scan after an EXIF thumbnail", "in the header's tables"])
def test_a_truncated_jpeg_is_refused_naming_the_file_and_where_it_ends(tmp_path, decoded, kind):
    """OpenCV decodes a truncated JPEG with its missing part grey, without an error: a JPEG whose segments
    and scans do not reach its end-of-image marker is refused, naming the file, before OpenCV decodes it."""
    data, message = _cut(kind)
    sequence = KittiOdometry(_jpeg_folder(tmp_path, data), None)
    with pytest.raises(ValueError, match=r"KittiOdometry: image pair 1: .*seq/image_0/000001.jpg: " + message):
        sequence.images(1)
    assert "000001.jpg" not in decoded


@pytest.mark.parametrize("length", [0, 1, 3, 0xFFFF])
def test_garbage_segment_lengths_are_refused_naming_the_file(tmp_path, length):
    """A Huffman table's length after a progressive JPEG's first scan (Pillow reads only up to the first)
    set to garbage: refused as damaged or truncated, naming the file."""
    from tests.support.jpegs import jpeg_bytes, smooth_noise

    data = jpeg_bytes(smooth_noise(96, 128), progressive=True)
    table = data.index(b"\xff\xc4", data.index(b"\xff\xda") + 2)
    sequence = KittiOdometry(_jpeg_folder(tmp_path, data[:table + 2] + struct.pack(">H", length) + data[table + 4:]),
                             None)
    with pytest.raises(ValueError, match=r"KittiOdometry: image pair 1: .*seq/image_0/000001.jpg: a "
                                         r"(damaged|truncated) JPEG \(.*at byte \d+"):
        sequence.images(1)


def test_random_damage_to_a_jpegs_header_is_read_or_refused_in_one_line(tmp_path):
    """Bytes of a JPEG's marker segments overwritten at random: each file is read, or refused with the
    loader's one-line error naming it; no other exception, no hang."""
    from tests.support.jpegs import jpeg_bytes, smooth_noise

    data = jpeg_bytes(smooth_noise(96, 128), progressive=True)
    sequence = KittiOdometry(_jpeg_folder(tmp_path, data), None)
    jpeg = sequence.folder / "image_0" / "000001.jpg"
    rng = np.random.default_rng(11)
    outcomes = set()
    for _ in range(150):
        damaged = bytearray(data)
        for at in rng.integers(2, data.index(b"\xff\xda") + 10, 2):
            damaged[at] = rng.integers(0, 256)
        jpeg.write_bytes(bytes(damaged))
        try:
            outcomes.add(sequence.images(1)[0].shape)
        except ValueError as err:
            assert str(err).startswith(f"KittiOdometry: image pair 1: {jpeg}: ") and "\n" not in str(err), err
            outcomes.add("refused")
    assert outcomes == {(96, 128), "refused"}


def test_a_sequence_needs_two_image_pairs(tmp_path):
    """One image pair gave a run of no frames that reported success: refused, naming the folder and the count."""
    folder = write_image_folder(tmp_path / "seq", n=1)
    with pytest.raises(ValueError, match=r"KittiOdometry: .*seq holds 1 image pair; odometry needs at least 2"):
        KittiOdometry(folder, None)


def test_images_too_small_for_features_are_refused_naming_the_size(tmp_path):
    """2x2 images ran as frames that all failed, and the images environment blamed its z_max, a
    setting the user never gave: images under 64 px on a side are refused by the loader."""
    folder = write_image_folder(tmp_path / "seq", width=2, height=2)
    with pytest.raises(ValueError, match=r"KittiOdometry: .*seq/image_0/000000.png is a 2x2 image; the front end "
                                         r"finds no features in images smaller than 64 px on a side"):
        KittiOdometry(folder, None)
    assert len(KittiOdometry(write_image_folder(tmp_path / "edge", width=64, height=64), None)) == 2


def test_unreadable_images_name_the_file_and_why(tmp_path):
    folder = write_image_folder(tmp_path / "seq")
    (folder / "image_0" / "000000.png").write_text("hello, not an image\n")
    with pytest.raises(ValueError, match=r"seq/image_0/000000.png: not a readable image \(no image format Pillow "
                                         r"knows begins it: empty, text or damaged\)$"):
        KittiOdometry(folder, None)


def test_an_image_0_that_is_no_folder_is_named(tmp_path):
    """image_0 as a link loop, or a folder without it, reported only the sequences/00 folder that was
    looked for instead (kitti:PATH with no image_0/ is read as a dataset's sequence 00)."""
    from stereovo.sequences import open_source

    folder = tmp_path / "seq"
    folder.mkdir()
    with pytest.raises(FileNotFoundError, match=r"KittiOdometry: no sequence folder .*seq/sequences/00, and no "
                                                r"image_0/ in .*seq$"):
        open_source(f"kitti:{folder}")
    (folder / "image_0").symlink_to("image_0")
    with pytest.raises(FileNotFoundError, match=r"KittiOdometry: .*seq/image_0 is not a folder of images \(a file, a "
                                                r"broken link or a link loop\), and there is no sequence folder"):
        KittiOdometry(folder)
