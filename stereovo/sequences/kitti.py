""":class:`KittiOdometry`: a sequence of the KITTI odometry benchmark read from disk.

KITTI's layout (Geiger, Lenz & Urtasun, "Are we ready for autonomous driving? The KITTI vision
benchmark suite", CVPR 2012)::

    ROOT/sequences/NN/image_0/000000.png ...   left grey images
    ROOT/sequences/NN/image_1/000000.png ...   right grey images
    ROOT/sequences/NN/calib.txt                 "P0: 12 numbers", "P1: ...": rectified 3x4 projections
    ROOT/poses/NN.txt                           (optional) one 3x4 camera-to-world pose per line

``ROOT`` may also be the sequence folder itself (holding ``image_0/``). The rig comes from P0 and
P1 (``fx, fy, cx, cy`` of P0, ``baseline = -P1[0, 3] / P1[0, 0]``), the image size from the first
image. An image pair is two files of one name in ``image_0/`` and ``image_1/``; a sequence has at least
two. Each image's header is read before the image (Pillow), so that an image larger than
:data:`MAX_IMAGE_PIXELS` or of another size than the first is refused before it is decoded (OpenCV);
a JPEG is read only when its structure reaches its end-of-image marker (:mod:`stereovo.sequences.jpeg`).
Only text and images are read: nothing in the folder can run code.

Labels when poses are known: there are no depth maps, so a match is labelled an inlier when the
true motion carries its k-1 triangulation onto its k measurement within ``label_tolerance`` px
(``uL``, ``vL`` and the disparity). KITTI's poses come from GPS/INS, accurate to centimetres, so
these labels are approximate for distant points and near the tolerance.
"""

from __future__ import annotations

import io
import itertools
import os
import stat
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.frontend import Matches
from stereovo.frontend.images import MIN_IMAGE_SIDE
from stereovo.geometry import invert_transform, relative_motion
from stereovo.options import Integer, Number
from stereovo.sequences.base import ImageSequence
from stereovo.sequences.jpeg import jpeg_defect
from stereovo.simulation import FrameTruth, OutlierKind

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".pgm", ".ppm", ".bmp", ".tif", ".tiff")


def _three_by_four(text: str, what: str, shown: str) -> np.ndarray:
    """The 12 numbers of one line of KITTI's calibration or pose file as a ``(3, 4)`` matrix.

    Raises:
        ValueError: ``{what} must be 12 numbers, got {shown}`` or ``... 12 finite numbers, got COUNT``.
    """
    try:
        numbers = np.array([float(x) for x in text.split()])
    except ValueError:
        raise ValueError(f"{what} must be 12 numbers, got {shown}") from None
    if numbers.size != 12 or not np.all(np.isfinite(numbers)):
        raise ValueError(f"{what} must be 12 finite numbers, got {numbers.size}")
    return numbers.reshape(3, 4)


MAX_POSITION_M = 1e7
"""The largest coordinate a KITTI pose, or the baseline, may hold (m): the Earth's scale, far beyond any sequence."""


