"""Robot poses from controller files (CSV/YAML) and in manifests: forms, units, bad input."""

import json
import math

from hmlvs.data.manifest import read_manifest
from hmlvs.data.poses import read_poses, rotation_from_vector, write_poses
from hmlvs.image.scan import stripes_from_images
import numpy as np
import pytest


def _rigid(rng, n):
    """n random base_from_hand poses (mm) from independent random rotation vectors."""
    out = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        rv = rng.normal(size=3)
        rv *= rng.uniform(0.1, 3.0) / np.linalg.norm(rv)
        out[i, :3, :3] = rotation_from_vector(rv)
        out[i, :3, 3] = rng.uniform([200, -400, 100], [800, 400, 700])
    return out


def _hand_rodrigues(rv):
    """Rodrigues written out element by element (independent of the module's version)."""
    th = math.sqrt(sum(v * v for v in rv))
    x, y, z = (v / th for v in rv)
    c, s, C = math.cos(th), math.sin(th), 1 - math.cos(th)
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])


@pytest.mark.parametrize("suffix", [".csv", ".yaml"])
@pytest.mark.parametrize("rotation, order", [("matrix", "xyzw"), ("quaternion", "xyzw"),
                                             ("quaternion", "wxyz"), ("rotation_vector", "xyzw")])
@pytest.mark.parametrize("unit", ["mm", "m"])
@pytest.mark.parametrize("with_ids", [True, False])
def test_round_trip(tmp_path, rng, suffix, rotation, order, unit, with_ids):
    poses = _rigid(rng, 7)
    ids = [f"p{i:03d}" for i in range(7)] if with_ids else None
    path = write_poses(tmp_path / f"poses{suffix}", poses, ids, rotation=rotation,
                       quaternion_order=order, unit=unit)
    got_ids, got = read_poses(path, unit=unit,
                              quaternion_order=order if rotation == "quaternion" else None)
    assert got_ids == ids
    np.testing.assert_allclose(got, poses, atol=1e-9)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files left


def test_ur_style_file_metres_and_rotation_vectors(tmp_path):
    """x, y, z in m and rx, ry, rz (rad) as a UR controller exports them -> mm transforms."""
    rows = [
        (0.5, 0.1, 0.3, 0.0, 0.0, math.pi / 2),         # 90 deg about z
        (-0.2, 0.45, 0.6, *(2 * math.pi / 3 / math.sqrt(3),) * 3),  # 120 deg about (1,1,1)
        (0.25, -0.35, 0.15, math.pi, 0.0, 0.0),         # 180 deg about x
        (0.404, -0.101, 0.222, 1.2, -2.1, 0.7),         # general
    ]
    text = "x,y,z,rx,ry,rz\n" + "\n".join(",".join(repr(v) for v in r) for r in rows) + "\n"
    (tmp_path / "ur.csv").write_text(text)
    ids, poses = read_poses(tmp_path / "ur.csv", unit="m")
    assert ids is None and poses.shape == (4, 4, 4)
    expected_r = [np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]),
                  np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]]),  # x -> y -> z -> x
                  np.diag([1.0, -1.0, -1.0]),
                  _hand_rodrigues((1.2, -2.1, 0.7))]
    for k, r in enumerate(rows):
        np.testing.assert_allclose(poses[k, :3, :3], expected_r[k], atol=1e-12)
        np.testing.assert_allclose(poses[k, :3, 3], np.array(r[:3]) * 1000.0, atol=1e-9)
        np.testing.assert_array_equal(poses[k, 3], [0, 0, 0, 1])
    # the same numbers claimed to be mm are refused: a hand 0.6 mm from the base is metres
    with pytest.raises(ValueError, match="look like metres; name unit 'm'"):
        read_poses(tmp_path / "ur.csv", unit="mm")


