"""The image pipeline: laser on/off images -> stripe centres (``stripe``), board corners
(``corners``), calibration points (``points``) and whole sessions (``session``).

It never imports the renderer (``hmlvs.sim``): it works on any images."""

from .._lazy import submodules

__getattr__ = submodules(__name__)