def read_calibration(path: Path) -> StereoCamera:
    """A :class:`StereoCamera` from KITTI's ``calib.txt`` (P0 and P1), of the default image size: the
    loader sets the images' own.

    P0 and P1 must be the projections of a rectified pair: ``K [I | 0]`` and ``K [I | (-b, 0, 0)]``
    with ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (Geiger, Lenz & Urtasun, CVPR 2012). Any other
    form (skew, a third row other than ``(0, 0, 1, 0)``, a vertical or depth offset) would be read as
    some other camera without a word, so it is refused, naming the file and the entry; so is a file
    that is not a regular one, or a line over :data:`MAX_LINE` characters.
    """
    rows: dict[str, np.ndarray] = {}
    for number, line in _lines(path):
        if ":" not in line:
            continue
        key, _, values = line.partition(":")
        key = key.strip()
        if key not in ("P0", "P1"):
            continue
        if key in rows:  # which of the two was meant cannot be told
            raise ValueError(f"{path}, line {number}: a second {key} line")
        rows[key] = _three_by_four(values, f"{path}, line {number}: {key}", repr(values.strip()))
    missing = [key for key in ("P0", "P1") if key not in rows]
    if missing:
        raise ValueError(f"{path}: no {' and no '.join(missing)} line (KITTI's 'P0: 12 numbers' projections)")
    P0, P1 = rows["P0"], rows["P1"]
    for key, P in rows.items():
        _check_rectified_projection(path, key, P)
    fx, fy, cx, cy = P0[0, 0], P0[1, 1], P0[0, 2], P0[1, 2]
    if not np.allclose(P1[:, :3], P0[:, :3], rtol=1e-6, atol=1e-6):
        raise ValueError(f"{path}: P0 and P1 have different intrinsics: the images are not a rectified pair")
    baseline = -(P1[0, 3] - P0[0, 3]) / P1[0, 0]
    if not 0 < baseline <= MAX_POSITION_M:
        raise ValueError(f"{path}: P1 puts the right camera at baseline {baseline:g} m; expected in (0, "
                         f"{MAX_POSITION_M:g}] (P1[0, 3] < 0)")
    try:
        return StereoCamera(fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy), baseline=float(baseline))
    except ValueError as err:  # the camera's own rule, said of the file it came from
        raise ValueError(f"{path}: {err}") from None


MIN_FOCAL_PX = 1.0
"""The shortest focal length a calibration may give (px): below it one pixel spans more than 45 deg,
which no camera does; a focal length of 1e-320 would otherwise pass as a positive number."""


def _check_rectified_projection(path: Path, key: str, P: np.ndarray) -> None:
    """Refuse a projection ``P (3, 4)`` that is not ``K [I | (tx, 0, 0)]`` with focal lengths of at
    least :data:`MIN_FOCAL_PX`.

    Zeros are zero within 1e-9 of the focal length (a written-out float's rounding), P[2, 2] is 1.
    """
    if not (P[0, 0] >= MIN_FOCAL_PX and P[1, 1] >= MIN_FOCAL_PX):
        raise ValueError(f"{path}: {key} has focal lengths fx={P[0, 0]:g}, fy={P[1, 1]:g} px; both must be at least "
                         f"{MIN_FOCAL_PX:g} px")
    tolerance = 1e-9 * max(abs(P[0, 0]), abs(P[1, 1]))
    expected = {(0, 1): 0.0, (1, 0): 0.0, (1, 3): 0.0, (2, 0): 0.0, (2, 1): 0.0, (2, 3): 0.0}
    for (i, j), value in expected.items():
        if abs(P[i, j] - value) > tolerance:
            raise ValueError(f"{path}: {key}[{i}, {j}] is {P[i, j]:g}; a rectified pair's projection has 0 there "
                             f"(K [I | (tx, 0, 0)], fx and fy > 0)")
    if abs(P[2, 2] - 1.0) > 1e-9:
        raise ValueError(f"{path}: {key}[2, 2] is {P[2, 2]:g}; a rectified pair's projection has 1 there "
                         f"(K [I | (tx, 0, 0)])")


def read_poses(path: Path) -> np.ndarray:
    """``(N, 4, 4)`` camera-to-world poses from KITTI's pose file (12 numbers a line).

    Raises:
        ValueError: naming the file and the line: not 12 finite numbers, not a rotation and a position
            within :data:`MAX_POSITION_M`, a line over :data:`MAX_LINE` characters; no pose; not a
            regular file.
    """
    poses = []
    for number, line in _lines(path):
        if not line.strip():
            continue
        pose = np.eye(4)
        pose[:3, :] = _three_by_four(line, f"{path}, line {number}: a pose", repr(line.strip()[:60]))
        # A camera-to-world pose: a rotation (KITTI's, from GPS/INS, are orthonormal to about 1e-6)
        # and a position on the Earth's scale; anything else would fail far away, in the drift's SVD.
        R = pose[:3, :3]
        # (a rotation's entries lie in [-1, 1]: checked first, so that R R' of huge ones cannot overflow)
        if (np.abs(R).max() > 1.001 or not np.allclose(R @ R.T, np.eye(3), atol=1e-3) or np.linalg.det(R) <= 0
                or np.abs(pose[:3, 3]).max() > MAX_POSITION_M):
            raise ValueError(f"{path}, line {number}: a pose must be a rotation and a position within "
                             f"{MAX_POSITION_M:g} m, got {line.strip()[:60]!r}")
        poses.append(pose)
    if not poses:
        raise ValueError(f"{path}: no poses")
    return np.array(poses)


