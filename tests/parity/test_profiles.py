"""hmlvs.Measurer.points (a grey frame's stripe and its points in one C++ call,
cpp/hmlvs/measure/profile.h; a colour frame's stripe from stripe_from_pair, then the same
kernel) against its NumPy composition (tests/oracles/reference_measurer.py: the stripe, the
sensor model's points_in_camera, the base transform): the same profile to the bit, for both
models, laser on/off pairs and laser-on frames alone, grey and colour frames, a laser plane
that some found centres' rays miss, and frames without a stripe."""

from __future__ import annotations

import dataclasses

import hmlvs
from hmlvs.measurement.measure import sensor_model
from hmlvs.measurement.measurer import PointStatus
from hmlvs.models.convert import paper_params_of
from hmlvs.sim.general import example_sensor, general_session, render_general_session
import numpy as np
import pytest
import reference_measurer as ref

pytestmark = pytest.mark.scene  # rendered images


@pytest.fixture(scope="module")
def rendered():
    s = general_session(example_sensor((640, 480)),
                        hmlvs.Checkerboard(rows=5, cols=7, square=15.0), views=2, seed=5,
                        distance=(330.0, 480.0))
    return s, render_general_session(s)


def _sensor(s, model: str, cut: bool, stripe_v: np.ndarray):
    """The session's sensor in either model; with ``cut`` a laser plane that the rays of part of
    the stripe miss (or graze): X = 100 mm in the camera for the general model (only the
    columns right of the principal point meet it), and for the paper's a plane whose horizon
    row runs through the middle of the stripe's rows ``stripe_v``."""
    if model == "opencv":
        if not cut:
            return s.sensor
        return dataclasses.replace(s.sensor, laser_plane=np.array([1.0, 0.0, 0.0, -100.0]))
    q = paper_params_of(s.sensor)
    if not cut:
        return q
    v = float(np.nanmedian(stripe_v))
    return dataclasses.replace(q, theta=float(np.arctan(q.Sv * (q.Cv - v) / q.f)))


def _colour(image: np.ndarray) -> np.ndarray:
    """A BGR frame whose red channel is the grey one (the laser's), the others dimmer."""
    return np.dstack([image // 3, image // 2, image])


def _assert_profile_is_the_oracle(got: hmlvs.measurement.measurer.Profile,
                                  want: dict[str, np.ndarray]) -> None:
    for name in ref.FIELDS:
        a = getattr(got, name)
        assert a.dtype == want[name].dtype and a.shape == want[name].shape, name
        np.testing.assert_array_equal(a, want[name], err_msg=name)  # NaN where NaN


@pytest.mark.parametrize("model", ["opencv", "paper"])
@pytest.mark.parametrize("cut", [False, True])
def test_profiles_are_their_numpy_composition(rendered, model, cut):
    s, r = rendered
    for i in range(len(s)):
        sensor = _sensor(s, model, cut, s.stripe_v[i])
        pose = s.base_from_hand[i]
        for colour, options in ((False, {}), (True, {}), (True, {"channel": 2})):
            m = hmlvs.Measurer(sensor, **options)
            on = _colour(r.on[i]) if colour else r.on[i]
            for off in (_colour(r.off[i]) if colour else r.off[i], None):
                got = m.points(on, pose, off)
                _assert_profile_is_the_oracle(
                    got, ref.profile(sensor_model(sensor), on, pose, off, **options))
                # the frames give points, and with a cut plane centres without one as well
                assert got.measured.sum() > (150 if cut else 400), (i, colour, off is None)
                no_point = int((got.status == PointStatus.NO_POINT).sum())
                assert no_point > 100 if cut else no_point == 0, (i, colour, off is None)


@pytest.mark.parametrize("model", ["opencv", "paper"])
def test_frames_without_a_stripe_are_their_numpy_composition(rendered, model):
    s, r = rendered
    sensor = _sensor(s, model, False, s.stripe_v[0])
    m = hmlvs.Measurer(sensor)
    blank = np.full(r.on[0].shape, 40, np.uint8)
    for frame in (blank, _colour(blank)):
        got = m.points(frame, s.base_from_hand[0])
        _assert_profile_is_the_oracle(
            got, ref.profile(sensor_model(sensor), frame, s.base_from_hand[0]))
        assert (got.status == PointStatus.NO_STRIPE).all()


def test_a_tilted_sensor_s_profiles_are_their_numpy_composition(rendered):
    """The Measurer keeps a tilted sensor's homography (OpenCV's taux, tauy) for its frames:
    the same points as the sensor's own mapping, which differ from the upright sensor's."""
    s, r = rendered
    tilted = dataclasses.replace(s.sensor,
                                 dist_coeffs=np.r_[s.sensor.dist_coeffs, np.zeros(7), 0.2, 0.03])
    pose = s.base_from_hand[0]
    got = hmlvs.Measurer(tilted).points(r.on[0], pose, r.off[0])
    _assert_profile_is_the_oracle(got, ref.profile(sensor_model(tilted), r.on[0], pose, r.off[0]))
    upright = hmlvs.Measurer(s.sensor).points(r.on[0], pose, r.off[0])
    both = got.measured & upright.measured
    assert both.sum() > 400
    assert np.abs(got.points[both] - upright.points[both]).max() > 1.0