def test_quaternion_order_is_the_named_one(tmp_path):
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)   # 60 deg about z
    rz60 = np.array([[0.5, -c, 0], [c, 0.5, 0], [0, 0, 1]])
    (tmp_path / "xyzw.csv").write_text(f"x,y,z,qx,qy,qz,qw\n100,200,300,0,0,{s!r},{c!r}\n")
    (tmp_path / "wxyz.csv").write_text(f"100,200,300,{c!r},0,0,{s!r}\n")
    _, a = read_poses(tmp_path / "xyzw.csv", unit="mm", quaternion_order="xyzw")
    _, b = read_poses(tmp_path / "wxyz.csv", unit="mm", quaternion_order="wxyz")
    np.testing.assert_allclose(a[0, :3, :3], rz60, atol=1e-12)
    np.testing.assert_allclose(b[0], a[0], atol=1e-12)
    # the same numbers read in the other order are another rotation (hence: never guessed)
    (tmp_path / "bare.csv").write_text(f"100,200,300,0,0,{s!r},{c!r}\n")
    _, wrong = read_poses(tmp_path / "bare.csv", unit="mm", quaternion_order="wxyz")
    assert np.abs(wrong[0, :3, :3] - rz60).max() > 0.5
    # a header naming the quaternion's columns must agree with the order given
    with pytest.raises(ValueError, match="the header orders the quaternion qx,qy,qz,qw but "
                       "quaternion_order wxyz was given"):
        read_poses(tmp_path / "xyzw.csv", unit="mm", quaternion_order="wxyz")
    # a quaternion off by rounding is normalised
    (tmp_path / "r.csv").write_text(f"0,0,900,0,0,{s * 1.001!r},{c * 1.001!r}\n")
    _, r = read_poses(tmp_path / "r.csv", unit="mm", quaternion_order="xyzw")
    np.testing.assert_allclose(r[0, :3, :3], rz60, atol=1e-12)


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "name, text, kwargs, match",
    [
        ("a.csv", "1,2,3,4,5\n", {"unit": "mm"}, r"a.csv has 5 numbers per row; a pose row has"),
        ("a.csv", "x,y,z,rx,ry,rz\n500,0,300,0,0,1\n500,0,300,0,0\n", {"unit": "mm"},
         r"a.csv: line 3 has 5 columns, the file's rows have 6"),
        ("a.csv", "500,0,300,0,nan,1\n", {"unit": "mm"},
         r"a.csv: line 1 has a value that is not finite \(NaN or inf\)"),
        ("a.csv", "500,0,300,0,,1\n", {"unit": "mm"}, r"a.csv: line 1: '' is not a number"),
        ("a.csv", "500,0,300,0,0,0.3,0.8\n", {"unit": "mm", "quaternion_order": "xyzw"},
         r"a.csv: line 1: the quaternion \[0.0, 0.0, 0.3, 0.8\] \(xyzw\) has norm 0.8544, not 1"),
        ("a.csv", "500,0,300,0,0,0,1\n", {"unit": "mm"},
         r"a.csv: line 1: the pose has a quaternion but its order is not named"),
        ("a.csv", "500,0,300,0,0,0,1\n", {"unit": "mm", "quaternion_order": "ijkw"},
         r"a.csv: unknown quaternion order 'ijkw'"),
        ("a.csv", "500,0,300,0,0,1\n", {"unit": "cm"}, r"a.csv: unknown length unit 'cm'"),
        ("a.csv", "500,0,300,0,0,1\n", {}, r"a.csv: the length unit of the positions is not "
         "named"),
        ("a.csv", "500,0,300,0,0,1\n", {"unit": "mm", "rotation": "quaternion"},
         r"a.csv has 6 numbers per row, but a pose in quaternion form has 7"),
        ("a.csv", "1,0,0,500,0,2,0,0,0,0,1,300,0,0,0,1\n", {"unit": "mm"},
         r"a.csv: line 1: the rotation part is not a rotation matrix"),
        ("a.csv", "id,x,y,z,rx,ry,rz\np1,500,0,300,0,0,1\np1,500,0,300,0,0,1\n", {"unit": "mm"},
         r"a.csv: pose 1 repeats the id 'p1' of pose 0"),
        ("a.csv", "x,y,z,rx,ry,rz\n", {"unit": "mm"}, r"a.csv: the pose file holds a header but "
         "no poses"),
        ("a.csv", "x,y,z,qw,qx,qy,qz\n500,0,300,1,0,0,0\n",
         {"unit": "mm", "quaternion_order": "xyzw"}, r"a.csv: line 1: the header orders the "
         "quaternion qw,qx,qy,qz but quaternion_order xyzw was given"),
        ("a.yaml", "- [500, 0, 300, 0, 0, 1]\n", {}, r"a.yaml: the length unit of the positions"),
        ("a.yaml", "pose_format: {unit: m, quaternion_order: xyzw}\nposes:\n"
         "  - {id: a, position: [0.5, 0, 0.3], quaternion: [0, 0, 0, 2]}\n", {},
         r"a.yaml: pose 0 \(id a\): the quaternion .* has norm 2, not 1"),
        ("a.yaml", "pose_format: {unit: m}\nposes:\n  - {position: [0.5, 0, 0.3]}\n", {},
         r"a.yaml: pose 0: a pose mapping is \{position"),
        ("a.yaml", "pose_format: {unit: m}\nposes: [[0.5, 0, 0.3, 0, 0, 1]]\n", {"unit": "mm"},
         r"a.yaml: the file's pose_format says unit 'm' but 'mm' was given"),
    ],
)
def test_bad_pose_files_name_the_file_and_the_problem(tmp_path, name, text, kwargs, match):
    path = _write(tmp_path, name, text)
    with pytest.raises(ValueError, match=match):
        read_poses(path, **kwargs)


