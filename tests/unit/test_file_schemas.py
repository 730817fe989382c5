"""Files with a value of the wrong type are refused with a sentence naming the file and the
key, never a TypeError or a silent misreading (issue: hardening)."""

from __future__ import annotations

import json

from hmlvs import Calibration, Parameters
import numpy as np
import pytest


@pytest.fixture()
def cal_doc():
    return Calibration(params=Parameters.nominal(), fixed=("Su",)).to_dict()


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(fixed=5), r"fixed: must be a list of parameter names, got 5"),
    (lambda d: d.update(fixed="Su"), r"fixed: must be a list of parameter names, got 'Su'"),
    (lambda d: d.update(fixed=["Sw"]), r"fixed\[0\]: must be one of f, Su, .*got 'Sw'"),
    (lambda d: d.update(std=[1, 2]), r"std: must be a mapping of names to standard deviations"),
    (lambda d: d.update(units="mm"), r"units: must be a mapping like \{length: mm"),
    (lambda d: d.update(version=None), r"version must be a whole number >= 1, got None"),
    (lambda d: d.update(version=1.9), r"version must be a whole number >= 1, got 1.9"),
    (lambda d: d["parameters"].update(f=True), r"parameters.f: must be a number, got True"),
    (lambda d: d["parameters"].update(f="8"), r"parameters.f: must be a number, got '8'"),
    (lambda d: d.update(num_points=2.5), r"num_points: must be a whole number"),
    (lambda d: d.update(model="pinhole"), r"model: must be one of paper, opencv"),
    (lambda d: d["hand_from_camera"][0].__setitem__(3, 99.0),
     r"hand_from_camera contradicts the calibration's parameters"),
    (lambda d: d.update(stripe_blur_var_px2="wide"),
     r"stripe_blur_var_px2: must be a blur variance in px\^2, got 'wide'"),
    (lambda d: d.update(stripe_blur_var_px2=-0.5),
     r"stripe_blur_var_px2 must lie in \[0, 4\] px\^2 .*got -0.5"),
])
def test_calibration_file_with_a_wrong_value_names_the_key(tmp_path, cal_doc, change, message):
    change(cal_doc)
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(cal_doc))
    with pytest.raises(ValueError, match=message) as e:
        Calibration.load(path)
    assert str(e.value).startswith(str(path))


def test_the_camera_blur_reads_back(tmp_path):
    """The blur an image calibration fitted is kept for measurement; files without it (data
    not from images, older files) read as None."""
    path = Calibration(params=Parameters.nominal(), blur_var=0.37).save(tmp_path / "c.yaml")
    assert Calibration.load(path).blur_var == 0.37
    plain = Calibration(params=Parameters.nominal()).save(tmp_path / "p.yaml")
    # every key is written (docs/file-formats.md), null where it does not apply
    assert "stripe_blur_var_px2: null" in plain.read_text()
    assert Calibration.load(plain).blur_var is None
    older = Calibration(params=Parameters.nominal()).to_dict()
    del older["stripe_blur_var_px2"]
    (tmp_path / "older.json").write_text(json.dumps(older))
    assert Calibration.load(tmp_path / "older.json").blur_var is None


def test_a_valid_file_with_unknown_keys_still_loads(tmp_path, cal_doc):
    cal_doc["written_by"] = "a newer hmlvs"
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(cal_doc))
    assert Calibration.load(path).fixed == ("Su",)


@pytest.mark.parametrize("board, message", [
    ({"rows": "six", "cols": 8, "square": 30}, r"board.rows: must be a whole number"),
    ({"rows": 6, "cols": 8, "square": "30"}, r"board.square: must be a size in mm"),
    ({"rows": 6, "cols": 8, "square": 30, "colour": "red"}, r"unknown key 'colour'"),
    ({"rows": 6, "cols": 8, "square": 30, "origin": [1, 2]}, r"board.origin: must be 3 "
     "numbers"),
])
def test_manifest_board_with_a_wrong_value_is_named(tmp_path, board, message):
    from hmlvs.image.paper_session import dataset_from_images

    doc = {"format": "hmlvs-images", "version": 1, "board": board,
           "poses": [{"id": "p0", "on": "a.png", "off": "b.png", "joints": [0, 0, 0, 0, 0]}]}
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message):
        dataset_from_images(tmp_path)


