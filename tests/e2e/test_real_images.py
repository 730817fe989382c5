"""Real images: OpenCV's sample chessboard photographs (tests/data/opencv_left, see its README).

``detect_board`` must find and number every corner, and a camera calibrated from its corners
must agree with OpenCV's own pipeline (frozen in reference.json) and with OpenCV's published
calibration of the same camera (left_intrinsics.yml)."""

from __future__ import annotations

import json
from pathlib import Path

from classic_corners import classic_corners
import cv2
from hmlvs.data.views import ViewData
from hmlvs.diagnostics.checks import lens_ratios
from hmlvs.geometry.board import BoardSpec, Checkerboard
from hmlvs.image.corner_base import CornerOptions
from hmlvs.image.corners import BoardNotFoundError, detect_board, find_corners, flip_board_numbering
from hmlvs.models.opencv import CLASSIC_DISTORTION
import numpy as np
import pytest

DATA = Path(__file__).parents[1] / "data" / "opencv_left"
REF = json.loads((DATA / "reference.json").read_text())
BOARD = Checkerboard(rows=6, cols=9, square=1.0)  # OpenCV's pattern (9, 6): 9 corners per row


def _gray(name: str) -> np.ndarray:
    img = cv2.imread(str(DATA / name), cv2.IMREAD_GRAYSCALE)
    assert img is not None, name
    return img


def _opencv_corners(gray: np.ndarray) -> np.ndarray:
    """OpenCV's own pipeline, as reference.json was made."""
    ok, c = cv2.findChessboardCorners(gray, (9, 6))
    assert ok
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    return cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), crit).reshape(-1, 2)


@pytest.fixture(scope="module")
def detected() -> dict:
    return {name: detect_board(_gray(name), BOARD) for name in REF["images"]}


@pytest.fixture(scope="module")
def subpix() -> dict:
    """The same detection refined as OpenCV's classic pipeline does (cornerSubPix alone)."""
    opts = CornerOptions(refine="cornersubpix")
    return {name: detect_board(_gray(name), BOARD, opts) for name in REF["images"]}


def _calibrate(corners: dict) -> tuple:
    obj, img = [], []
    for c in corners.values():
        obj.append(np.hstack([c.board_xy, np.zeros((len(c), 1))]).astype(np.float32))
        img.append(c.pixels.astype(np.float32))
    return (obj, img) + tuple(cv2.calibrateCamera(obj, img, (640, 480), None, None))


def test_detect_board_finds_all_54_corners_on_every_image(detected):
    assert len(detected) == 12
    for name, c in detected.items():
        assert len(c) == 54, name
        assert c.rule == "top-left"
        np.testing.assert_array_equal(c.index, np.arange(54))
        # r0c0 is the numbered corner nearest the image's top-left among r0c0 and its
        # 180-degree twin
        assert c.pixels[0].sum() < c.pixels[-1].sum(), name


def test_detected_corners_agree_with_opencvs_pipeline(detected):
    """Same corners as findChessboardCorners + cornerSubPix, up to numbering: different
    detectors and refinement windows, so a tenth of a pixel typically."""
    for name, c in detected.items():
        ref = _opencv_corners(_gray(name))
        # OpenCV's numbering may differ from ours (turned or mirrored): compare each corner
        # with OpenCV's nearest one
        d = np.linalg.norm(c.pixels[:, None] - ref[None], axis=2).min(axis=1)
        # OpenCV's 11 x 11 cornerSubPix window spans more than a square on the views where
        # the board is small (left02, 07, 09, 13) and pulls up to 6 of their corners by 1-6 px
        # (left02's 1.2 px view error in its reference); our window scales with the square
        # and our corners fit the calibrated camera within 0.6 px (test below)
        assert np.count_nonzero(d > 0.5) <= 6, (name, np.sort(d)[-8:])
        assert np.median(d) < 0.12, (name, np.median(d))