def test_missing_pose_file(tmp_path):
    with pytest.raises(ValueError, match="nope.csv: no such pose file"):
        read_poses(tmp_path / "nope.csv", unit="mm")


# ------------------------------------------------------------------------------------------
# manifests


def _stripe_manifest(tmp_path, entries, **top):
    """A measurement manifest whose entries give stripe lists (no images needed)."""
    (tmp_path / "s.csv").write_text("u,v\n300,200\n310,210\n")
    doc = {"format": "hmlvs-images", "version": 1, **top,
           "poses": [{"id": f"p{i}", "stripe": "s.csv", **e} for i, e in enumerate(entries)]}
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    return tmp_path / "manifest.json"


def test_manifest_pose_mappings_with_pose_format(tmp_path, rng):
    poses = _rigid(rng, 3)
    from hmlvs.data.poses import rotation_to_quaternion, rotation_to_vector

    q = rotation_to_quaternion(poses[0, :3, :3], "wxyz").tolist()
    rv = rotation_to_vector(poses[1, :3, :3]).tolist()
    m = poses[2].copy()
    m[:3, 3] /= 1000.0
    entries = [{"pose": {"position": (poses[0, :3, 3] / 1000).tolist(), "quaternion": q}},
               {"pose": {"position": (poses[1, :3, 3] / 1000).tolist(), "rotation_vector": rv}},
               {"pose": m.tolist()}]
    path = _stripe_manifest(tmp_path, entries,
                            pose_format={"unit": "m", "quaternion_order": "wxyz"})
    ids, stripes, got, reports = stripes_from_images(path)
    assert ids == ["p0", "p1", "p2"] and all(r.ok for r in reports)
    np.testing.assert_allclose(got, poses, atol=1e-9)
    # a quaternion without a named order is refused, naming the entry
    path = _stripe_manifest(tmp_path, entries, pose_format={"unit": "m"})
    with pytest.raises(ValueError, match=r"manifest.json: entry 0 \(id p0\): the pose has a "
                       "quaternion but its order is not named"):
        read_manifest(path)
    path = _stripe_manifest(tmp_path, entries, pose_format={"unit": "inch"})
    with pytest.raises(ValueError, match="manifest.json: pose_format: unknown length unit"):
        read_manifest(path)


def test_manifest_pose_file_by_id_and_by_order(tmp_path, rng):
    poses = _rigid(rng, 4)
    ids = ["p0", "p1", "p2", "p3"]
    order = [2, 0, 3, 1]  # the file lists the poses in another order; ids pair them
    write_poses(tmp_path / "poses.csv", poses[order], [ids[i] for i in order],
                rotation="rotation_vector", unit="m")
    path = _stripe_manifest(tmp_path, [{}] * 4, pose_file="poses.csv", pose_format={"unit": "m"})
    entries, _, _ = read_manifest(path)
    np.testing.assert_allclose(np.array([e["pose"] for e in entries]), poses, atol=1e-9)
    _, _, got, _ = stripes_from_images(path)
    np.testing.assert_allclose(got, poses, atol=1e-9)
    # without an id column: row order, and the counts must match
    write_poses(tmp_path / "poses.csv", poses, rotation="quaternion", quaternion_order="xyzw")
    path = _stripe_manifest(tmp_path, [{}] * 4, pose_file="poses.csv",
                            pose_format={"quaternion_order": "xyzw"})
    np.testing.assert_allclose(stripes_from_images(path)[2], poses, atol=1e-9)
    path = _stripe_manifest(tmp_path, [{}] * 5, pose_file="poses.csv",
                            pose_format={"quaternion_order": "xyzw"})
    with pytest.raises(ValueError, match="poses.csv has 4 poses but the manifest has 5 entries"):
        read_manifest(path)