def test_manifest_image_size_and_data_set_pose_index_are_checked(tmp_path):
    from hmlvs.data.manifest import read_manifest

    doc = {"format": "hmlvs-images", "version": 1, "image_size": [640, 480, 3],
           "poses": [{"id": "p0", "on": "a.png", "off": "b.png", "joints": [0, 0, 0, 0, 0]}]}
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"manifest.json: image_size: must be \[width, height\] "
                       "in pixels of 2 items, got 3"):
        read_manifest(tmp_path)
    from hmlvs import Dataset

    d = {"format": "hmlvs-dataset", "version": 1, "points": [
        {"id": "a", "pixel": [1, 2], "reference": [0, 0, 0],
         "base_from_hand": np.eye(4).tolist(), "pose_index": 1.7}]}
    (tmp_path / "d.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"d.json: points\[0\]\.pose_index: must be a whole "
                       "number, got 1.7"):
        Dataset.load(tmp_path / "d.json")


# --- data sets (.json and .npz) -----------------------------------------------------------

@pytest.fixture(scope="module")
def small_dataset():
    import hmlvs

    return hmlvs.simulate(seed=0).dataset.subset(np.arange(6))


@pytest.mark.parametrize("change, message", [
    # a text where a number belongs was read as that number
    (lambda d: d["points"][3].update(pixel=[1, "2"]),
     r"points\[3\]\.pixel\[1\]: must be a number, got '2'"),
    (lambda d: d["points"][3].update(reference=[1, 2]),
     r"points\[3\]\.reference: must be the reference point \[x, y, z\] of 3 items, got 2"),
    (lambda d: d["points"][3].update(base_from_hand=[[1, 0, 0, 0]] * 3),
     r"points\[3\]\.base_from_hand: must be the 4x4 base_from_hand pose of 4 items, got 3"),
    (lambda d: d["points"][3].pop("reference"),
     r"points\[3\]: lacks reference; it must be a calibration point \{id, pixel, reference"),
    (lambda d: d["points"][0].update(id=None),
     r"points\[0\]\.id: must be an id \(a text or a whole number\), got null"),
    (lambda d: d["points"][2].update(joints=[0.1, "x"]),
     r"points\[2\]\.joints\[1\]: must be a number, got 'x'"),
    # a pose_index on some points only was dropped
    (lambda d: d["points"][4].update(pose_index=2),
     r"points\[4\] has pose_index but points\[0\] does not: give pose_index for every point"),
    (lambda d: [e.update(joints=[0.0] * (4 if i == 5 else 5)) for i, e in
                enumerate(d["points"])],
     r"points\[5\]\.joints: has 4 readings, points\[0\] has 5"),
    (lambda d: d.update(points={"a": 1}), r"points: must be a list of calibration points"),
    (lambda d: d.update(joint_unit="grad"), r"joint_unit: must be one of rad, deg, got 'grad'"),
    (lambda d: d.update(meta=[1]), r"meta: must be a mapping"),
])
def test_json_data_set_with_a_wrong_entry_names_the_entry(tmp_path, small_dataset, change,
                                                          message):
    from hmlvs import Dataset

    doc = small_dataset.to_json_dict()
    change(doc)
    path = tmp_path / "d.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message) as e:
        Dataset.load(path)
    assert str(e.value).startswith(f"{path}: ") and str(e.value).count(str(path)) == 1


def _header(**change):
    h = {"format": "hmlvs-dataset", "version": 1, "length_unit": "mm", "joint_unit": "rad",
         "meta": {}}
    h.update(change)
    return np.array(json.dumps(h))


