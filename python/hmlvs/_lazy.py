"""Submodules reached as attributes on first use (``hmlvs.models.paper.residuals``), so that
importing a package stays light."""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Callable


def submodules(package: str) -> Callable[[str], ModuleType]:
    """A package's module ``__getattr__``: ``package.name`` imports the submodule ``name``;
    any other missing name is an AttributeError, as usual."""

    def __getattr__(name: str) -> ModuleType:
        try:
            return importlib.import_module(f"{package}.{name}")
        except ModuleNotFoundError as e:
            if e.name != f"{package}.{name}":
                raise  # the submodule exists and one of its own imports is missing
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None

    return __getattr__
