"""Every bad input raises a ValueError that names the problem."""

import hmlvs
import numpy as np
import pytest
import reference_model as ref

Q = hmlvs.Parameters.nominal()


def poses(n):
    return np.tile(np.eye(4), (n, 1, 1))


@pytest.mark.parametrize(
    "pixels, pose_arr, match",
    [
        (np.zeros((3, 3)), poses(3), r"pixels must have shape \(m, 2\)"),
        (np.zeros((3, 2)), poses(2), "pixels has 3 rows but poses has 2"),
        (np.zeros((2, 2)), np.zeros((2, 3, 4)), r"poses must have shape \(m, 4, 4\)"),
        (np.array([[1.0, np.nan], [2, 3]]), poses(2), "pixels row 0 is not finite"),
    ],
)
def test_shapes_and_nan(pixels, pose_arr, match):
    with pytest.raises(ValueError, match=match):
        hmlvs.models.paper.points_in_base(Q, pixels, pose_arr)


def test_pose_that_is_not_rigid():
    p = poses(3)
    p[2, 0, 0] = 2.0
    with pytest.raises(ValueError, match="pose 2 has a rotation part that is not a proper"):
        hmlvs.models.paper.points_in_base(Q, np.full((3, 2), 300.0), p)
    p = poses(2)
    p[1, 3, 3] = 0.5
    with pytest.raises(ValueError, match="pose 1 is not a homogeneous transform"):
        hmlvs.models.paper.points_in_base(Q, np.full((2, 2), 300.0), p)


def test_pixel_whose_ray_misses_the_laser_plane():
    q = Q.replace(theta=0.01)  # f tan(theta) = 0.08 mm: rows far above Cv miss the plane
    pixels = np.array([[320.0, 300.0], [320.0, 10.0]])
    with pytest.raises(ValueError, match=r"pixel 1 \(u=320, v=10\) has a ray that misses the "
                                         r"laser plane"):
        hmlvs.models.paper.points_in_base(q, pixels, poses(2))
    pts, valid = hmlvs.models.paper.points_in_base(q, pixels, poses(2), on_invalid="mask")
    assert valid.tolist() == [True, False] and np.isnan(pts[1]).all()
    with pytest.raises(ValueError, match="misses the laser plane"):
        hmlvs.models.paper.residuals(q, pixels, poses(2), np.zeros((2, 3)))
    assert hmlvs.models.paper.objective(q, pixels, poses(2), np.zeros((2, 3))) == np.inf


@pytest.mark.parametrize(
    "changes, match",
    [({"f": -1.0}, "f must be > 0"), ({"H": 0.0}, "H must be > 0"),
     ({"theta": 2.0}, r"theta must lie in \(-pi/2, pi/2\)")],
)
def test_bad_parameters(changes, match):
    with pytest.raises(ValueError, match=match):
        hmlvs.models.paper.points_in_base(Q.replace(**changes), np.full((1, 2), 300.0), poses(1))


def test_parameters_type():
    with pytest.raises(ValueError, match="parameter k is not finite"):
        Q.replace(k=float("nan"))
    with pytest.raises(ValueError, match="'fx' is not a parameter"):
        Q.replace(fx=1.0)
    with pytest.raises(ValueError, match="14 values"):
        hmlvs.Parameters.from_array(np.zeros(13))
    with pytest.raises(ValueError, match="bounds of Cu: lower 5 > upper 1"):
        lo, hi = hmlvs.Bounds.table2().lower.copy(), hmlvs.Bounds.table2().upper.copy()
        lo[3], hi[3] = 5, 1
        hmlvs.Bounds(lo, hi)


def test_dataset_validation(rng):
    px = rng.uniform(0, 400, (4, 2))
    pts = rng.uniform(-100, 100, (4, 3))
    with pytest.raises(ValueError, match="pixels has 4 rows but poses has 3"):
        hmlvs.Dataset(px, poses(3), pts)
    bad = pts.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="reference points row 2 is not finite"):
        hmlvs.Dataset(px, poses(4), bad)
    with pytest.raises(ValueError, match="ids must be unique"):
        hmlvs.Dataset(px, poses(4), pts, ids=["a", "b", "a", "c"])
    with pytest.raises(ValueError, match="look like degrees"):
        hmlvs.Dataset(px, poses(4), pts, joints=np.full((4, 5), 90.0))
    p = ref.random_poses(rng, 4)
    with pytest.raises(ValueError, match="do not share a length unit"):
        hmlvs.Dataset(px, p, p[:, :3, 3] / 1000.0 + 1e-4)


def test_malformed_files(tmp_path):
    f = tmp_path / "bad.json"
    f.write_text("{not json")
    with pytest.raises(ValueError, match="bad.json: malformed data set file"):
        hmlvs.Dataset.load(f)
    f.write_text('{"format": "something-else"}')
    with pytest.raises(ValueError, match="not an hmlvs data set"):
        hmlvs.Dataset.load(f)
    f.write_text('{"format": "hmlvs-dataset", "version": 1, "points": [{"id": "a"}]}')
    with pytest.raises(ValueError, match=r"bad.json: points\[0\]: lacks pixel, reference, "
                       "base_from_hand; it must be a calibration point"):
        hmlvs.Dataset.load(f)
    with pytest.raises(ValueError, match="no such data set file"):
        hmlvs.Dataset.load(tmp_path / "missing.npz")
    with pytest.raises(ValueError, match="saved as .npz or .json"):
        hmlvs.simulate(seed=0).dataset.save(tmp_path / "x.txt")