@pytest.mark.parametrize(
    "file_ids, entries, match",
    [(["p0", "p1", "px"], [{}] * 3, r"the pose_file poses.csv has no pose for the id\(s\) p2"),
     (["p0", "p1", "p2", "p9"], [{}] * 3, r"has poses for id\(s\) no entry has: p9"),
     (["p0", "p1", "p2"], [{}, {"joints": [0, 0, 0, 0, 0]}, {}],
      r"entry 1 \(id p1\) has 'joints' but the manifest gives every pose in its pose_file")],
)
def test_manifest_pose_file_mismatch(tmp_path, rng, file_ids, entries, match):
    write_poses(tmp_path / "poses.csv", _rigid(rng, len(file_ids)), file_ids,
                rotation="matrix")
    path = _stripe_manifest(tmp_path, entries, pose_file="poses.csv")
    with pytest.raises(ValueError, match=match):
        read_manifest(path)


def test_manifest_pose_file_missing(tmp_path):
    path = _stripe_manifest(tmp_path, [{}], pose_file="gone.csv")
    with pytest.raises(ValueError, match="manifest.json: the pose_file .*gone.csv does not exist"):
        read_manifest(path)


def test_the_documented_ur_example_reads(tmp_path):
    """docs/file-formats.md's UR-style pose file and manifest, as written there."""
    import pathlib
    import re

    doc = (pathlib.Path(__file__).parents[2] / "docs" / "file-formats.md").read_text()
    csv = re.search(r"```text\n# poses.csv\n(.*?)```", doc, re.S).group(1)
    manifest = re.search(r"```yaml\n# manifest.yaml\n(.*?)```", doc, re.S).group(1)
    (tmp_path / "poses.csv").write_text(csv)
    (tmp_path / "manifest.yaml").write_text(manifest)
    entries, _, _ = read_manifest(tmp_path / "manifest.yaml")
    assert [e["id"] for e in entries] == ["p000", "p001"]
    assert (entries[1]["on"], entries[1]["off"]) == ("p001_on.png", "p001_off.png")  # not bools
    p0 = entries[0]["pose"]
    np.testing.assert_allclose(p0[:3, 3], [412.0, -110.5, 355.0])
    # rotation vector pi/sqrt(2) (1, -1, 0): half a turn about (1, -1, 0), the flange down
    np.testing.assert_allclose(p0[:3, :3], [[0, -1, 0], [-1, 0, 0], [0, 0, -1]], atol=1e-4)


def test_a_matrix_printed_with_few_decimals_becomes_an_exact_rotation(tmp_path):
    import hmlvs

    r = rotation_from_vector([0.3, -1.1, 0.4])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, [512.25, -33.5, 401.0]
    text = ",".join(f"{v:.5f}" for v in m.ravel()) + "\n"   # |R^T R - I| ~ 1e-5
    (tmp_path / "m.csv").write_text(text)
    _, poses = read_poses(tmp_path / "m.csv", unit="mm")
    assert np.abs(poses[0, :3, :3].T @ poses[0, :3, :3] - np.eye(3)).max() < 1e-12
    np.testing.assert_allclose(poses[0], m, atol=2e-5)
    hmlvs.models.paper.validate_poses(poses)  # the C++ core's check (1e-6) passes too


def test_records_in_code_take_pose_mappings_in_mm(tmp_path):
    """Records passed as a list (no manifest): a rotation-vector mapping in mm works, a
    quaternion (no order can be named) rejects only its record."""
    (tmp_path / "s.csv").write_text("300,200\n")
    stripe = str(tmp_path / "s.csv")
    recs = [{"id": "a", "stripe": stripe,
             "pose": {"position": [500, 0, 300], "rotation_vector": [0, 0, math.pi / 2]}},
            {"id": "b", "stripe": stripe,
             "pose": {"position": [500, 0, 300], "quaternion": [0, 0, 0, 1]}}]
    ids, _, poses, reports = stripes_from_images(recs)
    assert ids == ["a"] and not reports[1].ok
    assert "its order is not named" in reports[1].reason
    np.testing.assert_allclose(poses[0, :3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