def test_calibration_from_detected_corners_matches_reference(detected):
    obj, img, rms, k, dist, rvecs, tvecs = _calibrate(detected)
    # The reference calibrates the same 12 views of a 640 x 480 camera. Its corners differ
    # from ours by ~0.1 px, except a few that OpenCV's pipeline misplaces by 1-6 px (test
    # above); they pull the reference's fx by ~0.6 % (ours: 533.5 px, the reference
    # 536.4 px, OpenCV's published 535.9 px) and cy by ~1.5 px. Hence 1 % on
    # fx, fy and 3 px on the principal point; a wrong numbering gives nonsense or a huge RMS.
    assert k[0, 0] == pytest.approx(REF["fx"], rel=0.01)
    assert k[1, 1] == pytest.approx(REF["fy"], rel=0.01)
    assert abs(k[0, 2] - REF["cx"]) < 3.0
    assert abs(k[1, 2] - REF["cy"]) < 3.0
    # k1, k2, k3 trade off against each other (ours k1 -0.282; the reference's -0.266,
    # -0.042, 0.243): only k1, the dominant term, is compared
    assert dist.ravel()[0] == pytest.approx(REF["dist"][0], abs=0.04)
    # OpenCV's own RMS over these images is 0.42 px, mostly from left02 (1.2 px, the
    # misplaced corners); ours is 0.17 px, every corner of every view within 0.6 px
    assert rms < 0.3
    assert rms < REF["rms"]
    for o, i, r, t in zip(obj, img, rvecs, tvecs):
        p, _ = cv2.projectPoints(o, r, t, k, dist)
        assert np.linalg.norm(p.reshape(-1, 2) - i, axis=1).max() < 0.6
    # OpenCV's published calibration (13 images, aspect ratio fixed) of the same camera
    pub = cv2.FileStorage(str(DATA / "left_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    kp = pub.getNode("camera_matrix").mat()
    pub.release()
    assert k[0, 0] == pytest.approx(kp[0, 0], rel=0.01)
    assert abs(k[0, 2] - kp[0, 2]) < 3.0 and abs(k[1, 2] - kp[1, 2]) < 3.0


def test_the_lens_check_passes_a_real_lens(detected):
    """A real lens of five terms (OpenCV's left camera): the rational terms and the tilted
    sensor's fit its corners no better than the noise allows (measured 0.995 and 0.993 of
    the RMS, 0.165 and 0.165 against 0.166 px; the verdict's limit is LENS_RATIO_MIN = 0.8, a
    rendered wide lens 0.43, a rendered tilted sensor 0.16)."""
    views = [ViewData(name, c.pixels, c.index, np.empty((0, 2)), None)
             for name, c in detected.items()]
    five, wider = lens_ratios(views, BoardSpec(6, 9, 1.0), (640, 480), CLASSIC_DISTORTION)
    assert len(wider) == 2 and five < 0.3
    for rms in wider.values():
        assert 0.95 < rms / five <= 1.0, wider


def test_flip_board_numbering_turns_the_board(detected):
    c = detected["left01.jpg"]
    f = flip_board_numbering(c)
    assert f.rule == "top-left flipped"
    np.testing.assert_array_equal(f.pixels[0], c.pixels[-1])
    np.testing.assert_array_equal(f.pixels, c.pixels[::-1])
    back = flip_board_numbering(f)
    np.testing.assert_array_equal(back.pixels, c.pixels)
    assert back.rule == "top-left"


def test_detect_board_without_a_board_says_so():
    blank = np.full((480, 640), 128, np.uint8)
    with pytest.raises(BoardNotFoundError, match="no fully visible 6 x 9 checkerboard"):
        detect_board(blank, BOARD)
    # the wrong pattern size is not a board either
    with pytest.raises(BoardNotFoundError):
        detect_board(_gray("left01.jpg"), Checkerboard(rows=7, cols=9, square=1.0))


@pytest.mark.parametrize("kwargs, message", [
    ({"max_error": "x"}, "corners.max_error must be a positive number, got 'x'"),
    ({"max_error": 0}, "corners.max_error must be a positive number, got 0"),
    ({"max_error": float("nan")}, "corners.max_error must be a positive number"),
    ({"extend": "yes"}, "corners.extend must be true or false, got 'yes'"),
    ({"fallback": 1}, "corners.fallback must be true or false, got 1"),
    ({"refine": "subpixel"}, "corners.refine must be one of saddle, cornersubpix, got "
                             "'subpixel'"),
])
def test_corner_options_are_checked(kwargs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        CornerOptions(**kwargs)


def test_corner_options_from_a_mapping_reject_unknown_names():
    assert CornerOptions.from_dict({"max_error": 0.5}).max_error == 0.5
    with pytest.raises(ValueError, match="unknown corner option.* max_err; valid: extend, "
                                         "max_error, fallback, refine"):
        CornerOptions.from_dict({"max_err": 0.5})


def test_find_corners_takes_options_or_the_old_keywords(detected):
    gray = _gray("left03.jpg")
    old = find_corners(gray, BOARD, extend=False, max_error=0.3)
    new = find_corners(gray, BOARD, options=CornerOptions(extend=False, max_error=0.3))
    np.testing.assert_array_equal(old.pixels, new.pixels)
    np.testing.assert_array_equal(new.pixels, detected["left03.jpg"].pixels)
    with pytest.raises(ValueError, match="options must be a CornerOptions"):
        find_corners(gray, BOARD, options={"extend": False})


def _nearest(ours: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per corner of ``ref``, the distance to the nearest of ``ours`` (numberings may differ)."""
    return np.linalg.norm(ref[:, None] - ours[None], axis=2).min(axis=1)


def test_every_corner_agrees_with_the_classic_detector_with_an_in_square_window(subpix):
    """findChessboardCorners + cornerSubPix with a window inside the squares finds the same
    54 corners in every view as detect_board refining with cornerSubPix alone, to 0.1 px
    (measured: under 0.001 px; both refinements converge to the same points from different
    starts), one to one."""
    for name, c in subpix.items():
        ref, _, win = classic_corners(_gray(name), None)
        assert 6 <= win <= 8, name
        d = _nearest(c.pixels, ref)
        assert d.max() < 0.1, (name, d.max())
        # one to one: every classic corner's nearest detected corner is a different one
        j = np.linalg.norm(ref[:, None] - c.pixels[None], axis=2).argmin(axis=1)
        assert len(set(j.tolist())) == 54, name


def test_saddle_refinement_fits_the_camera_better_than_cornersubpix(detected, subpix):
    """The default refinement (the smoothed image's saddle point after cornerSubPix) moves
    the classic in-square corners by 0.08 px (median; at most 0.40 px) and the camera
    calibrated from them fits better: RMS 0.166 px against 0.184 px with cornerSubPix
    alone (the same views, model and numbering), so the move is accuracy, not noise."""
    d = np.concatenate([_nearest(detected[n].pixels, subpix[n].pixels) for n in subpix])
    assert np.median(d) < 0.12 and d.max() < 0.5
    rms_saddle = _calibrate(detected)[2]
    rms_subpix = _calibrate(subpix)[2]
    assert rms_saddle < 0.95 * rms_subpix, (rms_saddle, rms_subpix)


def test_corners_agree_with_the_classic_11x11_pipeline_where_it_is_stable(subpix):
    """With OpenCV's customary 11 x 11 half-window (23 x 23 px, about a whole square on the
    small boards) cornerSubPix misplaces some corners. Rule: a classic corner counts as
    misplaced when its 11 x 11 refinement lies more than 0.5 px from its refinement with
    the in-square window (the result depends on the window). Measured: 15 of the 648
    corners (left02: 6, left07: 1, left09: 3, left13: 5), each 0.9-6.4 px off ours; every
    other corner within 0.43 px of ours (the larger window averages over more of the blur
    and JPEG noise), median 0.05 px."""
    misplaced, dist = {}, []
    for name, c in subpix.items():
        big, small, _ = classic_corners(_gray(name), 11)
        unstable = np.linalg.norm(big - small, axis=1) > 0.5
        d = _nearest(c.pixels, big)
        misplaced[name] = int(unstable.sum())
        assert np.all(d[unstable] > 0.5), name  # the rule picks corners that are really off
        dist.append(d[~unstable])
    d = np.concatenate(dist)
    assert sum(misplaced.values()) <= 20 and len(d) >= 628, misplaced
    assert {k for k, v in misplaced.items() if v} <= {"left02.jpg", "left07.jpg", "left09.jpg",
                                                       "left13.jpg"}
    assert d.max() < 0.5 and np.median(d) < 0.1


@pytest.mark.parametrize("bits", [8, 10, 12, 16])
def test_boards_are_found_at_every_bit_depth(bits):
    """A 10- or 12-bit camera stores values up to 1023 / 4095 in a 16-bit file: the board is
    found as in the 8-bit original (scaled by the image's range, not by 1/256)."""
    import cv2
    from hmlvs.geometry.board import Checkerboard
    from hmlvs.image.corners import detect_board

    img8 = cv2.imread(str(DATA / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    img = img8 if bits == 8 else (img8.astype(np.uint16) << (bits - 8))
    board = Checkerboard(rows=6, cols=9, square=25.0)
    ref = detect_board(img8, board)
    got = detect_board(img, board)
    assert len(got.index) == 54
    assert np.abs(got.pixels - ref.pixels).max() < 0.05
