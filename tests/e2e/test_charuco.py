"""ChArUco boards: a board image made by OpenCV (``CharucoBoard.generateImage``), warped by a
homography (``cv2.warpPerspective``), detected and numbered by its marker ids, also when it
is turned or only partly visible; and a ChArUco session read through its manifest."""

from __future__ import annotations

import json

import cv2
from hmlvs.calibration.joint import calibrate_joint
from hmlvs.geometry.board import BoardSpec, CharucoSpec
from hmlvs.image.charuco import detect_charuco
from hmlvs.image.corners import BoardNotFoundError
from hmlvs.image.views import views_from_images
from hmlvs.report.inspect import inspect_session
import numpy as np
import pytest

BOARD = CharucoSpec(9, 7, 20.0, 15.0, "DICT_5X5_100")  # 6 x 8 = 48 chessboard corners
SIZE = (1024, 768)
S, M = 80, 40  # px per square and margin of the generated board image


def _source() -> tuple[np.ndarray, np.ndarray]:
    """The board image and its chessboard corners' pixels (centre convention), by id."""
    cvb = BOARD.cv_board()
    img = cvb.generateImage((BOARD.squares_x * S + 2 * M, BOARD.squares_y * S + 2 * M),
                            marginSize=M)
    # the generated image holds whole S-pixel squares from the margin on: a corner at board
    # (x, y) mm sits on the pixel edge M + x / square * S, i.e. at that minus 0.5 in pixel
    # centre coordinates
    obj = cvb.getChessboardCorners()[:, :2]
    return img, M + obj / BOARD.square * S - 0.5


