"""The independent renderer's session cache (``HMLVS_TEST_RENDER_CACHE``, set by make test so
that the suite's second pass reads the sessions its first pass drew): a session asked for
again comes from the cache, the same files and truth as rendered; other arguments render
anew."""

import independent_render as R
import numpy as np
import pytest


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_a_cached_session_is_the_rendered_one(tmp_path, monkeypatch):
    fresh = R.render_session(tmp_path / "fresh", seed=4, views=1, held_out=1)
    monkeypatch.setenv("HMLVS_TEST_RENDER_CACHE", str(tmp_path / "cache"))
    (tmp_path / "cache").mkdir()
    first = R.render_session(tmp_path / "a", seed=4, views=1, held_out=1)
    assert len(list((tmp_path / "cache").iterdir())) == 1

    def no_render(*args, **kwargs):
        raise AssertionError("rendered again")

    monkeypatch.setattr(R, "_render_session", no_render)
    again = R.render_session(tmp_path / "b", seed=4, views=1, held_out=1)
    assert _files(tmp_path / "fresh") == _files(tmp_path / "a") == _files(tmp_path / "b")
    for truth in (first, again):
        assert truth.keys() == fresh.keys() and truth["views"] == fresh["views"] == 1
        for k in ("params", "poses", "centres", "ids"):
            np.testing.assert_array_equal(truth[k], fresh[k])
    with pytest.raises(AssertionError, match="rendered again"):
        R.render_session(tmp_path / "c", seed=4, views=1, held_out=1, speckle=0.0)


def test_the_rays_kept_on_disk_are_the_computed_ones(tmp_path):
    """hmlvs' renderer's camera rays, kept on disk for one make test (conftest): computed
    once per camera, then read back bit for bit by another process's wrapper."""
    from conftest import plain_pixel_rays, rays_kept_on_disk
    from hmlvs.sim.general import example_sensor

    calls = []

    def compute(sensor, supersample=1):
        calls.append(supersample)
        return plain_pixel_rays()(sensor, supersample)

    sensor = example_sensor((160, 120))
    first = rays_kept_on_disk(compute, str(tmp_path))(sensor, 3)
    again = rays_kept_on_disk(compute, str(tmp_path))(sensor, 3)  # a fresh process's
    assert calls == [3] and len(list(tmp_path.glob("rays-*.npy"))) == 1
    np.testing.assert_array_equal(again, first)
    other = rays_kept_on_disk(compute, str(tmp_path))(sensor, 1)  # another camera's
    assert calls == [3, 1] and other.shape == (120, 160, 3)
    np.testing.assert_array_equal(other, plain_pixel_rays()(sensor, 1))
