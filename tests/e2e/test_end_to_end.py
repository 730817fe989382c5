"""Issue 6's end-to-end criterion: from rendered images + joint readings to a calibration.

"Perfect pixel extraction with the same noise" is read as: the same calibration points, their
exact pixels (the truth's projection) plus Gaussian noise of the pipeline's own measured pixel
RMS per axis. Both calibrations are judged on the same held-out poses with exact pixels.
"""

import hmlvs
from hmlvs.image.corners import predicted_corners
import numpy as np
import pytest
from scene_checks import shows_block

pytestmark = pytest.mark.scene  # simulated sessions or rendered images


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("session")
    session = hmlvs.simulate.session(num_poses=24, seed=11)
    hmlvs.simulate.render_session(session, out)
    return session, out


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::hmlvs.HmlvsDataWarning")
@pytest.mark.parametrize("mode", [
    "corners", pytest.param("homography", marks=pytest.mark.one_kernel)])
def test_calibration_from_images_matches_perfect_extraction(rendered, mode):
    session, folder = rendered
    ds, reports = hmlvs.image.paper_session.dataset_from_images(folder, mode=mode)
    # every view showing a whole 3 x 3 block of the board is used; partial boards without
    # one are rejected, with a reason
    poses = session.robot.poses(session.joints)
    clear = [shows_block(predicted_corners(session.truth, p, session.board), session.board)
             for p in poses]
    assert sum(clear) >= 12
    assert all(r.ok for r, v in zip(reports, clear) if v)
    assert all(r.reason for r in reports if not r.ok)
    exact, ok = hmlvs.models.paper.project(session.truth, ds.points, ds.poses)
    assert ok.all()
    sigma = np.sqrt(np.mean((ds.pixels - exact) ** 2, axis=0))
    assert sigma.max() < 0.1  # sub-pixel extraction on rendered images (px)
    perfect = hmlvs.Dataset(exact, ds.poses, ds.points, ids=ds.ids, pose_index=ds.pose_index)
    # One split and a few noise draws give a ratio that scatters 0.5-1.5 from split to split
    # (measured on two sessions: 0.54-1.17 per split with a 10-draw baseline). The criterion
    # is on the mean over three splits, each against a baseline averaged over six draws.
    # the solves alone are compared here (judge=False: no verdict, which re-calibrates halves)
    ratios = []
    for split in (1, 2, 3):
        fit, _ = ds.split(0.5, seed=split, by_pose=True)
        in_fit = np.isin(ds.pose_index, np.unique(fit.pose_index))
        test = perfect.subset(~in_fit)
        from_images = hmlvs.calibrate(fit, test=test, seed=0, judge=False)
        pf = perfect.subset(in_fit)
        baseline = []
        for k in range(6):  # the noise of the baseline is random: average six draws
            noisy = hmlvs.Dataset(pf.pixels + np.random.default_rng(k).normal(0, sigma,
                                                                              (len(pf), 2)),
                                  pf.poses, pf.points)
            baseline.append(hmlvs.calibrate(noisy, test=test, seed=0, judge=False).test_rms)
        ratios.append(from_images.test_rms / np.mean(baseline))
    assert np.mean(ratios) <= 1.5 and max(ratios) <= 2.0, ratios
