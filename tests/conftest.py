import hashlib
import os
from pathlib import Path

from hmlvs.models.params import TABLE2_LOWER, TABLE2_UPPER
import numpy as np
import pytest


def rays_kept_on_disk(compute, folder: str):
    """``compute`` (:func:`hmlvs.sim.general.pixel_rays`) with its rays kept in ``folder``
    (one ``.npy`` per camera, written whole) and the last camera's in memory."""
    import hmlvs.sim.general as general

    last: dict[str, np.ndarray] = {}

    def pixel_rays(sensor, supersample: int = 1) -> np.ndarray:
        w, h = sensor.image_size
        key = hashlib.sha256(np.asarray(sensor.camera_matrix, float).tobytes()
                             + np.asarray(sensor.dist_coeffs, float).tobytes()
                             + f"{w}x{h}x{int(supersample)}".encode()).hexdigest()[:24]
        if key in last:
            return last[key]
        path = Path(folder) / f"rays-{key}.npy"
        try:
            rays = np.load(path)
            general._RAYS.clear()  # one camera's rays in memory, as pixel_rays keeps them
        except (OSError, ValueError):
            rays = compute(sensor, supersample)
            tmp = Path(folder) / f"rays-{key}.{os.getpid()}.part"
            with open(tmp, "wb") as fh:
                np.save(fh, rays)
            os.replace(tmp, path)  # whole, or not at all, for the other worker
        last.clear()
        last[key] = rays
        return rays

    return pixel_rays


def _rays_kept_on_disk() -> None:
    """With ``HMLVS_TEST_RENDER_CACHE`` naming a folder (make test: one folder for its two
    passes), the camera rays of hmlvs' renderer (:func:`hmlvs.sim.general.pixel_rays`, a pure
    function of the camera: 3 s for a 1024 x 768 one at 3 x supersampling, kept in memory
    for the last camera only) are kept there too (:func:`rays_kept_on_disk`), so that each
    camera's are computed once in a run instead of 15 times for 6 cameras (measured on the
    main pass). Loaded, they are the computed ones bit for bit (``np.save``)."""
    folder = os.environ.get("HMLVS_TEST_RENDER_CACHE")
    if folder:
        import hmlvs.sim.general as general

        general.pixel_rays = rays_kept_on_disk(plain_pixel_rays(), folder)


def plain_pixel_rays():
    """hmlvs' own :func:`~hmlvs.sim.general.pixel_rays`, without the disk cache."""
    import hmlvs.sim.general as general

    return _PLAIN_RAYS.setdefault("f", general.pixel_rays)


_PLAIN_RAYS: dict = {}


_rays_kept_on_disk()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def random_params(rng: np.random.Generator) -> np.ndarray:
    """Parameters drawn inside the Table 2 bounds, with theta kept away from 0 so rays hit."""
    q = rng.uniform(TABLE2_LOWER, TABLE2_UPPER)
    q[7] = rng.uniform(0.3, 0.7)
    q[5] = rng.uniform(0.0, 0.02)
    return q


@pytest.fixture(scope="session")
def cli_files(tmp_path_factory):
    """A folder with a simulated data set, its calibration and a rendered 3-view image
    session, for the command-line fault tests: (folder, data set, calibration, session)."""
    import hmlvs
    from hmlvs.cli import main
    from hmlvs.sim.general import general_session, render_general_session

    d = tmp_path_factory.mktemp("cli")
    ds = hmlvs.simulate.session(num_poses=8, seed=1).dataset.save(d / "sim.npz")
    cal = d / "cal.yaml"
    with pytest.raises(SystemExit):
        main(["calibrate", str(ds), "--method", "lm", "--out", str(cal), "-q"])
    sess = d / "sess"
    render_general_session(general_session(views=3, seed=2), sess)
    return d, ds, cal, sess


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    """Run the command line in-process: (exit code, stdout, stderr)."""
    from hmlvs.cli import main

    with pytest.raises(SystemExit) as e:
        main(argv)
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


@pytest.fixture(scope="session")
def clean():
    """8 poses of the paper's set-up rendered without sensor noise (the image tests' clean
    session)."""
    import hmlvs

    return hmlvs.simulate.render_session(num_poses=8, seed=0)


def tree_digest(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (relative name -> sha256), links as their target's name."""
    out = {}
    for p in sorted(folder.rglob("*")):
        key = str(p.relative_to(folder))
        if p.is_symlink():
            out[key] = "link:" + os.readlink(p)
        elif p.is_file():
            out[key] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[key] = "folder"
    return out


def stripe_errors(session, sensor) -> np.ndarray:
    """Every view's whole true stripe of a rendered general session (on the board and off
    it) mapped through ``sensor`` against its true points (mm)."""
    errs = []
    for i in range(len(session)):
        v = session.stripe_v[i]
        ok = np.isfinite(v)
        px = np.c_[np.flatnonzero(ok).astype(float), v[ok]]
        poses = np.repeat(session.base_from_hand[i][None], len(px), 0)
        want, a = session.sensor.points_in_base(px, poses, on_invalid="mask")
        got, b = sensor.points_in_base(px, poses, on_invalid="mask")
        errs.append(np.linalg.norm(got[a & b] - want[a & b], axis=1))
    return np.concatenate(errs)


def assert_lens_matches_opencv(sensor, span: float, seed: int) -> None:
    """A general sensor's projection and undistortion against OpenCV's own
    (``cv2.projectPoints``, ``cv2.undistortPoints``) for points up to ``span`` times their
    depth off the axis and pixels over the whole image."""
    import cv2

    k, dist = sensor.camera_matrix, sensor.dist_coeffs
    w, h = sensor.image_size
    rng = np.random.default_rng(seed)
    pts = np.c_[rng.uniform(-span, span, (400, 2)) * 400, np.full(400, 400.0)]
    ours, valid = sensor.project(pts)
    ref = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k, dist)[0][:, 0]
    assert valid.all() and np.abs(ours - ref).max() < 1e-9
    # pixels -> normalised points: OpenCV's iteration to its own tolerance; ours is exact
    px = np.c_[rng.uniform(0, w - 1, 300), rng.uniform(0, h - 1, 300)]
    und, ok = sensor.undistort(px)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(px.reshape(-1, 1, 2), k, dist, None, None, None, crit)[:, 0]
    assert ok.all() and np.abs(und - ref).max() < 1e-7
    back = cv2.projectPoints(np.c_[und, np.ones(len(und))], np.zeros(3), np.zeros(3), k,
                             dist)[0][:, 0]
    assert np.abs(back - px).max() < 1e-9
