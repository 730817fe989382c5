"""How good can any calibration be on a Blaser session? The trade-off of the two scores.

    python examples/blaser/frontier.py SESSION START_CAL [--weights 0.5 1.5 5 50]
                                       [--pixels scorer|hmlvs]

score.py rates a calibration by stripe planarity (mm) and chain reprojection (px). Both run
through the same nominal robot poses, whose errors no calibration can remove; they pull the
camera, the laser plane and the hand-eye transform different ways. This script maps the best
pairs reachable by a calibration of the opencv model (fx, fy, cx, cy, k1 k2 p1 p2 k3, a laser
plane, hand_from_camera): for each weight w it minimises, over those and the board's pose in
the base and one free plane in the base,

    sum (corner residual px / 1 px)^2  +  w^2 sum (stripe point's distance to the plane mm)^2

fitted on the scorer's OWN measurements (its corners and its stripe pixels: an oracle no
calibration has), started from START_CAL (an hmlvs opencv calibration of the session), and
scores each result with score.py. No calibration of this model reaches a pair below the curve
this traces (up to local minima), which tells whether a target pair is reachable at all.
Not run in CI (it needs the data).
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
import tempfile

import cv2
import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hmlvs import Calibration, OpenCvSensor  # noqa: E402
import score  # noqa: E402

STRIPE_STEP = 3  # every third stripe pixel of each view (the fit's cost; enough points)


def transform(x: np.ndarray) -> np.ndarray:
    """Rotation vector (3) + translation (3) -> 4x4."""
    t = np.eye(4)
    t[:3, :3] = cv2.Rodrigues(np.asarray(x[:3], float))[0]
    t[:3, 3] = x[3:6]
    return t


def as_vector(t: np.ndarray) -> np.ndarray:
    return np.r_[cv2.Rodrigues(t[:3, :3])[0].ravel(), t[:3, 3]]


def unit(angles: np.ndarray) -> np.ndarray:
    """Spherical angles (azimuth, polar) -> unit vector."""
    a, p = angles
    return np.array([np.cos(a) * np.sin(p), np.sin(a) * np.sin(p), np.cos(p)])


def angles(n: np.ndarray) -> np.ndarray:
    return np.array([np.arctan2(n[1], n[0]), np.arccos(np.clip(n[2], -1.0, 1.0))])


class Problem:
    """The parameters (intrinsics 9, hand_from_camera 6, base_from_board 6, laser plane 3,
    stripe plane in the base 3) and the two residual groups."""

    def __init__(self, sess: score.Session, start: Calibration) -> None:
        s = start.sensor
        self.obj = sess.board.object_points()
        self.image_size = sess.image_size
        poses = {v.id: v.base_from_hand for v in sess.views}
        self.board_views = [(poses[i], c) for i, c in sess.corners.items()]
        stripes = [(poses[v.id], sess.stripes[v.id][::STRIPE_STEP]) for v in sess.views]
        self.stripes = [(p, px) for p, px in stripes if len(px)]
        hfc = np.asarray(s.hand_from_camera)
        # the board's numbering and pose in the base as the scorer's chain measure takes them
        options = [(p @ hfc @ score.camera_from_board(s, self.obj, c),
                    p @ hfc @ score.camera_from_board(s, self.obj, c[::-1]))
                   for p, c in self.board_views]
        self.flips = score.consistent_numbering(options)
        bfb = score.mean_pose([pair[k] for pair, k in zip(options, self.flips)])
        k = s.camera_matrix
        self.x0 = np.r_[k[0, 0], k[1, 1], k[0, 2], k[1, 2], s.dist_coeffs[:5], as_vector(hfc),
                        as_vector(bfb), angles(s.laser_plane[:3]), s.laser_plane[3],
                        angles(bfb[:3, 2]), -bfb[:3, 2] @ bfb[:3, 3]]

    def _project(self, bfh: np.ndarray, hfc: np.ndarray, bfb: np.ndarray, k: np.ndarray,
                 d: np.ndarray) -> np.ndarray:
        cfb = np.linalg.inv(bfh @ hfc) @ bfb
        return cv2.projectPoints(self.obj, cv2.Rodrigues(cfb[:3, :3])[0], cfb[:3, 3], k,
                                 d)[0].reshape(-1, 2)

    @staticmethod
    def unpack(x: np.ndarray) -> dict:
        k = np.array([[x[0], 0, x[2]], [0, x[1], x[3]], [0, 0, 1.0]])
        return {"k": k, "d": x[4:9], "hfc": transform(x[9:15]), "bfb": transform(x[15:21]),
                "laser": np.r_[unit(x[21:23]), x[23]], "plane": np.r_[unit(x[24:26]), x[26]]}

    def residuals(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = self.unpack(x)
        corners = [(self._project(bfh, p["hfc"], p["bfb"], p["k"], p["d"])
                    [::-1 if fl else 1] - c).ravel()
                   for (bfh, c), fl in zip(self.board_views, self.flips)]
        camera = OpenCvSensor(p["k"], p["d"], self.image_size, p["laser"], p["hfc"])
        dist = []
        for bfh, px in self.stripes:
            und, ok = camera.undistort(px)
            rays = np.c_[np.where(ok[:, None], und, 0.0), np.ones(len(px))]
            cam = rays * (-p["laser"][3] / (rays @ p["laser"][:3]))[:, None]
            m = bfh @ p["hfc"]
            dist.append((cam @ m[:3, :3].T + m[:3, 3]) @ p["plane"][:3] + p["plane"][3])
        return np.concatenate(corners), np.concatenate(dist)

    def calibration(self, x: np.ndarray, start: Calibration) -> Calibration:
        p, d = self.unpack(x), start.to_dict()
        d["sensor"].update(camera_matrix=p["k"].tolist(), dist_coeffs=p["d"].tolist(),
                           laser_plane=p["laser"].tolist(), hand_from_camera=p["hfc"].tolist(),
                           base_from_board=p["bfb"].tolist())
        d["hand_from_camera"] = p["hfc"].tolist()
        return Calibration.from_dict(d)


def hmlvs_stripes(session: Path, like: dict[str, np.ndarray], start: Calibration
                  ) -> dict[str, np.ndarray]:
    """The stripe pixels hmlvs' own pipeline finds in each view of the session (an empty
    array where it finds none), keyed as the scorer's, less those its calibration's robust
    step would drop: mapped by START to the base, beyond 5 robust sigmas from their plane
    (the fit here is plain least squares, which a few stray pixels would pull)."""
    from hmlvs.image.views import views_from_images

    views = views_from_images(session / "manifest.yaml")[0]
    own = {v.id: np.asarray(v.laser_pixels, float).reshape(-1, 2) for v in views}
    poses = {v.id: v.base_from_hand for v in views}
    pts = {k: start.sensor.points_in_base(px, np.repeat(poses[k][None], len(px), 0),
                                          on_invalid="mask")[0] for k, px in own.items()}
    every = np.concatenate([p for p in pts.values() if len(p)])
    every = every[np.isfinite(every).all(axis=1)]
    centre = every.mean(axis=0)
    normal = np.linalg.svd(every - centre)[2][2]
    dist = {k: np.abs((p - centre) @ normal) for k, p in pts.items()}
    d_all = np.concatenate(list(dist.values()))
    d_all = d_all[np.isfinite(d_all)]
    limit = 5 * 1.4826 * np.median(np.abs(d_all - np.median(d_all)))
    return {k: own[k][dist[k] <= limit] if k in own else np.empty((0, 2)) for k in like}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("session", type=Path)
    ap.add_argument("start", type=Path, help="an hmlvs opencv calibration of the session")
    ap.add_argument("--weights", type=float, nargs="+", default=[0.5, 1.5, 5.0, 50.0])
    ap.add_argument("--cache-dir", type=Path, default=score.default_cache_dir())
    ap.add_argument("--pixels", choices=("scorer", "hmlvs"), default="scorer",
                    help="the stripe pixels fitted: the scorer's own (the oracle) or those "
                    "hmlvs' pipeline finds (views_from_images); scored on the scorer's and, "
                    "with hmlvs, on those too")
    ap.add_argument("--hmlvs-column", action="store_true",
                    help="also score every fit on hmlvs' pixels (with --pixels scorer)")
    a = ap.parse_args(argv)
    sess = score.load_session(a.session, a.cache_dir)
    start = Calibration.load(a.start)
    scorer_px = sess.stripes
    own_px = hmlvs_stripes(a.session, scorer_px, start) \
        if a.pixels == "hmlvs" or a.hmlvs_column else None
    sess.stripes = own_px if a.pixels == "hmlvs" else scorer_px  # the pixels fitted
    prob = Problem(sess, start)

    def scores(path: Path) -> str:
        """planarity on the scorer's pixels, chain (and planarity on hmlvs' pixels)"""
        sess.stripes = scorer_px
        s = score.score(path, "", sess)
        out = f"{s.planarity.rms_mm:.3f} | {s.chain.rms_px:.2f} | "
        if own_px is not None:
            sess.stripes = own_px
            out += f"{score.score(path, '', sess).planarity.rms_mm:.3f} | "
        return out

    extra = ("planarity on hmlvs' pixels (mm) | ", "---|") if own_px is not None else ("", "")
    print(f"| weight (1/mm) | planarity (mm) | chain (px) | {extra[0]}fx | fy |")
    print(f"|---|---|---|{extra[1]}---|---|")
    s0 = start.sensor
    print(f"| START | {scores(a.start)}{s0.fx:.1f} | {s0.fy:.1f} |", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for w in a.weights:
            def weighted(x: np.ndarray, w: float = w) -> np.ndarray:
                corners, dist = prob.residuals(x)
                return np.r_[corners, w * dist]

            sol = least_squares(weighted, prob.x0, x_scale="jac", max_nfev=200)
            path = Path(tmp) / f"w{w}.yaml"
            prob.calibration(sol.x, start).save(path)
            print(f"| {w:g} | {scores(path)}{sol.x[0]:.1f} | {sol.x[1]:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
