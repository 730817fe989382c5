"""The example that turns a public capture folder (frameNNNN.png + poseNNNN.txt, ROS tf's
one-line pose) into an hmlvs session: frames paired with poses by number, the authors'
discards (a leading underscore) and frames without a pose left out, bad pose files refused
before anything is written."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from hmlvs.data.manifest import write_png
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]


def _example(name: str):
    path = ROOT / "examples" / name / "make_session.py"
    spec = importlib.util.spec_from_file_location(f"example_{name}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


POSE = "((1.36, 0.03, 1.48), (0.018, 0.664, -0.003, 0.748))"


def _capture(folder: Path) -> None:
    folder.mkdir()
    for name in ("frame0001.png", "frame0002.png", "_frame0003.png", "frame0004.png"):
        write_png(folder / name, np.full((8, 10), 7, np.uint8))
    for n in ("0001", "0003", "0004"):
        (folder / f"pose{n}.txt").write_text(POSE + "\n")
    (folder / "_pose0004.txt").write_text("not a pose")


def test_frames_pair_with_poses_by_number(tmp_path, capsys):
    etna = _example("etna")
    _capture(tmp_path / "calib")
    assert etna.main([str(tmp_path / "calib"), str(tmp_path / "out")]) == 0
    assert "frame0002.png: no pose file, left out" in capsys.readouterr().out
    doc = yaml.safe_load((tmp_path / "out" / "manifest.yaml").read_text())
    assert [e["id"] for e in doc["poses"]] == ["frame0001", "frame0004"]
    assert doc["poses"][1]["pose"] == {"position": [1.36, 0.03, 1.48],
                                       "quaternion": [0.018, 0.664, -0.003, 0.748]}
    assert doc["pose_format"] == {"unit": "m", "quaternion_order": "xyzw"}
    assert sorted(p.name for p in (tmp_path / "out" / "images").iterdir()) == \
        ["frame0001.png", "frame0004.png"]


def test_a_bad_pose_file_writes_nothing(tmp_path, capsys):
    etna = _example("etna")
    _capture(tmp_path / "calib")
    (tmp_path / "calib" / "pose0004.txt").write_text("((1, 2), (3,))")
    assert etna.main([str(tmp_path / "calib"), str(tmp_path / "out")]) == 2
    assert "pose0004.txt" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_bench_checkout_becomes_a_session_without_poses(tmp_path, capsys):
    """The hand-held-board example: every N_right.jpg frame in number order (10 after 2),
    the board, and no pose at all (a bench session); a folder that is not empty is refused
    and left as it was."""
    import cv2

    light = _example("light_stripe")
    (tmp_path / "co" / "images").mkdir(parents=True)
    for n in (10, 2, 1):
        cv2.imwrite(str(tmp_path / "co" / "images" / f"{n}_right.jpg"),
                    np.full((8, 10, 3), 90, np.uint8))
    assert light.main([str(tmp_path / "co"), str(tmp_path / "out")]) == 0
    doc = yaml.safe_load((tmp_path / "out" / "manifest.yaml").read_text())
    assert [e["id"] for e in doc["poses"]] == ["1_right", "2_right", "10_right"]
    assert all(set(e) == {"id", "on"} for e in doc["poses"])
    assert doc["board"] == {"type": "checkerboard", "rows": 6, "cols": 8, "square": 40.0}
    assert (tmp_path / "out" / "images" / "10_right.jpg").is_file()
    keep = tmp_path / "full"
    keep.mkdir()
    (keep / "mine.txt").write_text("mine")
    assert light.main([str(tmp_path / "co"), str(keep)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert [p.name for p in keep.iterdir()] == ["mine.txt"]