MAX_LINE = 4096
"""The most characters a line of a calibration or pose file may hold, its end included: KITTI's hold
under 250. Longer is refused as it is read; a file of one endless line was read whole into memory."""


def _open_regular(path: Path, what: str) -> BinaryIO:
    """``path`` open for reading bytes, once it is known to be a regular file (``what`` it should be
    names it in a message).

    Raises:
        ValueError: ``{path}: not a readable {what} (REASON)`` or ``{path}: not a regular file (KIND)``.
    """
    try:
        # O_NONBLOCK: a FIFO (put there after the folder was checked) opens at once instead of waiting for a writer
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as err:
        link = "a link that leads to no file: " if os.path.islink(path) else ""
        raise ValueError(f"{path}: not a readable {what} ({link}{err.strerror})") from None
    handle = os.fdopen(fd, "rb")
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        handle.close()
        raise ValueError(f"{path}: not a regular file ({_file_kind(mode)})")
    return handle


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    """``(number, line)`` of text file ``path`` (UTF-8, undecodable bytes replaced), numbered from 1.

    Raises:
        ValueError: naming the file: not a regular file (see :func:`_open_regular`), or a line over
            :data:`MAX_LINE` characters.
    """
    with _open_regular(path, "text file") as raw, io.TextIOWrapper(raw, encoding="utf-8", errors="replace") as text:
        for number in itertools.count(1):
            line = text.readline(MAX_LINE + 1)
            if not line:
                return
            if len(line) > MAX_LINE:
                raise ValueError(f"{path}, line {number}: longer than {MAX_LINE} characters (MAX_LINE); a line "
                                 "holds one entry of 12 numbers")
            yield number, line


def _images(folder: Path) -> list[Path]:
    """The image files of ``folder`` (names ending in :data:`_IMAGE_SUFFIXES`), sorted by name.

    Raises:
        FileNotFoundError: no such folder, or no image file in it.
        ValueError: an entry named like an image that is not a regular file, named, before anything
            reads it: a FIFO would block the reader forever, a directory or a broken link reads as nothing.
    """
    if not folder.is_dir():
        raise FileNotFoundError(f"no image folder {folder}")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    if not files:
        raise FileNotFoundError(f"no images in {folder}")
    for path in files:
        try:
            mode = os.stat(path).st_mode  # through links: a link to an image file is one
        except OSError as err:  # a broken link, a link loop
            raise ValueError(f"{path}: not a regular file (a link that leads to no file: {err.strerror})") from None
        if not stat.S_ISREG(mode):
            raise ValueError(f"{path}: not a regular file ({_file_kind(mode)})")
    return files


def _file_kind(mode: int) -> str:
    """What a file that is not a regular one is, from its ``st_mode``, for a message."""
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO: reading it would wait for a writer"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a file of data"


MAX_IMAGE_PIXELS = 50_000_000
"""The most pixels (width x height) an image file may declare; a larger one is refused from its header,
before any decoding. A decoder allocates the declared size before it reads a pixel: a 69-byte PNG
header claiming 32768x32768 16-bit RGBA made OpenCV ask for 8 GiB, 389 KB of zeros declaring
20000x20000 took 830 MB. 50 MP is 100 times a KITTI image (1241x376) and 1.5 times an 8K frame; decoded
as 16-bit RGBA, the costliest form OpenCV returns, it is 400 MB."""


