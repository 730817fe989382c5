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
])
def test_calibration_file_with_a_wrong_value_names_the_key(tmp_path, cal_doc, change, message):
    change(cal_doc)
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(cal_doc))
    with pytest.raises(ValueError, match=message) as e:
        Calibration.load(path)
    assert str(e.value).startswith(str(path))


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
    from hmlvs.image.session import dataset_from_images

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
    with pytest.raises(ValueError, match=r"image_size must be \[width, height\]"):
        read_manifest(tmp_path)
    from hmlvs import Dataset

    d = {"format": "hmlvs-dataset", "version": 1, "points": [
        {"id": "a", "pixel": [1, 2], "reference": [0, 0, 0],
         "base_from_hand": np.eye(4).tolist(), "pose_index": 1.7}]}
    (tmp_path / "d.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="pose_index must be a whole number, got 1.7"):
        Dataset.load(tmp_path / "d.json")
