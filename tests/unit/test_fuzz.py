"""Property-based fuzzing (Hypothesis) of every file loader and of the array entry points: any
input either works or raises a ValueError with a message; never a TypeError, KeyError,
IndexError, cv2.error or a crash, and never a silent NaN in a result that claims validity."""

from __future__ import annotations

import json

import hmlvs
from hmlvs import Calibration, Dataset, Parameters
from hmlvs.data.guess import read_bounds, read_initial
from hmlvs.data.manifest import read_manifest
from hmlvs.data.poses import read_poses
from hmlvs.data.robot_file import robot_from_dict
from hmlvs.models.opencv import OpenCvSensor
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

FUZZ = settings(max_examples=60, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

# JSON-like values: what a YAML or JSON file can hold.
scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8))
json_values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)),
    max_leaves=20)


def _mutations(doc: dict) -> st.SearchStrategy:
    """A valid document with one key replaced by an arbitrary value, or removed."""
    keys = sorted(doc)

    @st.composite
    def mutate(draw):
        d = json.loads(json.dumps(doc))
        key = draw(st.sampled_from(keys))
        if draw(st.booleans()):
            d[key] = draw(json_values)
        else:
            del d[key]
        return d

    return mutate()


def _loads_or_value_error(fn, *args) -> None:
    try:
        fn(*args)
    except ValueError as e:
        assert str(e), "a ValueError must say what is wrong"


VALID_CAL = Calibration(params=Parameters.nominal(), fixed=("Su",)).to_dict()


@FUZZ
@given(doc=st.one_of(json_values, _mutations(VALID_CAL)))
def test_calibration_loader(doc):
    _loads_or_value_error(Calibration.from_dict, doc, "cal.yaml")


@FUZZ
@given(doc=st.one_of(json_values, _mutations(VALID_CAL)))
def test_calibration_file_round_trip(tmp_path_factory, doc):
    path = tmp_path_factory.mktemp("cal") / "cal.json"
    path.write_text(json.dumps(doc))
    _loads_or_value_error(Calibration.load, path)


VALID_MANIFEST = {"format": "hmlvs-images", "version": 1, "joint_unit": "rad",
                  "board": {"rows": 6, "cols": 8, "square": 30.0},
                  "poses": [{"id": "p0", "on": "a.png", "off": "b.png",
                             "joints": [0, 0, 0, 0, 0]}]}


@FUZZ
@given(doc=st.one_of(json_values, _mutations(VALID_MANIFEST)))
def test_manifest_loader(tmp_path_factory, doc):
    folder = tmp_path_factory.mktemp("m")
    (folder / "manifest.json").write_text(json.dumps(doc))
    _loads_or_value_error(read_manifest, folder)


@FUZZ
@given(doc=json_values)
def test_robot_loader(doc):
    _loads_or_value_error(robot_from_dict, doc, "robot.yaml")


@FUZZ
@given(doc=st.one_of(json_values, _mutations(VALID_CAL["parameters"])))
def test_initial_guess_and_bounds_loaders(tmp_path_factory, doc):
    folder = tmp_path_factory.mktemp("g")
    path = folder / "g.json"
    path.write_text(json.dumps(doc))
    _loads_or_value_error(read_initial, path)
    _loads_or_value_error(read_bounds, path, Parameters.nominal())


@FUZZ
@given(doc=json_values)
def test_opencv_sensor_loader(doc):
    _loads_or_value_error(OpenCvSensor.from_dict, doc, "sensor")


@FUZZ
@given(rows=st.lists(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                                          st.text(max_size=3)), max_size=18), max_size=5),
       header=st.booleans())
def test_pose_file_loader(tmp_path_factory, rows, header):
    path = tmp_path_factory.mktemp("p") / "poses.csv"
    lines = (["x,y,z,rx,ry,rz"] if header else []) + [",".join(map(str, r)) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    _loads_or_value_error(lambda: read_poses(path, unit="m"))


VALID_POSE_FILE = {"pose_format": {"unit": "m", "quaternion_order": "xyzw"}, "poses": [
    {"id": "a", "position": [0.5, 0.0, 0.3], "quaternion": [0.0, 0.0, 0.0, 1.0]},
    {"id": "b", "position": [0.5, 0.1, 0.3], "rotation_vector": [0.0, 0.0, 1.0]}]}


@FUZZ
@given(doc=st.one_of(json_values, _mutations(VALID_POSE_FILE),
                     _mutations(VALID_POSE_FILE["poses"][0]).map(
                         lambda e: dict(VALID_POSE_FILE, poses=[e]))))
def test_yaml_pose_file_loader(tmp_path_factory, doc):
    path = tmp_path_factory.mktemp("p") / "poses.yaml"
    path.write_text(json.dumps(doc))  # JSON is YAML
    _loads_or_value_error(lambda: read_poses(path))


VALID_POINT = {"id": "a", "pixel": [300.0, 200.0], "reference": [600.0, 0.0, 0.0],
               "base_from_hand": np.eye(4).tolist(), "joints": [0.0] * 5, "pose_index": 0}


@FUZZ
@given(entry=_mutations(VALID_POINT))
def test_dataset_entry_loader(tmp_path_factory, entry):
    path = tmp_path_factory.mktemp("d") / "d.json"
    path.write_text(json.dumps({"format": "hmlvs-dataset", "version": 1,
                                "points": [VALID_POINT, entry]}))
    _loads_or_value_error(Dataset.load, path)


npz_members = st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=8).map(np.asarray),
    st.integers(0, 3).flatmap(lambda m: st.sampled_from([
        np.zeros((m, 2)), np.zeros((m, 4, 4)), np.full((m, 3), np.nan), np.arange(m),
        np.array(["x"] * m), np.zeros((m, 2), bool), np.array("{}"), np.array(json.dumps(
            {"format": "hmlvs-dataset", "version": 1, "meta": []}))])))