@pytest.mark.parametrize("change, message", [
    ({"pixels": np.zeros((6, 3))},
     r"pixels: must be the stripe pixels of shape \(m, 2\), got shape \(6, 3\)"),
    # numbers stored as texts were converted silently
    ({"pixels": np.full((6, 2), "300")},
     r"pixels: must be the stripe pixels: numbers, got an array of <U3"),
    ({"points": np.full((6, 3), np.inf)},
     r"points: must be finite; the entry at \(0, 0\) is inf"),
    ({"poses": np.zeros((6, 3, 4))}, r"poses: must be the base_from_hand poses of shape "
     r"\(m, 4, 4\), got shape \(6, 3, 4\)"),
    ({"pose_index": np.full(6, 0.5)}, r"pose_index: must be the pose index of each point: "
     "whole numbers, got an array of float64"),
    ({"header": None}, r"lacks header; it must be an hmlvs data set \(.npz: header, pixels"),
    ({"ids": None}, r"lacks ids"),
    ({"header": _header(joint_unit="grad")},
     r"header\.joint_unit: must be one of rad, deg, got 'grad'"),
    ({"header": _header(meta="none")}, r"header\.meta: must be a mapping"),
    ({"header": _header(version=2)}, r"data set format version 2 is newer than this hmlvs"),
    ({"poses": np.zeros((5, 4, 4))}, r"pixels has 6 rows but poses has 5"),
])
def test_npz_data_set_with_a_wrong_array_names_the_array(tmp_path, small_dataset, change,
                                                         message):
    from hmlvs import Dataset

    with np.load(small_dataset.save(tmp_path / "ok.npz")) as z:
        arrays = dict(z)
    arrays.update(change)
    path = tmp_path / "d.npz"
    np.savez(path, **{k: v for k, v in arrays.items() if v is not None})
    with pytest.raises(ValueError, match=message) as e:
        Dataset.load(path)
    assert str(e.value).startswith(f"{path}: ") and str(e.value).count(str(path)) == 1


def test_a_valid_data_set_reads_back_in_both_forms(tmp_path, small_dataset):
    from hmlvs import Dataset

    for name in ("d.npz", "d.json"):
        back = Dataset.load(small_dataset.save(tmp_path / name))
        np.testing.assert_array_equal(back.pixels, small_dataset.pixels)
        np.testing.assert_array_equal(back.poses, small_dataset.poses)
        np.testing.assert_array_equal(back.ids, small_dataset.ids)


def _with_quality(ds):
    from dataclasses import replace

    m = len(ds)
    return replace(ds, quality={"sigma": np.linspace(0.01, 0.02, m),
                                "width": np.full(m, 4.5), "peak": np.arange(m) + 40.0,
                                "residual": np.r_[np.nan, np.full(m - 1, 0.05)]})


def test_the_stripe_quality_reads_back_and_follows_subsets(tmp_path, small_dataset):
    """Per-point stripe quality (a data set from images has it) survives both file forms
    (NaN as JSON null), a subset and a concatenation."""
    from dataclasses import replace

    from hmlvs import Dataset

    ds = _with_quality(small_dataset)
    for name in ("q.npz", "q.json"):
        back = Dataset.load(ds.save(tmp_path / name))
        assert sorted(back.quality) == sorted(ds.quality)
        for k, v in ds.quality.items():
            np.testing.assert_array_equal(back.quality[k], v)
    assert "null" in (tmp_path / "q.json").read_text()
    sub = ds.subset(ds.quality["peak"] > 42.0)
    np.testing.assert_array_equal(sub.quality["peak"], [43.0, 44.0, 45.0])
    np.testing.assert_array_equal(sub.ids, ds.ids[3:])
    other = replace(sub, ids=np.char.add(sub.ids, "b"))
    both = ds.concat(other)
    np.testing.assert_array_equal(both.quality["peak"], np.r_[ds.quality["peak"], 43, 44, 45])
    assert ds.concat(replace(other, quality=None)).quality is None  # one side without it
    assert Dataset.load(small_dataset.save(tmp_path / "plain.npz")).quality is None


