"""Simulation: the paper's random-pixel protocol and checkerboard sessions (``sessions``),
scene geometry (``scene``), the renderer of laser on/off images (``render``) and the general
sensor's sessions and images without a robot model (``general``).

``hmlvs.simulate(...)`` is :func:`sessions.simulate`; ``hmlvs.simulate.session(...)`` and
``hmlvs.simulate.render_session(...)`` hang on it as attributes."""

from .general import (
    GeneralSession,
    RenderedGeneralSession,
    example_sensor,
    general_session,
    render_general_session,
)
from .render import RenderOptions, render_pose, render_session
from .sessions import Session, Simulation, session, simulate

simulate.session = session  # type: ignore[attr-defined]
simulate.render_session = render_session  # type: ignore[attr-defined]
simulate.RenderOptions = RenderOptions  # type: ignore[attr-defined]
simulate.general_session = general_session  # type: ignore[attr-defined]
simulate.render_general_session = render_general_session  # type: ignore[attr-defined]

__all__ = ["GeneralSession", "RenderOptions", "RenderedGeneralSession", "Session", "Simulation",
           "example_sensor", "general_session", "render_general_session", "render_pose",
           "render_session", "session", "simulate"]