def _declared_size(path: Path) -> tuple[int, int]:
    """``(width, height)`` (px) that the header of image file ``path`` declares, read without decoding
    a pixel (Pillow's ``Image.open`` reads the header only).

    Raises:
        ValueError: naming the file: not a regular file, not a readable image (Pillow identifies no
            image format in it), more than :data:`MAX_IMAGE_PIXELS` pixels, or a JPEG whose structure
            does not reach its end-of-image marker (truncated: OpenCV would decode the missing part as
            grey; see :func:`~stereovo.sequences.jpeg.jpeg_defect`).
    """
    from PIL import Image, UnidentifiedImageError

    with _open_regular(path, "image") as handle:
        try:
            with warnings.catch_warnings():  # the filter below lasts for this read only: the caller's are kept
                # Pillow warns of an image over its own limit, Image.MAX_IMAGE_PIXELS, and still hands over
                # the size, checked below against MAX_IMAGE_PIXELS with this module's message
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                with Image.open(handle) as image:
                    (width, height), kind = image.size, image.format
        except Image.DecompressionBombError:
            # Pillow refuses, without the size, an image over twice its limit (its documented rule)
            raise ValueError(_refused_by_pillow(path)) from None
        except UnidentifiedImageError:
            raise ValueError(f"{path}: not a readable image (no image format Pillow knows begins it: empty, text or "
                             "damaged)") from None
        except Exception as err:  # Pillow's format readers raise many types on a malformed header
            raise ValueError(f"{path}: not a readable image (Pillow: {' '.join(str(err).split())})") from None
        if width * height > MAX_IMAGE_PIXELS:
            raise ValueError(f"{path}: declares a {width}x{height} image ({width * height:,} pixels); images of at "
                             f"most {MAX_IMAGE_PIXELS:,} pixels are read (MAX_IMAGE_PIXELS)")
        if kind in ("JPEG", "MPO"):  # (MPO: JPEGs one after another; OpenCV decodes the first)
            defect = jpeg_defect(handle)
            if defect is not None:
                raise ValueError(f"{path}: {defect}")
    return width, height


def _refused_by_pillow(path: Path) -> str:
    """The message for an image Pillow refused with ``DecompressionBombError``: over twice
    ``Image.MAX_IMAGE_PIXELS``, which is over :data:`MAX_IMAGE_PIXELS` unless someone lowered Pillow's."""
    from PIL import Image

    pillow = 2 * (Image.MAX_IMAGE_PIXELS or 0)
    if pillow >= MAX_IMAGE_PIXELS:
        return (f"{path}: declares an image of more than {pillow:,} pixels; images of at most {MAX_IMAGE_PIXELS:,} "
                "pixels are read (MAX_IMAGE_PIXELS)")
    return (f"{path}: not a readable image (Pillow refuses images of more than {pillow:,} pixels: twice its "
            f"Image.MAX_IMAGE_PIXELS, {pillow // 2:,})")


