"""The paper's studies: sensor design analysis (``design``, Figs. 4-6), the simulation study
(``study``, Table 1 and Fig. 8) and the measurement scenarios (``scenarios``, Fig. 13 and
Table 3)."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
