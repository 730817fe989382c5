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