def _read_grey(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """Image file ``path`` as a ``(H, W)`` uint8 grey array (a colour image converted, alpha dropped).

    Its header is read first (:func:`_declared_size`): an image over :data:`MAX_IMAGE_PIXELS`, or of
    another size than ``size`` (``(width, height)`` px, the sequence's: no frame costs more than the
    first), is refused before a decoder allocates it.

    Raises:
        ValueError: naming the file (see :func:`_declared_size`), its size against ``size``, an image
            OpenCV cannot decode or allocate, or one that is not 8-bit.
    """
    import cv2

    width, height = _declared_size(path)
    if size is not None and (width, height) != tuple(size):
        raise ValueError(f"{path}: a {width}x{height} image; the sequence's images are {size[0]}x{size[1]}")
    try:
        image = cv2.imread(os.fspath(path), cv2.IMREAD_UNCHANGED)
    except (cv2.error, MemoryError) as err:  # OpenCV's own pixel limit, or an allocation that failed
        # cv2.error's .err is the reason alone, without OpenCV's source file and function
        detail = " ".join(str(getattr(err, "err", None) or err).split()) or "out of memory"
        raise ValueError(f"{path}: not a readable image (OpenCV: {detail})") from None
    if image is None:
        raise ValueError(f"{path}: not a readable image (OpenCV decodes no image from it: damaged or truncated)")
    if image.shape[:2] != (height, width):  # Pillow and OpenCV read the file differently
        raise ValueError(f"{path}: decoded as a {image.shape[1]}x{image.shape[0]} image, but its header declares "
                         f"{width}x{height}")
    if image.ndim == 3 and image.shape[2] not in (3, 4):  # cvtColor would fail with OpenCV's own error
        raise ValueError(f"{path}: a {image.shape[2]}-channel image; the front end takes grey, BGR or BGRA images")
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if image.dtype != np.uint8:
        raise ValueError(f"{path}: {image.dtype} image; the front end takes 8-bit grey images")
    return image


class KittiOdometry(ImageSequence):
    """A KITTI odometry sequence as frame pairs (see the module docstring for the layout).

    Args:
        root: the dataset folder (holding ``sequences/`` and optionally ``poses/``) or one
            sequence's folder (holding ``image_0/``).
        sequence: the sequence name, e.g. ``"00"`` (or an int, written with two digits); None
            when ``root`` is the sequence folder.
        start, stop: image range ``[start, stop)`` (stop None: to the end); poses are re-anchored
            so that the first image's pose is the identity.
        noise_sigma: the pixel noise (px) the frames declare to the estimator.
        label_tolerance: pixel gate of the approximate labels (px).
        **frontend_options: :class:`~stereovo.frontend.FrontendOptions` fields.

    Attributes:
        true_poses: ``(F+1, 4, 4)`` poses from ``poses/NN.txt``, or None without it.

    Raises:
        FileNotFoundError: a missing folder, image folder or calib.txt, named.
        ValueError: malformed calibration or poses (or files of them that are not regular files), unequal
            image counts or names, fewer than two image pairs, a bad range, a first image that is
            unreadable, not a regular file, over :data:`MAX_IMAGE_PIXELS` or under
            :data:`~stereovo.frontend.images.MIN_IMAGE_SIDE` on a side, or a truncated JPEG (a later
            image is read, and refused likewise, by :meth:`load_images`).
    """

    def __init__(self, root: str | os.PathLike, sequence: str | int | None = "00", start: int = 0,
                 stop: int | None = None, noise_sigma: float = 0.5, label_tolerance: float = 3.0,
                 **frontend_options: Any) -> None:
        root = Path(root).expanduser()
        if not root.is_dir():
            raise FileNotFoundError(f"KittiOdometry: no folder {root}")
        name = f"{sequence:02d}" if isinstance(sequence, int) and not isinstance(sequence, bool) else sequence
        if (root / "image_0").is_dir():
            folder, name = root, name if name is not None else root.name
            pose_candidates = [root.parent.parent / "poses" / f"{name}.txt", root / "poses.txt"]
        else:
            if name is None:
                raise FileNotFoundError(f"KittiOdometry: {root} holds no image_0/; give sequence= or a sequence folder")
            folder = root / "sequences" / str(name)
            if not folder.is_dir():
                if os.path.lexists(root / "image_0"):  # there, but no folder: what the user meant, unreadable
                    raise FileNotFoundError(f"KittiOdometry: {root / 'image_0'} is not a folder of images (a file, "
                                            f"a broken link or a link loop), and there is no sequence folder {folder}")
                raise FileNotFoundError(f"KittiOdometry: no sequence folder {folder}, and no image_0/ in {root}")
            pose_candidates = [root / "poses" / f"{name}.txt"]
        calib = folder / "calib.txt"
        if not os.path.lexists(calib):  # (one that is there but no file is refused, as such, when read)
            raise FileNotFoundError(f"KittiOdometry: no calibration file {calib}")
        lefts, rights = _images(folder / "image_0"), _images(folder / "image_1")
        if len(lefts) != len(rights):
            raise ValueError(f"KittiOdometry: {len(lefts)} left images but {len(rights)} right images in {folder}")
        for left, right in zip(lefts, rights):
            # a pair is two files of one name (the suffix may differ: a PNG and a JPEG of one frame): paired by
            # position alone, one renamed file would pair every later left image with the next right one
            if left.stem != right.stem:
                raise ValueError(f"KittiOdometry: {left} has no right image of its name in {folder / 'image_1'} "
                                 f"(the one in its place, in name order, is {right.name}): a left and a right image "
                                 "are paired by name")
        n = len(lefts)
        if n < 2:  # a run of no frame pairs would pass as a run that went well
            raise ValueError(f"KittiOdometry: {folder} holds {n} image pair; odometry needs at least 2 (one frame "
                             "pair)")
        start = Integer(low=0, high=max(n - 2, 0)).check("start", start, prefix="KittiOdometry: ")
        stop = Integer(low=start + 2, high=n, allow_none=True).check("stop", stop, prefix="KittiOdometry: ")
        stop = n if stop is None else stop
        self.label_tolerance = float(Number(low=0.0, low_open=True, unit="px").check(
            "label_tolerance", label_tolerance, prefix="KittiOdometry: "))
        first = _read_grey(lefts[start])
        width, height = int(first.shape[1]), int(first.shape[0])
        if width < MIN_IMAGE_SIDE or height < MIN_IMAGE_SIDE:
            # every frame would fail; a simulator setting checked against the size (the environment's
            # z_max) would be the one blamed
            raise ValueError(f"KittiOdometry: {lefts[start]} is a {width}x{height} image; the front end finds no "
                             f"features in images smaller than {MIN_IMAGE_SIDE} px on a side (ORB's border alone "
                             "is 31 px)")
        camera = read_calibration(calib)
        if not (0 <= camera.cx <= width and 0 <= camera.cy <= height):
            # a calibration of some other image size: every ray would be bent the wrong way
            raise ValueError(f"KittiOdometry: {calib} puts the principal point at ({camera.cx:g}, {camera.cy:g}) px, "
                             f"outside the {width}x{height} images of {folder / 'image_0'}")
        camera = StereoCamera(fx=camera.fx, fy=camera.fy, cx=camera.cx, cy=camera.cy, baseline=camera.baseline,
                              width=width, height=height)
        super().__init__(camera, noise_sigma=noise_sigma, **frontend_options)
        self.root, self.folder, self.sequence = root, folder, name
        self._lefts, self._rights = lefts[start:stop], rights[start:stop]
        self.start = start
        # one that is there but no file (a broken link, a FIFO) is refused when read, not passed over in silence
        self.poses_file = next((p for p in pose_candidates if os.path.lexists(p)), None)
        self.true_poses = None
        if self.poses_file is not None:
            poses = read_poses(self.poses_file)
            if len(poses) < stop:
                raise ValueError(f"KittiOdometry: {self.poses_file} has {len(poses)} poses for {n} images")
            anchor = invert_transform(poses[start])
            self.true_poses = anchor @ poses[start:stop]
            self.true_poses.setflags(write=False)

    def n_images(self) -> int:
        return len(self._lefts)

    def load_images(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        size = (self.camera.width, self.camera.height)  # checked in each header, before decoding
        try:
            return _read_grey(self._lefts[k], size), _read_grey(self._rights[k], size)
        except ValueError as err:
            raise ValueError(f"KittiOdometry: image pair {k}: {err}") from None

    def label(self, k: int, matches: Matches) -> FrameTruth | None:
        if self.true_poses is None:
            return None
        R, t = relative_motion(self.true_poses[k - 1], self.true_poses[k])
        X, _, usable = self.camera.triangulate_usable(matches.prev, 1.0)
        X = np.where(usable[:, None], X, np.array([0.0, 0.0, 1.0]))
        moved = X @ R.T + t
        ahead = usable & (moved[:, 2] > 1e-6)
        predicted = self.camera.project(np.where(ahead[:, None], moved, np.array([0.0, 0.0, 1.0])))
        error = np.abs(matches.curr[:, :3] - predicted[:, :3])
        inlier = ahead & np.all(error <= self.label_tolerance, axis=1)
        kind = np.where(inlier, int(OutlierKind.INLIER), int(OutlierKind.RANDOM_MISMATCH)).astype(np.int8)
        return FrameTruth(rotation=R, translation=t, inlier=inlier, outlier_kind=kind,
                          pose_prev=self.true_poses[k - 1], pose_curr=self.true_poses[k],
                          outlier_ratio=float(1.0 - inlier.mean()) if inlier.size else 1.0)

    def __repr__(self) -> str:
        return f"KittiOdometry({os.fspath(self.root)!r}, sequence={self.sequence!r}, frames={len(self)})"
