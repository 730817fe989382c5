"""The image pipeline on rendered sessions with known truth, from the board on: corners,
calibration points, and whole sessions of image files to a data set (difference images and
stripes: test_image.py)."""

from dataclasses import replace
import json

import cv2
import hmlvs
from hmlvs.image.corners import predicted_corners
from hmlvs.image.session import BOARD_SMOOTH_ALONG, stripe_from_pair
from hmlvs.image.stripe import StripeStatus
from hmlvs.sim.render import RenderOptions, render_pose
import numpy as np
import pytest
from scene_checks import shows_block, stripe_errors

pytestmark = pytest.mark.scene  # simulated sessions or rendered images


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A session with sensor noise written to disk (images + manifest)."""
    out = tmp_path_factory.mktemp("session")
    r = hmlvs.simulate.render_session(num_poses=8, seed=5, out_dir=out,
                                      options=RenderOptions(noise=1.0))
    return r, out


# ------------------------------------------------------------------------------ corners


def true_corner_errors(r, params=None):
    s = r.session
    poses = s.robot.poses(s.joints)
    errs, counts = [], []
    for i in range(len(poses)):
        truth = predicted_corners(s.truth, poses[i], s.board)
        exp = predicted_corners(params or s.truth, poses[i], s.board)
        try:
            c = hmlvs.image.corners.find_corners(r.off[i], s.board, expected=exp)
        except ValueError:
            counts.append(0)
            continue
        errs.append(np.linalg.norm(c.pixels - truth[c.index], axis=1))
        counts.append(len(c))
    return np.concatenate(errs), counts


def test_corners_accurate_and_numbered(clean):
    e, counts = true_corner_errors(clean)
    s = clean.session
    poses = s.robot.poses(s.joints)
    # every view that shows a whole 3 x 3 block of corners has its board found (views showing
    # less may or may not be found: a partial board without a 3 x 3 grid is rejected)
    clear = [shows_block(predicted_corners(s.truth, p, s.board), s.board) for p in poses]
    assert sum(clear) >= 2
    assert all(c > 0 for c, v in zip(counts, clear) if v)
    assert rms(e) < 0.1 and e.max() < 0.15
    # approximate parameters (3 mm, 1 degree off) number the corners the same way
    approx = clean.session.truth.replace(tx=clean.session.truth.tx + 3.0, omega=0.0175)
    e2, counts2 = true_corner_errors(clean, approx)
    # (cornerSubPix works in float32: the same corners to ~1e-6 px)
    assert counts2 == counts and rms(e2) == pytest.approx(rms(e), abs=1e-5)


def overhead_pose(q, flip=False):
    """base_from_hand with the camera 700 mm above the board centre, looking down, the image
    showing the whole board (rotated by 180 degrees with flip)."""
    x = np.array([0.0, 1.0, 0.0]) if flip else np.array([0.0, -1.0, 0.0])
    z = np.array([0.0, 0.0, -1.0])
    bfc = np.eye(4)
    bfc[:3, 0], bfc[:3, 1], bfc[:3, 2] = x, np.cross(z, x), z
    bfc[:3, 3] = [625.0, -15.0, 700.0]
    return bfc @ np.linalg.inv(hmlvs.models.paper.hand_from_camera(q))


def test_corner_numbering_full_board_and_flip():
    q = hmlvs.Parameters.nominal()
    board = hmlvs.Checkerboard()
    n = board.rows * board.cols
    for flip in (False, True):
        pose = overhead_pose(q, flip)
        img = render_pose(q, pose, board).off
        truth = predicted_corners(q, pose, board)
        c = hmlvs.image.corners.find_corners(img, board, expected=truth)
        assert len(c) == n and c.rule == "expected"
        assert np.linalg.norm(c.pixels - truth[c.index], axis=1).max() < 0.1
        # the marker-free rule: r0c0 is the corner nearest the image's top-left. Right for
        # the upright view; for the view turned by 180 degrees it numbers the board from the
        # opposite corner (the documented limit of a rule without markers).
        c2 = hmlvs.image.corners.find_corners(img, board)
        assert c2.rule == "top-left" and len(c2) == n
        want = truth if not flip else truth[::-1]
        assert np.linalg.norm(c2.pixels - want[c2.index], axis=1).max() < 0.1
    # a partly visible board cannot be numbered without expected pixels
    with pytest.raises(ValueError, match="for a partly visible board pass the expected"):
        hmlvs.image.corners.find_corners(
            render_pose(q, overhead_pose(q)[:, :] @ _shift(150), board).off,
                           board)


def test_find_corners_refuses_a_mirrored_expectation():
    """A 3 x 3 board seen whole: the mirror image of the expected pixels matches every
    detected corner (a mirror is a homography too), so only the board's handedness can tell
    that every label would be wrong. The mirrored expectation must be refused, the right
    one accepted."""
    q = hmlvs.Parameters.nominal()
    board = hmlvs.Checkerboard(rows=3, cols=3, square=60.0, origin=(685.0, 45.0, 0.0))
    pose = overhead_pose(q)
    img = render_pose(q, pose, board).off
    truth = predicted_corners(q, pose, board)
    c = hmlvs.image.corners.find_corners(img, board, expected=truth)
    assert len(c) == 9 and np.linalg.norm(c.pixels - truth[c.index], axis=1).max() < 0.1
    for mirror in (truth.reshape(3, 3, 2)[:, ::-1], truth.reshape(3, 3, 2)[::-1, :],
                   truth.reshape(3, 3, 2).transpose(1, 0, 2)):
        with pytest.raises(ValueError, match="mirror image"):
            hmlvs.image.corners.find_corners(img, board, expected=mirror.reshape(-1, 2))


def test_full_board_detector_gets_its_flags(clean, monkeypatch):
    """OpenCV's Python findChessboardCornersSB takes ``corners`` third: flags passed
    positionally are silently dropped. The detector must run with EXHAUSTIVE | ACCURACY."""
    calls = []
    real = cv2.findChessboardCornersSB

    def spy(*args, **kwargs):
        calls.append((args, kwargs))
        return real(*args, **kwargs)

    monkeypatch.setattr(cv2, "findChessboardCornersSB", spy)
    q = hmlvs.Parameters.nominal()
    board = hmlvs.Checkerboard()
    img = render_pose(q, overhead_pose(q), board).off
    hmlvs.image.corners.find_corners(img, board)
    assert len(calls) == 1
    args, kwargs = calls[0]
    want = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    assert len(args) == 2 and kwargs == {"flags": want}
    # and the flags change what OpenCV returns (ACCURACY refines the corners), so a call that
    # dropped them would not be the same call
    ok1, with_flags = real(img, (board.cols, board.rows), flags=want)
    ok2, without = real(img, (board.cols, board.rows))
    assert ok1 and ok2 and np.abs(with_flags - without).max() > 1e-3


def _shift(dx):
    t = np.eye(4)
    t[0, 3] = dx
    return t


def test_find_corners_no_board_and_bad_expected(clean):
    blank = np.full((480, 640), 120, np.uint8)
    with pytest.raises(ValueError, match="no checkerboard found"):
        hmlvs.image.corners.find_corners(blank, expected=np.zeros((48, 2)))
    with pytest.raises(ValueError, match=r"expected must hold the \(48, 2\)"):
        hmlvs.image.corners.find_corners(clean.off[0], expected=np.zeros((10, 2)))
    s = clean.session
    far = predicted_corners(s.truth, s.robot.poses(s.joints)[0], s.board) + [0.0, 0.0]
    far[:, 0] = far[:, 0][::-1]  # scrambled: nothing is where it should be
    # the corners matched to it that fit one grid are its mirror image (u reversed)
    with pytest.raises(ValueError, match="do not match the expected|do not form a board|"
                                         "a mirror image of the board"):
        hmlvs.image.corners.find_corners(clean.off[0], s.board, expected=far)


# ------------------------------------------------------------------------------ points


def test_calibration_points_corners_mode(clean):
    """The stripe passes through exactly the corners the session put on the laser plane;
    their stripe pixels are within 0.1 px of the exact ones."""
    s = clean.session
    poses = s.robot.poses(s.joints)
    found_ids, errs, found_views = [], [], set()
    for i in range(len(poses)):
        exp = predicted_corners(s.truth, poses[i], s.board)
        try:
            c = hmlvs.image.corners.find_corners(clean.off[i], s.board, expected=exp)
        except ValueError:
            assert not shows_block(exp, s.board)
            continue
        found_views.add(f"p{i:03d}")
        st = hmlvs.extract_stripe(hmlvs.difference_image(clean.on[i], clean.off[i],
                                                         normalize=True))
        cp = hmlvs.image.points.calibration_points(st, c, mode="corners")
        found_ids += [f"p{i:03d}:{k}" for k in cp.ids]
        exact, _ = hmlvs.models.paper.pixels_from_points(s.truth, cp.points,
                                            np.repeat(poses[i][None], len(cp), axis=0))
        errs.append(np.linalg.norm(cp.pixels - exact, axis=1))
        assert np.all(np.abs(cp.distance) < 0.5)
    # every corner of the session on the stripe, in every view whose board was found
    want = {k for k in s.dataset.ids if k.split(":")[0] in found_views}
    assert set(found_ids) == want and len(want) > 0
    e = np.concatenate(errs)
    assert rms(e) < 0.1 and e.max() < 0.15


def test_calibration_points_homography_mode(clean):
    s = clean.session
    poses = s.robot.poses(s.joints)
    errs, n_images = [], 0
    for i in range(len(poses)):
        exp = predicted_corners(s.truth, poses[i], s.board)
        try:
            c = hmlvs.image.corners.find_corners(clean.off[i], s.board, expected=exp)
        except ValueError:
            continue
        st = hmlvs.extract_stripe(hmlvs.difference_image(clean.on[i], clean.off[i],
                                                         normalize=True))
        cp = hmlvs.image.points.calibration_points(st, c, mode="homography", step=4)
        if len(cp) == 0:
            continue
        n_images += 1
        rep = np.repeat(poses[i][None], len(cp), axis=0)
        # the reference points lie on the board plane, at the laser plane to ~0.01 mm
        assert np.abs(cp.points[:, 2]).max() < 1e-9
        assert np.abs(hmlvs.models.paper.laser_plane_distance(s.truth, cp.points, rep)).max() < 0.05
        exact, _ = hmlvs.models.paper.project(s.truth, cp.points, rep)
        errs.append(np.linalg.norm(cp.pixels - exact, axis=1))
    e = np.concatenate(errs)
    assert e.size > 20 * n_images  # many points per image, not one or two corners
    assert rms(e) < 0.1 and e.max() < 0.3


def test_calibration_points_bad_input(clean):
    st = hmlvs.extract_stripe(hmlvs.difference_image(clean.on[0], clean.off[0]))
    s = clean.session
    c = hmlvs.image.corners.find_corners(clean.off[0], s.board, expected=predicted_corners(
        s.truth, s.robot.poses(s.joints)[0], s.board))
    with pytest.raises(ValueError, match="mode must be"):
        hmlvs.image.points.calibration_points(st, c, mode="lines")
    with pytest.raises(ValueError, match="tolerance must be > 0"):
        hmlvs.image.points.calibration_points(st, c, tolerance=0)
    with pytest.raises(ValueError, match="numbered on a 6 x 8 board"):
        hmlvs.image.points.calibration_points(st, c, hmlvs.Checkerboard(rows=5, cols=7))
    # a stripe without a found centre (every scan line flagged, here ALBEDO_EDGE: a stripe
    # along a row of squares' edges with the check on) gives no point and says why
    flagged = replace(st, status=np.where(st.found, np.uint8(StripeStatus.ALBEDO_EDGE),
                                          st.status))
    for mode in ("corners", "homography"):
        cp = hmlvs.image.points.calibration_points(flagged, c, mode=mode)
        assert len(cp) == 0 and cp.rejected, mode


# ------------------------------------------------------------------------------ sessions


def test_render_session_writes_manifest_and_images(written):
    r, out = written
    doc = json.loads((out / "manifest.json").read_text())
    assert doc["format"] == "hmlvs-images" and doc["joint_unit"] == "rad"
    assert doc["image_size"] == [640, 480] and len(doc["poses"]) == 8
    for i, e in enumerate(doc["poses"]):
        np.testing.assert_array_equal(cv2.imread(str(out / e["on"]), cv2.IMREAD_UNCHANGED),
                                      r.on[i])
        np.testing.assert_allclose(e["joints"], r.session.joints[i], rtol=0, atol=0)
    with np.load(out / "truth.npz") as z:
        np.testing.assert_array_equal(z["stripe_v"], r.stripe_v)
    assert not list(out.glob(".*tmp"))  # atomic writes leave no temporary files
    # the true stripe crosses the image in every pose
    assert np.isfinite(r.stripe_v).mean() > 0.95


@pytest.mark.parametrize("mode", ["corners", "homography"])
def test_dataset_from_images_end_to_end(written, mode):
    r, out = written
    s = r.session
    ds, report = hmlvs.image.paper_session.dataset_from_images(out, mode=mode)
    assert len(report) == 8
    assert sum(x.ok for x in report) >= 6
    assert all(x.reason for x in report if not x.ok)
    np.testing.assert_allclose(ds.poses, s.robot.poses(ds.joints), atol=1e-12)
    assert all(k.split(":")[0] == f"p{i:03d}" for k, i in zip(ds.ids, ds.pose_index))
    exact, ok = hmlvs.models.paper.project(s.truth, ds.points, ds.poses)
    err = np.linalg.norm(ds.pixels - exact, axis=1)
    assert ok.all() and rms(err) < 0.1
    e3 = np.linalg.norm(hmlvs.models.paper.residuals(s.truth, ds.pixels, ds.poses, ds.points),
                        axis=1)
    if mode == "corners":
        # the snapped corners are exactly the session's points: the residual is the 3D
        # effect of the pixel error alone
        assert set(ds.ids) <= set(s.dataset.ids)
        p_exact, _ = hmlvs.models.paper.points_in_base(s.truth, exact, ds.poses)
        p_found, _ = hmlvs.models.paper.points_in_base(s.truth, ds.pixels, ds.poses)
        assert rms(e3) == pytest.approx(rms(np.linalg.norm(p_found - p_exact, axis=1)),
                                        rel=1e-6)
    else:
        assert len(ds) > 10 * sum(x.ok for x in report)
    assert rms(e3) < 0.1  # mm, for < 0.1 px at ~0.25 mm per pixel
    assert ds.meta["smooth_along"] == BOARD_SMOOTH_ALONG  # the stripe lies on the board
    # every point carries the quality of its scan line of the stripe the session extracted
    from hmlvs.image.session import stripe_from_pair

    q = ds.quality
    assert sorted(q) == ["peak", "residual", "sigma", "width"]
    assert all(v.shape == (len(ds),) and np.isfinite(v).all() for v in q.values())
    assert (q["sigma"] > 0).all() and (q["residual"] >= 0).all()
    view = int(ds.pose_index[0])
    on, off = r.on[view], r.off[view]
    opts = {"smooth_along": ds.meta["smooth_along"], "blur_var": ds.meta["blur_var"]}
    if f"p{view:03d}" in ds.meta.get("albedo_offset_taken_by", []):
        opts["albedo_offset"] = ds.meta["albedo_offset_session"]
    stripe = stripe_from_pair(on, off, **opts)
    here = ds.pose_index == view
    line = np.rint(ds.pixels[here, 0]).astype(int)
    np.testing.assert_array_equal(q["width"][here], stripe.width[line])
    np.testing.assert_array_equal(q["peak"][here], stripe.intensity[line])
    np.testing.assert_array_equal(q["residual"][here], stripe.residual[line])


def test_smooth_along_bad_values(written):
    r, out = written
    for bad in (0.5, float("nan"), "two"):
        with pytest.raises(ValueError, match="smooth_along"):
            stripe_from_pair(r.on[0], r.off[0], smooth_along=bad)
    with pytest.raises(ValueError, match="smooth_along"):
        hmlvs.image.paper_session.dataset_from_images(out, smooth_along=20)


def test_dataset_from_images_reports_bad_pairs(written, tmp_path):
    r, out = written
    joints = r.session.joints
    good = [{"id": f"g{i}", "on": r.on[i], "off": r.off[i], "joints": joints[i]}
            for i in (0, 2)]
    (tmp_path / "broken.png").write_bytes(b"not a png")
    bad = [
        {"id": "nostripe", "on": r.off[0], "off": r.off[0], "joints": joints[0]},
        {"id": "noboard", "on": 80 + hmlvs.difference_image(r.on[0], r.off[0]) // 2,
         "off": np.full((480, 640), 80, np.uint8), "joints": joints[0]},
        {"id": "size", "on": r.on[0][:400], "off": r.off[0][:400], "joints": joints[0]},
        {"id": "dtype", "on": r.on[0].astype(np.float32), "off": r.off[0], "joints": joints[0]},
        {"id": "black", "on": np.zeros((480, 640), np.uint8),
         "off": np.zeros((480, 640), np.uint8), "joints": joints[0]},
        {"id": "mismatch", "on": r.on[0], "off": r.off[3], "joints": joints[0]},
        {"id": "missing", "on": str(tmp_path / "nope.png"), "off": r.off[0], "joints": joints[0]},
        {"id": "unreadable", "on": str(tmp_path / "broken.png"), "off": r.off[0],
         "joints": joints[0]},
        {"id": "joints", "on": r.on[0], "off": r.off[0], "joints": [0.1, 0.2]},
    ]
    ds, report = hmlvs.image.paper_session.dataset_from_images(good[:1] + bad + good[1:])
    by_id = {x.id: x for x in report}
    assert by_id["g0"].ok and by_id["g2"].ok
    assert set(ds.pose_index.tolist()) == {0, len(bad) + 1}
    expect = {
        "nostripe": "no laser stripe found",
        "noboard": "checkerboard: no checkerboard found",
        "size": "are 640 x 400 pixels but the session's are 640 x 480",
        "dtype": "8- or 16-bit",
        "black": "all black",
        "mismatch": "not a pair taken at the same pose",
        "missing": "does not exist",
        "unreadable": "cannot be read as an image",
        "joints": "joint readings must be 5 finite numbers",
    }
    for k, text in expect.items():
        assert not by_id[k].ok and text in by_id[k].reason, (k, by_id[k].reason)
    # the data set from the good pairs is the same as from a session of only those pairs
    ds2, _ = hmlvs.image.paper_session.dataset_from_images(good)
    np.testing.assert_allclose(ds.pixels, ds2.pixels, rtol=0, atol=0)
    with pytest.raises(ValueError, match="no image pair gave a calibration point"):
        hmlvs.image.paper_session.dataset_from_images(bad)
    with pytest.raises(ValueError, match="no such manifest"):
        hmlvs.image.paper_session.dataset_from_images(tmp_path / "nowhere")
    with pytest.raises(ValueError, match="method must be"):
        hmlvs.image.paper_session.dataset_from_images(good, method="moments")


@pytest.fixture(scope="module")
def distorted():
    """6 poses of a lens with k = 0.003 / mm^2, sensor noise."""
    q = hmlvs.Parameters.nominal().replace(k=0.003)
    s = hmlvs.simulate.session(q, num_poses=6, seed=0)
    return q, s, hmlvs.simulate.render_session(s, options=RenderOptions(noise=1.0), seed=4)


def test_pipeline_with_radial_distortion(distorted):
    """k = 0.003 / mm^2 moves the image corners by ~2.6 % (10 px): corners and stripe still
    within 0.1 px, and the homography mode takes the distortion out before mapping."""
    q, s, r = distorted
    e, _ = stripe_errors(r, "steger")
    assert rms(e) < 0.1
    records = [{"id": f"p{i:03d}", "on": r.on[i], "off": r.off[i], "joints": s.joints[i]}
               for i in range(6)]
    poses = s.robot.poses(s.joints)
    clear = [shows_block(predicted_corners(q, p, s.board), s.board) for p in poses]
    assert sum(clear) >= 2
    for mode in ("corners", "homography"):
        # the approximate parameters (nominal, k = 0) still number the corners: every view
        # showing a whole 3 x 3 block of the board is used
        ds, report = hmlvs.image.paper_session.dataset_from_images(records, mode=mode)
        assert all(x.ok for x, v in zip(report, clear) if v), [x.reason for x in report]
        exact, _ = hmlvs.models.paper.project(q, ds.points, ds.poses)
        assert rms(np.linalg.norm(ds.pixels - exact, axis=1)) < 0.1


def _view_corners(q, s, r):
    poses = s.robot.poses(s.joints)
    out = []
    for i in range(len(poses)):
        try:
            out.append((i, hmlvs.image.corners.find_corners(r.off[i], s.board,
                                              expected=predicted_corners(q, poses[i], s.board))))
        except ValueError:
            continue
    return out


def test_session_distortion_is_fitted_to_all_views(distorted):
    """One lens for the whole session: its division coefficient fitted to the corners of
    every view, recorded in the data set, and close to the true one (k Su^2 in 1/px^2)."""
    from hmlvs.image.points import fit_division_distortion

    q, s, r = distorted
    views = [c for _, c in _view_corners(q, s, r)]
    assert len(views) >= 3
    true_k = q.k * q.Su ** 2
    centre, k = fit_division_distortion(views)
    np.testing.assert_array_equal(centre, [319.5, 239.5])
    assert k == pytest.approx(true_k, rel=0.05)
    # one view alone: what calibration_points fits without a given distortion
    for c in views:
        if len(c) >= 9:
            assert fit_division_distortion([c])[1] == pytest.approx(true_k, rel=0.5)
    records = [{"id": f"p{i:03d}", "on": r.on[i], "off": r.off[i], "joints": s.joints[i]}
               for i in range(len(r.on))]
    ds, _ = hmlvs.image.paper_session.dataset_from_images(records, mode="homography")
    got = ds.meta["division_distortion"]
    assert got["centre_px"] == [319.5, 239.5] and got["k_per_px2"] == pytest.approx(k, rel=1e-9)
    ds_c, _ = hmlvs.image.paper_session.dataset_from_images(records, mode="corners")
    assert "division_distortion" not in ds_c.meta


def test_a_view_with_few_corners_is_mapped_with_the_session_distortion(distorted):
    """A view showing 8 corners (2 x 4) cannot fit the distortion alone, so without the
    session's only the squares with all four corners give points; with it, the one
    homography of the 8 corners maps the stripe in the squares around them too, as
    accurately."""
    from hmlvs.image.corner_base import Corners
    from hmlvs.image.points import fit_division_distortion

    q, s, r = distorted
    views = _view_corners(q, s, r)
    dist = fit_division_distortion([c for _, c in views])
    poses = s.robot.poses(s.joints)
    gained = blocks = 0
    for i, c in views:
        st = hmlvs.extract_stripe(hmlvs.difference_image(r.on[i], r.off[i], normalize=True))
        have = set(c.index.tolist())
        for row in range(s.board.rows - 1):
            for col in range(s.board.cols - 3):
                ids = [(row + a) * s.board.cols + col + b for a in (0, 1) for b in range(4)]
                if not have.issuperset(ids):
                    continue
                keep = np.isin(c.index, ids)
                few = Corners(c.pixels[keep], c.index[keep], c.anchor[keep], c.board, c.rule,
                              c.image_size)
                alone = hmlvs.image.points.calibration_points(st, few, mode="homography", step=4)
                shared = hmlvs.image.points.calibration_points(st, few, mode="homography", step=4,
                                                  distortion=dist)
                assert len(shared) >= len(alone)
                if len(shared) == 0:
                    continue
                blocks += 1
                gained += len(shared) - len(alone)
                rep = np.repeat(poses[i][None], len(shared), axis=0)
                exact, _ = hmlvs.models.paper.project(q, shared.points, rep)
                err = np.linalg.norm(shared.pixels - exact, axis=1)
                assert rms(err) < 0.1 and err.max() < 0.3, (i, row, col)
    assert blocks >= 3 and gained > 100  # measured: 8 blocks, 627 points gained
    assert gained > 20


def test_session_distortion_bad_input(distorted):
    from hmlvs.image.corner_base import Corners
    from hmlvs.image.points import fit_division_distortion

    q, s, r = distorted
    (_, c), *_ = _view_corners(q, s, r)
    with pytest.raises(ValueError, match="non-empty sequence"):
        fit_division_distortion([])
    with pytest.raises(ValueError, match="non-empty sequence"):
        fit_division_distortion([c.pixels])
    other = Corners(c.pixels, c.index, c.anchor, c.board, c.rule, (800, 600))
    with pytest.raises(ValueError, match="different sizes"):
        fit_division_distortion([c, other])
    st = hmlvs.extract_stripe(hmlvs.difference_image(r.on[0], r.off[0]))
    with pytest.raises(ValueError, match="distortion must be a finite"):
        hmlvs.image.points.calibration_points(st, c, mode="homography",
                                              distortion=(np.zeros(2), np.nan))
