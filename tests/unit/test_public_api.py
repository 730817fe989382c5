"""The public API: a small set of names at the top of hmlvs, each documented and typed; the
rest reached through its subpackage."""

from __future__ import annotations

import inspect

import hmlvs
import pytest

#: the most names the top level may hold (issue 37: "about 25")
MOST = 26


def test_the_top_level_is_small_and_every_name_resolves():
    names = [n for n in hmlvs.__all__ if n != "__version__"]
    assert len(names) <= MOST - 1, names
    for n in names:
        assert getattr(hmlvs, n) is not None, n
    # the paper's studies are not re-exported: they live under hmlvs.paper
    for n in ("study", "design", "scenarios"):
        assert n not in hmlvs.__all__


def test_every_public_name_is_documented_and_its_arguments_typed():
    for n in hmlvs.__all__:
        if n == "__version__":
            continue
        v = getattr(hmlvs, n)
        assert (v.__doc__ or "").strip(), f"{n} has no docstring"
        if inspect.isclass(v):
            continue
        sig = inspect.signature(v)
        assert sig.return_annotation is not inspect.Signature.empty, f"{n}: no return type"
        for p in sig.parameters.values():
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                continue
            assert p.annotation not in (inspect.Parameter.empty, "Any"), f"{n}({p.name}) untyped"


def test_subpackages_load_their_modules_on_first_use():
    assert hmlvs.models.paper.residuals.__module__ == "hmlvs.models.paper"
    assert issubclass(hmlvs.errors.FlatDirectionWarning, hmlvs.HmlvsDataWarning)
    assert callable(hmlvs.paper.study.study) and callable(hmlvs.paper.design.analyze)
    with pytest.raises(AttributeError, match="no attribute 'no_such_module'"):
        _ = hmlvs.models.no_such_module