@FUZZ
@given(changes=st.dictionaries(st.sampled_from(["header", "pixels", "poses", "points", "ids",
                                                "joints", "pose_index"]),
                               st.one_of(st.none(), npz_members), max_size=3))
def test_npz_dataset_loader(tmp_path_factory, changes):
    folder = tmp_path_factory.mktemp("z")
    ds = hmlvs.simulate(seed=0).dataset.subset(np.arange(3))
    with np.load(ds.save(folder / "ok.npz")) as z:
        members = dict(z)
    members.update(changes)
    np.savez(folder / "d.npz", **{k: v for k, v in members.items() if v is not None})
    _loads_or_value_error(Dataset.load, folder / "d.npz")


@FUZZ
@given(doc=st.one_of(json_values, st.fixed_dictionaries({
    "format": st.just("hmlvs-dataset"), "version": st.just(1), "points": json_values})))
def test_dataset_loader(tmp_path_factory, doc):
    path = tmp_path_factory.mktemp("d") / "d.json"
    path.write_text(json.dumps(doc))
    _loads_or_value_error(Dataset.load, path)


# --- array entry points -------------------------------------------------------------------

arrays = st.one_of(
    st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), max_size=4),
             max_size=6),
    st.lists(st.floats(-1e6, 1e6), max_size=8),
    st.just([]), st.just([[]]), st.text(max_size=4))


def _array_call(fn, *args, **kwargs):
    """Works (and every point marked valid is finite) or raises a ValueError."""
    try:
        out = fn(*args, **kwargs)
    except ValueError as e:
        assert str(e)
        return
    pts, valid = out
    assert np.all(np.isfinite(np.asarray(pts)[np.asarray(valid, bool)]))


@FUZZ
@given(pixels=arrays)
def test_paper_model_points(pixels):
    p = Parameters.nominal()
    _array_call(hmlvs.models.paper.points_in_camera, p, pixels, on_invalid="mask")
    _array_call(hmlvs.models.paper.points_in_base, p, pixels, np.eye(4), on_invalid="mask")


@FUZZ
@given(pixels=arrays)
def test_opencv_model_points(pixels):
    k = np.array([[1000.0, 0, 500], [0, 1000, 400], [0, 0, 1]])
    s = OpenCvSensor(k, [-0.2, 0.05, 0, 0, 0], (1000, 800), [0, 0.9, 0.4, -100], np.eye(4))
    _array_call(s.points_in_camera, pixels, on_invalid="mask")
    try:
        pts, ok = s.points_in_base(pixels, np.eye(4), on_invalid="mask")
        assert np.all(np.isfinite(pts[ok]))
    except ValueError as e:
        assert str(e)


@FUZZ
@given(shape=st.tuples(st.integers(0, 12), st.integers(0, 12)),
       dtype=st.sampled_from([np.uint8, np.uint16, np.float32, np.float64, np.int32, bool]),
       fill=st.floats(allow_nan=True, allow_infinity=True))
def test_extract_stripe_on_any_image(shape, dtype, fill):
    with np.errstate(over="ignore"):  # a float64 beyond float32's range becomes inf: wanted
        img = np.full(shape, fill if np.dtype(dtype).kind == "f" else 0).astype(dtype)
    try:
        r = hmlvs.extract_stripe(img)
    except ValueError as e:
        assert str(e)
        return
    assert np.all(np.isfinite(r.pixels))


@pytest.mark.parametrize("bad", [np.zeros((0, 0)), np.zeros((3,)), np.zeros((2, 2, 2, 2))])
def test_extract_stripe_on_degenerate_shapes_names_the_problem(bad):
    with pytest.raises(ValueError):
        hmlvs.extract_stripe(bad)


@FUZZ
@given(board=st.one_of(json_values, _mutations({"rows": 6, "cols": 8, "square": 30.0,
                                                 "origin": [700, 90, 0]})))
def test_manifest_board_block(board):
    from hmlvs.image.views import board_of

    _loads_or_value_error(board_of, {"board": board}, None, "manifest.json")