@pytest.mark.parametrize("quality, message", [
    ({"width": np.ones(5)}, r"quality\['width'\] must have 6 entries \(one per point\), got "
     r"shape \(5,\)"),
    ({"snr": np.ones(6)}, r"quality has an unknown entry 'snr'; the entries are sigma, width, "
     "peak, residual"),
    ({"peak": np.r_[np.inf, np.ones(5)]}, r"quality\['peak'\] entry 0 is infinite"),
    ([1, 2], r"quality must be a dict of arrays named sigma, width, peak, residual, got list"),
])
def test_a_wrong_stripe_quality_is_named(small_dataset, quality, message):
    from dataclasses import replace

    with pytest.raises(ValueError, match=message):
        replace(small_dataset, quality=quality)


def test_a_data_set_file_with_a_wrong_quality_names_the_point(tmp_path, small_dataset):
    from hmlvs import Dataset

    doc = _with_quality(small_dataset).to_json_dict()
    doc["points"][2]["quality"].pop("peak")
    (tmp_path / "a.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"points\[2\]\.quality: has \['residual', 'sigma', "
                       r"'width'\], points\[0\] has \['peak', 'residual', 'sigma', 'width'\]"):
        Dataset.load(tmp_path / "a.json")
    doc["points"][2]["quality"]["peak"] = "high"
    (tmp_path / "b.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"points\[2\]\.quality\.peak: must be a number"):
        Dataset.load(tmp_path / "b.json")
    with np.load(_with_quality(small_dataset).save(tmp_path / "ok.npz")) as z:
        arrays = dict(z)
    arrays["quality_width"] = np.ones(4)
    np.savez(tmp_path / "c.npz", **arrays)
    with pytest.raises(ValueError, match=r"c.npz: quality\['width'\] must have 6 entries"):
        Dataset.load(tmp_path / "c.npz")
    arrays["quality_width"] = np.r_[np.ones(5), -np.inf]
    np.savez(tmp_path / "d.npz", **arrays)
    with pytest.raises(ValueError, match=r"quality_width: must be finite; the entry at 5 is "
                       "-inf"):
        Dataset.load(tmp_path / "d.npz")


# --- pose files (YAML) and manifest poses -----------------------------------------------

@pytest.mark.parametrize("text, message", [
    # numbers given as texts or booleans were read as numbers
    ("pose_format: {unit: m}\nposes:\n  - {id: a, position: ['0.5', 0, 0.3], "
     "rotation_vector: [0, 0, 1]}\n", r"poses\[0\]\.position\[0\]: must be a number, got '0.5'"),
    ("pose_format: {unit: m}\nposes:\n  - {id: a, position: [0.5, 0, 0.3], "
     "rotation_vector: [0, 0, true]}\n",
     r"poses\[0\]\.rotation_vector\[2\]: must be a number, got True"),
    ("- [500, 0, '300', 0, 0, 1]\n", r"poses\[0\]\[2\]: must be a number, got '300'"),
    # a misspelt key was ignored
    ("pose_format: {unit: m, order: xyzw}\nposes:\n  - [0.5, 0, 0.3, 0, 0, 1]\n",
     r"pose_format: unknown key 'order'; the keys are unit, quaternion_order"),
    ("pose_format: {unit: m}\nposes:\n  - {id: a, position: [0.5, 0, 0.3], rotation: [0, 0, "
     "1]}\n", r"poses\[0\]: unknown key 'rotation'; the keys are id, pose, position"),
    ("pose_format: {unit: m}\nposes:\n  - [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0.3]]\n",
     r"poses\[0\]: must be a 4x4 base_from_hand matrix of 4 items, got 3"),
    ("pose_format: {unit: m}\nposes:\n  - 5\n",
     r"poses\[0\]: must be a pose: a row of 16, 7 or 6 numbers, a 4x4 matrix, or a mapping"),
    ("pose_format: {unit: m}\nposes: []\n", r"poses: must hold at least one pose, got \[\]"),
    ("pose_format: {unit: m}\n", r"lacks poses; it must be a pose file"),
    ("pose_format: {unit: m}\nposes:\n  - {id: [1], position: [0.5, 0, 0.3], "
     "rotation_vector: [0, 0, 1]}\n", r"poses\[0\]\.id: must be an id"),
])
def test_yaml_pose_file_with_a_wrong_value_names_the_pose(tmp_path, text, message):
    from hmlvs.data.poses import read_poses

    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as e:
        read_poses(path, unit="m" if text.startswith("-") else None)
    assert str(e.value).startswith(f"{path}: ")


def test_manifest_pose_with_a_text_for_a_number_names_the_entry(tmp_path):
    from hmlvs.data.manifest import read_manifest

    doc = {"format": "hmlvs-images", "version": 1, "poses": [
        {"id": "p0", "stripe": "s.csv",
         "pose": {"position": [500, "0", 300], "rotation_vector": [0, 0, 1]}}]}
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"manifest.json: entry 0 \(id p0\): pose\.position\[1\]: "
                       "must be a number, got '0'"):
        read_manifest(tmp_path)


def test_poses_given_in_code_as_arrays_still_read():
    from hmlvs.data.poses import PoseFormat, pose_from_entry

    m = np.eye(4)
    m[:3, 3] = [500.0, 0.0, 300.0]
    np.testing.assert_array_equal(pose_from_entry(m, PoseFormat()), m)
    got = pose_from_entry({"position": np.array([500.0, 0, 300]),
                           "rotation_vector": (0, 0, np.float32(0))}, PoseFormat())
    np.testing.assert_array_equal(got, m)


# --- manifests beyond the board -----------------------------------------------------------

@pytest.mark.parametrize("change, message", [
    # joint readings written as texts were read as numbers
    (lambda d: d["poses"][0].update(joints=["0.1", 0, 0, 0, 0]),
     r"entry 0 \(id p0\): joints\[0\]: must be a number, got '0.1'"),
    (lambda d: d["poses"][0].update(joints=[]),
     r"entry 0 \(id p0\): joints: must hold at least one joint reading"),
    (lambda d: d["poses"][0].update(on=5), r"entry 0 \(id p0\): on: must be an image file name"),
    (lambda d: d["poses"][0].update(id=[1]), r"entry 0 \(id \[1\]\): id: must be an id"),
    (lambda d: d.update(image_size=[640.5, 480]),
     r"image_size\[0\]: must be a whole number of pixels, got 640.5"),
    (lambda d: d.update(image_size=[0, 480]), r"image_size\[0\]: must be >= 1, got 0"),
    (lambda d: d.update(joint_unit="grad"), r"joint_unit: must be one of rad, deg, got 'grad'"),
    (lambda d: d.update(poses={"p0": {}}), r"poses: must be a list of entries"),
    (lambda d: d.pop("poses"), r"lacks poses; it must be an image manifest"),
    (lambda d: d.update(pose_file=3), r"pose_file: must be a file name, got 3"),
])
def test_manifest_with_a_wrong_value_names_the_key(tmp_path, change, message):
    from hmlvs.data.manifest import read_manifest

    doc = {"format": "hmlvs-images", "version": 1, "joint_unit": "rad",
           "poses": [{"id": "p0", "on": "a.png", "off": "b.png", "joints": [0, 0, 0, 0, 0]}]}
    change(doc)
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message) as e:
        read_manifest(tmp_path)
    assert str(e.value).startswith(str(tmp_path / "manifest.json") + ": ")
