"""Parameter identification: the solvers facade (PSO, LM, random search) and its results."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