def homography(angle_deg: float, scale: float, shift: tuple[float, float],
               persp: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    a = np.radians(angle_deg)
    return np.array([[scale * np.cos(a), -scale * np.sin(a), shift[0]],
                     [scale * np.sin(a), scale * np.cos(a), shift[1]],
                     [persp[0], persp[1], 1.0]])


def render(h: np.ndarray, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The board warped into a SIZE image (blurred against aliasing, dimmed, noisy) and the
    true pixel of every chessboard corner (by id)."""
    src, corners = _source()
    img = cv2.warpPerspective(cv2.GaussianBlur(src, (0, 0), 1.2), h, SIZE,
                              flags=cv2.INTER_LINEAR, borderValue=110)
    rng = np.random.default_rng(seed)
    img = np.clip(0.8 * img + 20 + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)
    truth = cv2.perspectiveTransform(corners.reshape(-1, 1, 2).astype(float), h).reshape(-1, 2)
    return img, truth


VIEWS = {
    "upright": homography(10, 0.7, (200, 100), (1e-4, 5e-5)),
    "turned": homography(185, 0.7, (850, 650), (-1e-4, 1e-4)),  # upside down
    "partial": homography(-20, 0.9, (-250, 200), (1e-4, 0.0)),  # its left part outside
}


def _inside(truth: np.ndarray, margin: float = 5.0) -> np.ndarray:
    return (truth[:, 0] > margin) & (truth[:, 0] < SIZE[0] - 1 - margin) & \
        (truth[:, 1] > margin) & (truth[:, 1] < SIZE[1] - 1 - margin)


@pytest.mark.parametrize("name", list(VIEWS))
def test_charuco_corners_are_found_and_numbered_by_their_ids(name):
    img, truth = render(VIEWS[name])
    c = detect_charuco(img, BOARD)
    assert c.rule == "charuco ids"
    n_inside = int(_inside(truth).sum())
    if name == "partial":
        assert 20 <= n_inside < 48
        # corners whose neighbouring markers are cut off cannot be interpolated: most others are
        assert len(c) >= n_inside - 8
    else:
        assert n_inside == 48 and len(c) == 48
    # each corner at its id's true pixel: a wrong id would be a square (>= 50 px) away
    err = np.linalg.norm(c.pixels - truth[c.index], axis=1)
    # measured: at most 0.07 px, RMS <= 0.05 px
    assert err.max() < 0.15, (name, err.max())
    assert np.sqrt(np.mean(err**2)) < 0.08, name
    assert np.all(np.diff(c.index) > 0)


def test_charuco_ids_map_to_the_board_frame_points():
    """ChArUco id k is board index k: corner (r, c) = (k // cols, k % cols) at (r, c) squares,
    OpenCV's (c + 1, r + 1) squares; the board frame's points map to the detected pixels by
    one homography (so calibrate_joint's board.points(corner_index) is consistent)."""
    obj = BOARD.cv_board().getChessboardCorners()
    pts = BOARD.points()
    np.testing.assert_allclose(pts[:, 0], obj[:, 1] - BOARD.square)
    np.testing.assert_allclose(pts[:, 1], obj[:, 0] - BOARD.square)
    img, _ = render(VIEWS["turned"])
    c = detect_charuco(img, BOARD)
    h, _ = cv2.findHomography(BOARD.points(c.index)[:, :2], c.pixels, 0)
    back = cv2.perspectiveTransform(BOARD.points(c.index)[:, None, :2], h).reshape(-1, 2)
    assert np.linalg.norm(back - c.pixels, axis=1).max() < 0.3


def test_no_charuco_board_says_so():
    blank = np.full(SIZE[::-1], 120, np.uint8)
    with pytest.raises(BoardNotFoundError, match="no ChArUco board found.*0 chessboard corners"):
        detect_charuco(blank, BOARD)
    # a board of another dictionary is not this board
    other = CharucoSpec(9, 7, 20.0, 15.0, "DICT_6X6_50")
    img, _ = render(VIEWS["upright"])
    with pytest.raises(BoardNotFoundError):
        detect_charuco(img, other)
    with pytest.raises(ValueError, match="needs a CharucoSpec"):
        detect_charuco(img, BoardSpec(6, 8, 20.0))


@pytest.mark.parametrize("values, message", [
    ({"squares_x": 9, "squares_y": 7, "square": 20}, "lacks marker"),
    ({"squares_x": 9, "squares_y": 7, "square": 20, "marker": 25}, "smaller than the square"),
    ({"squares_x": 9, "squares_y": 7, "square": 20, "marker": 15, "dictionary": "DICT_9"},
     "unknown ArUco dictionary 'DICT_9'"),
    ({"squares_x": 30, "squares_y": 20, "square": 20, "marker": 15},
     "needs more markers than DICT_4X4_50 holds"),
    ({"squares_x": 9, "squares_y": 7, "square": 20, "marker": 15, "rows": 3},
     "unknown ChArUco board field"),
])
def test_charuco_board_description_is_checked(values, message):
    """A wrong description is refused with a sentence; a right one round-trips through its
    manifest form (also via BoardSpec.of, as calibrate_joint takes a board)."""
    assert CharucoSpec.from_dict(BOARD.to_dict()) == BOARD
    assert BoardSpec.of(BOARD.to_dict()) == BOARD and BoardSpec.of(BOARD) is BOARD
    with pytest.raises(ValueError, match=message):
        CharucoSpec.from_dict({"type": "charuco", **values})


def _laser(off: np.ndarray, v0: float, slope: float) -> np.ndarray:
    """The laser-on frame: a bright Gaussian line v = v0 + slope * u added to ``off``."""
    vv, uu = np.mgrid[0:off.shape[0], 0:off.shape[1]].astype(float)
    line = 120.0 * np.exp(-0.5 * ((vv - v0 - slope * uu) / 1.5) ** 2)
    return np.clip(off + line, 0, 255).astype(np.uint8)


def test_a_charuco_session_gives_views_numbered_by_ids(tmp_path):
    """A manifest with ``board: {type: charuco, ...}``: every view's corner_index is the
    ChArUco id (the true corner of that id lies at the pixel); a view without the board is
    rejected with the reason."""
    entries, truths = [], {}
    for k, (name, h) in enumerate([*VIEWS.items(), ("empty", None)]):
        if h is None:
            off = np.full(SIZE[::-1], 110, np.uint8)
        else:
            off, truths[name] = render(h, seed=k)
        cv2.imwrite(str(tmp_path / f"{name}_off.png"), off)
        cv2.imwrite(str(tmp_path / f"{name}_on.png"), _laser(off, 300 + 40 * k, 0.05))
        pose = np.eye(4)
        pose[:3, 3] = [600.0, 10.0 * k, 300.0]
        entries.append({"id": name, "on": f"{name}_on.png", "off": f"{name}_off.png",
                        "pose": pose.tolist()})
    (tmp_path / "manifest.json").write_text(json.dumps({
        "format": "hmlvs-images", "version": 1,
        "board": {"type": "charuco", "squares_x": 9, "squares_y": 7, "square": 20.0,
                  "marker": 15.0, "dictionary": "DICT_5X5_100"},
        "poses": entries}))
    views, board, size, pose, reports = views_from_images(tmp_path)
    assert board == BOARD and pose is None and size == SIZE
    assert [v.id for v in views] == list(VIEWS)
    for v in views:
        err = np.linalg.norm(v.corner_pixels - truths[v.id][v.corner_index], axis=1)
        assert err.max() < 0.15, v.id
        assert len(v.laser_pixels) > 500
    assert len(views[0].corner_index) == 48
    bad = [r for r in reports if not r.ok]
    assert [r.id for r in bad] == ["empty"]
    assert "no ChArUco board found" in bad[0].reason


def test_an_unknown_board_type_in_a_manifest_is_named(tmp_path):
    (tmp_path / "manifest.json").write_text(json.dumps({
        "format": "hmlvs-images", "version": 1, "board": {"type": "circles", "rows": 4},
        "poses": [{"id": "a", "on": "a.png", "off": "b.png", "pose": np.eye(4).tolist()}]}))
    with pytest.raises(ValueError, match="unknown board type 'circles'"):
        views_from_images(tmp_path)


def _rt(rvec, t) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float))[0]
    m[:3, 3] = t
    return m


def _camera_session(n_views: int, seed: int):
    """A physically consistent session: a pinhole camera (fx = fy = 900 px, no distortion) on
    a robot hand looks at the ChArUco board (every third view with the board partly out of
    the image); the laser plane's line is drawn on the board. The board image is mapped by
    K [r1 r2 t] (our board frame, mm) composed with board mm -> generated-image pixels.
    Returns the images, poses and the truth."""
    s, m = 60, 30
    src = BOARD.cv_board().generateImage((BOARD.squares_x * s + 2 * m,
                                          BOARD.squares_y * s + 2 * m), marginSize=m)
    src = cv2.GaussianBlur(src, (0, 0), 1.0)
    k_mm = s / BOARD.square  # ours (x, y) is OpenCV's (y + square, x + square)
    a = np.array([[0, k_mm, m + s - 0.5], [k_mm, 0, m + s - 0.5], [0, 0, 1.0]])
    k = np.array([[900.0, 0, 512], [0, 900.0, 384], [0, 0, 1]])
    hand_from_camera = _rt([0.02, -0.03, 1.6], [55.0, -5.0, -40.0])
    base_from_board = _rt([np.pi, 0, 0.3], [650.0, 50.0, 0.0])
    n = np.array([0.0, 0.94, 0.34]) / np.linalg.norm([0.0, 0.94, 0.34])
    plane = np.r_[n, -n @ np.array([0, 0, 380.0])]
    rng = np.random.default_rng(seed)
    centre = np.array([(BOARD.rows - 1) * BOARD.square / 2, (BOARD.cols - 1) * BOARD.square / 2,
                       0.0])
    vv, uu = np.mgrid[0:SIZE[1], 0:SIZE[0]].astype(float)
    out = []
    for i in range(n_views):
        # our board frame's z points to the printed side, towards the camera
        r = cv2.Rodrigues(rng.uniform(-0.35, 0.35, 3) + [0, 0, rng.uniform(-np.pi, np.pi)])[0] \
            @ np.diag([1.0, -1.0, -1.0])
        t = np.array([rng.normal(0, 15), rng.normal(0, 15), rng.uniform(330, 420)])
        if i % 3 == 1:
            t[0] += rng.choice([-1, 1]) * 150
        cam = np.eye(4)
        cam[:3, :3], cam[:3, 3] = r, t - r @ centre  # camera_from_board
        h = k @ np.c_[cam[:3, 0], cam[:3, 1], cam[:3, 3]] @ np.linalg.inv(a)
        off = 0.6 * cv2.warpPerspective(src, h, SIZE, borderValue=90) + 15 + \
            rng.normal(0, 1.5, SIZE[::-1])
        nb, tb = cam[:3, 2], cam[:3, 3]
        direction = np.cross(n, nb)
        p0 = np.linalg.solve(np.array([n, nb, direction]), [-plane[3], nb @ tb, 0])
        q = np.array([p0 - 400 * direction, p0 + 400 * direction]) @ k.T
        q = q[:, :2] / q[:, 2:]
        d = q[1] - q[0]
        dist = ((uu - q[0, 0]) * -d[1] + (vv - q[0, 1]) * d[0]) / np.linalg.norm(d)
        on = off + np.exp(-0.5 * (dist / 1.3) ** 2) * (0.5 * (off - 15) + 30)
        out.append({"on": np.clip(on, 0, 255).astype(np.uint8),
                    "off": np.clip(off, 0, 255).astype(np.uint8),
                    "pose": base_from_board @ np.linalg.inv(cam)
                    @ np.linalg.inv(hand_from_camera)})
    return out, k, hand_from_camera, plane


def test_a_rendered_charuco_session_calibrates_through_the_manifest(tmp_path):
    """Images -> views_from_images (ids as corner_index, partly visible boards kept) ->
    calibrate_joint: nothing flipped or rejected, the camera, the hand-eye transform and the
    laser plane recovered."""
    views, k, hand_from_camera, plane = _camera_session(9, seed=0)
    entries = []
    for i, v in enumerate(views):
        cv2.imwrite(str(tmp_path / f"v{i}_on.png"), v["on"])
        cv2.imwrite(str(tmp_path / f"v{i}_off.png"), v["off"])
        entries.append({"id": f"v{i}", "on": f"v{i}_on.png", "off": f"v{i}_off.png",
                        "pose": v["pose"].tolist()})
    (tmp_path / "manifest.json").write_text(json.dumps({
        "format": "hmlvs-images", "version": 1, "board": BOARD.to_dict(), "poses": entries}))
    got, board, size, _, reports = views_from_images(tmp_path)
    assert all(r.ok for r in reports) and len(got) == 9
    partial = [v.id for v in got if len(v.corner_index) < 48]
    assert len(partial) >= 2  # some views show only part of the board
    # hmlvs inspect draws the same corners (numbered by id) on the partly visible boards
    seen = inspect_session(tmp_path, tmp_path / "pics")
    assert [(v.used, v.corners) for v in seen] == [(True, len(v.corner_index)) for v in got]
    assert all(v.image is not None and v.image.is_file() for v in seen)
    r = calibrate_joint(got, board, size, distortion=())
    assert r.flipped == [] and r.rejected == {}
    # measured: corners 0.04 px RMS, fx, fy, cx, cy within 0.05 px, hand-eye translation
    # within 0.02 mm, plane distance within 0.001 mm
    assert r.corner_rms_px < 0.1
    s = r.sensor
    assert abs(s.fx - 900) < 0.5 and abs(s.fy - 900) < 0.5
    assert abs(s.cx - 512) < 0.5 and abs(s.cy - 384) < 0.5
    assert np.abs(s.hand_from_camera[:3, 3] - hand_from_camera[:3, 3]).max() < 0.2
    rot = s.hand_from_camera[:3, :3].T @ hand_from_camera[:3, :3]
    assert np.degrees(np.arccos(np.clip((np.trace(rot) - 1) / 2, -1, 1))) < 0.2
    assert np.abs(s.laser_plane[:3] - plane[:3]).max() < 2e-3
    assert abs(s.laser_plane[3] - plane[3]) < 0.1
