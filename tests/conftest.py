import hashlib
import os
from pathlib import Path

from hmlvs.models.params import TABLE2_LOWER, TABLE2_UPPER
import numpy as np
import pytest


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
