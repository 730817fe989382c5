"""Simulation: the paper's random-pixel protocol and checkerboard sessions (``sessions``),
scene geometry (``scene``) and the renderer of laser on/off images (``render``).

``hmlvs.simulate(...)`` is :func:`sessions.simulate`; ``hmlvs.simulate.session(...)`` and
``hmlvs.simulate.render_session(...)`` hang on it as attributes."""

from .render import RenderOptions, render_pose, render_session
from .sessions import Session, Simulation, session, simulate

simulate.session = session  # type: ignore[attr-defined]
simulate.render_session = render_session  # type: ignore[attr-defined]
simulate.RenderOptions = RenderOptions  # type: ignore[attr-defined]

__all__ = ["RenderOptions", "Session", "Simulation", "render_pose", "render_session", "session",
           "simulate"]
