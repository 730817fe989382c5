"""Rendered laser-on / laser-off images of a checkerboard session, with known truth.

Every pixel is ray-traced through the sensor model of docs/model.md: the pixel's (distorted)
position gives an undistorted camera ray (:func:`hmlvs.models.paper.rays_in_camera`), the ray
meets
the board plane (the board lies on a table in that plane), the point's albedo comes from the
checkerboard pattern and the laser adds a Gaussian of the pixel's distance to the
laser-plane / board intersection curve. Pixels are supersampled for anti-aliasing, then
blurred (optics), given sensor noise and rounded to 8 bits.

``hmlvs.simulate.render_session(...)`` renders a whole simulated session
(:func:`hmlvs.simulate.session`) and writes the images plus a JSON manifest of joint readings;
:func:`hmlvs.image.paper_session.dataset_from_images` reads that back.

Board layout: inner corner (r, c) is at board coordinates (x, y) = (r, c) * square. The
squares between inner corners, extended by one square on every side, form the pattern; the
square with ``floor(x / square) + floor(y / square)`` even is black (so the four outer
corner squares are black for the paper's 6 x 8 inner corners). A white border of
``RenderOptions.margin`` squares surrounds the pattern; beyond it is the table.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import _core
from .._arrays import as_params
from ..data.manifest import write_image_manifest
from ..geometry.board import Checkerboard
from ..models.paper import hand_from_camera, rays_in_camera
from .scene import TINY, Scene, Table

if TYPE_CHECKING:  # pragma: no cover
    from .sessions import Session



@dataclass(frozen=True)
class RenderOptions:
    """How images are rendered. Intensities are 8-bit grey levels.

    Attributes
    ----------
    supersample : samples per pixel along each axis (anti-aliasing), odd so that one sample
        sits at the pixel centre
    stripe_sigma : standard deviation (px) of the laser stripe's Gaussian profile across the
        stripe, before blur
    blur_sigma : optics blur (px), applied to both frames; 0 for none
    laser : laser intensity on a white (albedo 1) surface at the stripe centre
    ambient : ambient light on a white surface (both frames)
    white, black, table : albedos of the white and black squares and of the table
    margin : white border around the pattern, in squares
    noise : standard deviation of Gaussian sensor noise, independent in each frame
    glare : a saturating specular highlight of ambient light (both frames) centred on the
        stripe at ``glare_at`` (fraction of the image width), radius ``glare_radius`` px
    spurious : relative intensity of a laser reflection: a second copy of the stripe offset
        by ``spurious_offset`` px over the columns ``spurious_columns`` (fractions of the
        width); 0 for none
    speckle : relative standard deviation of laser speckle, a multiplicative log-normal
        pattern (mean 1) of grains ``speckle_grain`` px (Gaussian sigma) on the laser light
        only; 0 for none
    vignetting : relative loss of light at the image corners, both frames: the exposure is
        multiplied by 1 - vignetting * (r / r_corner)^2, r the distance from the image
        centre; 0 for none
    """

    supersample: int = 3
    stripe_sigma: float = 1.2
    blur_sigma: float = 0.5
    laser: float = 140.0
    ambient: float = 130.0
    white: float = 0.85
    black: float = 0.25
    table: float = 0.45
    margin: float = 1.0
    noise: float = 0.0
    glare: bool = False
    glare_at: float = 0.3
    glare_radius: float = 25.0
    spurious: float = 0.0
    spurious_offset: float = 20.0
    spurious_columns: tuple[float, float] = (0.6, 0.8)
    speckle: float = 0.0
    speckle_grain: float = 1.0
    vignetting: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.supersample, (int, np.integer)) and self.supersample >= 1
                and self.supersample % 2 == 1):
            raise ValueError(f"supersample must be an odd integer >= 1, got {self.supersample}")
        for name in ("stripe_sigma",):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("blur_sigma", "laser", "ambient", "noise", "spurious", "margin",
                     "glare_radius", "speckle", "speckle_grain"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")
        if not 0 <= self.vignetting < 1:
            raise ValueError(f"vignetting must lie in [0, 1), got {self.vignetting}")
        for name in ("white", "black", "table"):
            v = getattr(self, name)
            if not 0 <= v <= 1:
                raise ValueError(f"albedo {name} must lie in [0, 1], got {v}")


@dataclass(frozen=True)
class RenderedPose:
    """One rendered pose: the two frames and the true stripe centre per column."""

    on: np.ndarray       # (h, w) uint8, laser on
    off: np.ndarray      # (h, w) uint8, laser off
    stripe_v: np.ndarray  # (w,) true sub-pixel row of the stripe centre in each column, NaN
    #                       where the stripe is not in the image


@dataclass(frozen=True)
class RenderedSession:
    """A rendered session: images, true stripe centres and the simulated session behind them.

    ``stripe_v[i, u]`` is the true centre row of the stripe in column u of pose i (NaN where
    the stripe does not cross that column). ``manifest`` is the written manifest's path, if
    the session was written to a folder.
    """

    session: "Session"
    options: RenderOptions
    ids: list[str]
    on: list[np.ndarray]
    off: list[np.ndarray]
    stripe_v: np.ndarray
    manifest: Path | None = None
    files: dict[str, Any] = field(default_factory=dict)


_RAY_CACHE: dict[tuple, np.ndarray] = {}


def _sample_pixels(image_size: tuple[int, int], s: int) -> np.ndarray:
    """The supersample positions (h*s * w*s, 2), s x s in each pixel, row by row."""
    w, h = image_size
    off = (np.arange(s) + 0.5) / s - 0.5
    us = (np.arange(w)[:, None] + off[None, :]).ravel()
    vs = (np.arange(h)[:, None] + off[None, :]).ravel()
    uu, vv = np.meshgrid(us, vs)
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def _sample_rays(q: np.ndarray, image_size: tuple[int, int], s: int) -> np.ndarray:
    """Camera rays (h*s, w*s, 3) of the supersample positions, cached for the last call."""
    key = (tuple(q.tolist()), tuple(image_size), s)
    if key not in _RAY_CACHE:
        w, h = image_size
        rays = rays_in_camera(q, _sample_pixels(image_size, s))
        _RAY_CACHE.clear()
        _RAY_CACHE[key] = rays.reshape(h * s, w * s, 3)
    return _RAY_CACHE[key]


_RAY_JACOBIAN_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def _sample_ray_jacobian(q: np.ndarray, image_size: tuple[int, int], s: int
                         ) -> tuple[np.ndarray, np.ndarray]:
    """d ray / du and d ray / dv (each (h*s, w*s, 3), camera frame, per pixel) at the
    supersample positions of :func:`_sample_rays`, by central differences of the model's
    own rays (:func:`hmlvs.models.paper.rays_in_camera`); cached for the last call."""
    key = (tuple(q.tolist()), tuple(image_size), s)
    if key not in _RAY_JACOBIAN_CACHE:
        w, h = image_size
        px = _sample_pixels(image_size, s)
        eps = 1e-3
        out = []
        for step in ([eps, 0.0], [0.0, eps]):
            d = (rays_in_camera(q, px + step) - rays_in_camera(q, px - step)) / (2 * eps)
            out.append(d.reshape(h * s, w * s, 3))
        _RAY_JACOBIAN_CACHE.clear()
        _RAY_JACOBIAN_CACHE[key] = (out[0], out[1])
    return _RAY_JACOBIAN_CACHE[key]


def _board_from_camera(q: np.ndarray, pose: np.ndarray, board: Checkerboard) -> np.ndarray:
    base_from_camera = np.asarray(pose, float) @ hand_from_camera(q)
    return np.linalg.inv(board.base_from_board()) @ base_from_camera


def _laser_distance(q: np.ndarray, cam: np.ndarray) -> np.ndarray:
    """Signed distance (mm) of camera-frame points from the laser plane y + z tan(theta) = H."""
    th, hh = q[7], q[6]
    return (cam[..., 1] + cam[..., 2] * np.tan(th) - hh) * np.cos(th)


def _laser_plane(q: np.ndarray) -> np.ndarray:
    """The laser plane y + z tan(theta) = H as (a, b, c, d): a x + b y + c z + d is the signed
    distance (mm) of :func:`_laser_distance`."""
    th, hh = q[7], q[6]
    return np.array([0.0, np.cos(th), np.tan(th) * np.cos(th), -hh * np.cos(th)])


def _true_stripe_rows(q: np.ndarray, pose: np.ndarray, board: Checkerboard,
                      image_size: tuple[int, int], d_centres: np.ndarray) -> np.ndarray:
    """Row v per column u where the laser-plane distance on the board plane is zero.

    ``d_centres`` (h, w) holds the distance at pixel centres (NaN where the ray misses the
    plane); its sign changes bracket the root, then Newton steps on exact rays refine it.
    """
    w, h = image_size
    bfc = _board_from_camera(q, pose, board)
    out = np.full(w, np.nan)
    d = d_centres
    sign_change = (np.sign(d[:-1]) * np.sign(d[1:]) <= 0) & np.isfinite(d[:-1]) & \
        np.isfinite(d[1:])
    cols = np.nonzero(sign_change.any(axis=0))[0]
    if cols.size == 0:
        return out
    rows = np.argmax(sign_change[:, cols], axis=0)
    d0, d1 = d[rows, cols], d[rows + 1, cols]
    v = rows + np.where(d0 != d1, d0 / (d0 - d1), 0.5)

    def dist(vv: np.ndarray) -> np.ndarray:
        rays = rays_in_camera(q, np.stack([cols.astype(float), vv], axis=1))
        rb = rays @ bfc[:3, :3].T
        t = -bfc[2, 3] / rb[:, 2]
        return _laser_distance(q, rays * t[:, None])

    for _ in range(4):
        f = dist(v)
        g = (dist(v + 1e-3) - dist(v - 1e-3)) / 2e-3
        v = v - f / g
    out[cols] = v
    return out


def board_exposures(rays: np.ndarray, bfc: np.ndarray, board: Checkerboard, o: RenderOptions,
                     plane: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ambient and laser exposure (h, w) of the board plane, and the laser-plane distance
    (mm) at the pixel centres (NaN where a ray misses the plane).

    ``rays`` (h*s, w*s, 3) are the camera rays of the supersample positions (s =
    ``o.supersample``, the centre sample of each pixel at its integer position), ``bfc`` the
    4x4 board_from_camera transform and ``plane`` (4,) the laser plane in the camera frame:
    ``plane[:3] . p + plane[3]`` is a camera point's signed distance (mm) from it. The sensor
    model enters only through these two, so any camera model renders with the same shading.

    The C++ core shades (``ShadeBoard``): every edge of the print smoothed over +-1.5
    samples, so that the s x s samples integrate the pixel's area without the aliasing that
    makes point-sampled squares bias corner positions by ~0.1 px, and the stripe a Gaussian
    of the sample's distance in pixels from the plane's trace on the board.
    """
    shading = _core._BoardShading()
    shading.supersample = int(o.supersample)
    shading.rows, shading.cols, shading.square = int(board.rows), int(board.cols), board.square
    for name in ("margin", "white", "black", "table", "ambient", "laser", "stripe_sigma",
                 "spurious", "spurious_offset"):
        setattr(shading, name, float(getattr(o, name)))
    shading.spurious_lo, shading.spurious_hi = (float(c) for c in o.spurious_columns)
    return _core._shade_board(rays, np.asarray(bfc, float), np.asarray(plane, float), shading)


def _add_glare(ambient: np.ndarray, stripe_v: np.ndarray, o: RenderOptions) -> np.ndarray:
    """The ambient exposure with ``o.glare``'s highlight centred on the stripe (if on)."""
    if not o.glare:
        return ambient
    h, w = ambient.shape
    u0 = o.glare_at * (w - 1)
    v0 = np.interp(u0, np.arange(w)[np.isfinite(stripe_v)],
                   stripe_v[np.isfinite(stripe_v)]) if np.isfinite(stripe_v).any() else h / 2
    vv, uu = np.mgrid[0:h, 0:w]
    return ambient + 400.0 * np.exp(-0.5 * ((uu - u0) ** 2 + (vv - v0) ** 2)
                                    / o.glare_radius ** 2)


def render_pose(params: Any, pose: np.ndarray, board: Checkerboard | None = None,
                image_size: tuple[int, int] = (640, 480), options: RenderOptions | None = None,
                rng: np.random.Generator | None = None) -> RenderedPose:
    """Render the laser-on and laser-off images seen at one base_from_hand pose.

    Parameters
    ----------
    params : true sensor parameters (:class:`hmlvs.Parameters` or 14-vector)
    pose : (4, 4) base_from_hand transform
    board : the checkerboard (default: the paper's)
    image_size : (width, height) in pixels
    options : :class:`RenderOptions`
    rng : random generator for the sensor noise (default: seeded with 0)
    """
    q = as_params(params)
    board = Checkerboard() if board is None else board
    o = RenderOptions() if options is None else options
    rng = np.random.default_rng(0) if rng is None else rng
    w, h = (int(image_size[0]), int(image_size[1]))
    if w < 8 or h < 8:
        raise ValueError(f"image_size must be at least 8 x 8 pixels, got {image_size}")
    rays = _sample_rays(q, (w, h), o.supersample)
    bfc = _board_from_camera(q, pose, board)
    ambient, laser, d_centres = board_exposures(rays, bfc, board, o, _laser_plane(q))
    stripe_v = _true_stripe_rows(q, pose, board, (w, h), d_centres)
    ambient = _add_glare(ambient, stripe_v, o)
    on, off = finish_frames(ambient, laser, o, rng)
    return RenderedPose(on, off, stripe_v)


def finish_frames(ambient: np.ndarray, laser: np.ndarray, o: RenderOptions,
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Exposure (h, w) of the ambient light and of the laser -> the 8-bit laser-on and
    laser-off frames: laser speckle, optics blur, independent sensor noise per frame,
    rounding (saturating at 255)."""
    import cv2
    if o.speckle > 0:
        grain = rng.normal(0.0, 1.0, laser.shape)
        if o.speckle_grain > 0:
            grain = cv2.GaussianBlur(grain, (0, 0), o.speckle_grain,
                                     borderType=cv2.BORDER_REFLECT)
            grain /= max(float(grain.std()), 1e-12)
        laser = laser * np.exp(o.speckle * grain - 0.5 * o.speckle ** 2)
    if o.vignetting > 0:
        h, w = ambient.shape
        vv, uu = np.mgrid[0:h, 0:w]
        r2 = ((uu - 0.5 * (w - 1)) ** 2 + (vv - 0.5 * (h - 1)) ** 2) / (0.25 * ((w - 1) ** 2
                                                                            + (h - 1) ** 2))
        fall = 1.0 - o.vignetting * r2
        ambient, laser = ambient * fall, laser * fall
    frames = []
    for img in (ambient + laser, ambient):
        if o.blur_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), o.blur_sigma, borderType=cv2.BORDER_REFLECT)
        if o.noise > 0:
            img = img + rng.normal(0.0, o.noise, img.shape)
        frames.append(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    return frames[0], frames[1]


def render_session(session: "Session | None" = None, out_dir: str | os.PathLike | None = None,
                   *, options: RenderOptions | None = None, seed: int = 0,
                   progress: Any = None, **session_kwargs: Any) -> RenderedSession:
    """Render laser-on / laser-off images of a simulated session, optionally writing them.

    Parameters
    ----------
    session : a :func:`hmlvs.simulate.session`; default: one made with ``seed`` and
        ``session_kwargs`` (e.g. ``num_poses=8``, ``params=...``)
    out_dir : folder to write ``pNNN_on.png``, ``pNNN_off.png``, ``manifest.json`` (pose ids,
        image files, joint readings in rad, image size, robot and board) and ``truth.npz``
        (true parameters and per-column stripe centres ``stripe_v``). Every file is written
        atomically. None: nothing is written.
    options : :class:`RenderOptions` (stripe width, blur, noise, glare, spurious peak, ...)
    seed : seeds the session (if made here) and the sensor noise
    progress : optional callable (done, total) called after each rendered pose

    Returns
    -------
    RenderedSession

    Examples
    --------
    >>> r = hmlvs.simulate.render_session(num_poses=4, seed=1, out_dir="session1")
    >>> ds, report = hmlvs.image.paper_session.dataset_from_images("session1")
    """
    from .sessions import session as make_session
    if session is None:
        session = make_session(seed=seed, **session_kwargs)
    elif session_kwargs:
        raise ValueError(f"session_kwargs {sorted(session_kwargs)} apply only when no "
                         "session is given")
    o = RenderOptions() if options is None else options
    rng = np.random.default_rng([seed, 7])
    poses = session.robot.poses(session.joints)
    ids = [f"p{i:03d}" for i in range(len(poses))]
    on, off, sv = [], [], []
    for k, pose in enumerate(poses):
        r = render_pose(session.truth, pose, session.board, session.image_size, o, rng)
        if progress is not None:
            progress(k + 1, len(poses))
        on.append(r.on)
        off.append(r.off)
        sv.append(r.stripe_v)
    stripe_v = np.array(sv)
    manifest = None
    files: dict[str, Any] = {}
    if out_dir is not None:
        out = Path(out_dir)

        def truth(fh: Any) -> None:
            np.savez_compressed(fh, params=session.truth.to_array(), stripe_v=stripe_v,
                                joints=session.joints, ids=np.array(ids))

        manifest = write_image_manifest(
            out, ids, on, off, session.joints, session.image_size, session.robot.name,
            files={"truth.npz": truth}, board=session.board.to_dict(),
            render_options=asdict(o))
        files = {"manifest": manifest, "truth": out / "truth.npz"}
    return RenderedSession(session, o, ids, on, off, stripe_v, manifest, files)





# ------------------------------------------------------------------------------------------
# Rendering


@dataclass(frozen=True)
class RenderedScene:
    """One rendered pose of a scene.

    ``surface[v, u]`` is the index of the primitive seen at the pixel's centre (-1: none);
    ``lit[v, u]`` whether the laser reaches the point seen there (not in laser shadow).
    """

    on: np.ndarray
    off: np.ndarray
    surface: np.ndarray
    lit: np.ndarray


def laser_origin(params: Any, pose: np.ndarray) -> np.ndarray:
    """The laser projector's position in the base frame: the point ``(0, H, 0)`` of the
    camera frame, on the laser plane's baseline."""
    q = as_params(params)
    bfc = np.asarray(pose, float) @ hand_from_camera(q)
    return bfc[:3, :3] @ np.array([0.0, q[6], 0.0]) + bfc[:3, 3]


def render_scene(params: Any, pose: np.ndarray, scene: Scene,
                 image_size: tuple[int, int] = (640, 480),
                 options: RenderOptions | None = None,
                 rng: np.random.Generator | None = None,
                 laser_shadows: bool = True) -> RenderedScene:
    """Render the laser-on and laser-off images of a scene at one base_from_hand pose.

    Parameters
    ----------
    params : the true sensor parameters (:class:`hmlvs.Parameters` or 14-vector)
    pose : (4, 4) base_from_hand transform
    scene : the :class:`Scene`
    image_size : (width, height) px
    options : :class:`hmlvs.simulate.RenderOptions` (supersample, stripe_sigma, blur_sigma,
        laser, ambient, noise are used)
    rng : random generator for the sensor noise (default: seeded with 0)
    laser_shadows : test every stripe point's segment to the projector for occlusion
    """
    q = as_params(params)
    o = RenderOptions() if options is None else options
    rng = np.random.default_rng(0) if rng is None else rng
    w, h = int(image_size[0]), int(image_size[1])
    if w < 8 or h < 8:
        raise ValueError(f"image_size must be at least 8 x 8 pixels, got {image_size}")
    s = o.supersample
    bfc = np.asarray(pose, float) @ hand_from_camera(q)
    th = q[7]
    r = _SceneRenderer(q, o, scene, s, w, _sample_rays(q, (w, h), s),
                       *_sample_ray_jacobian(q, (w, h), s), bfc[:3, :3], bfc[:3, 3],
                       laser_origin(q, pose), np.asarray(scene.light),
                       np.array([0.0, np.cos(th), np.sin(th)]), laser_shadows)
    ambient = np.empty((h, w))
    laser = np.empty((h, w))
    surface = np.empty((h, w), np.int64)
    lit_map = np.zeros((h, w), bool)
    chunk = 8  # pixel rows per block: small blocks keep the temporaries in the cache
    for r0 in range(0, h, chunk):
        r1 = min(h, r0 + chunk)
        shape = ((r1 - r0) * s, w * s)
        amb, lz, which, lit = r.block(r0, r1)
        rows = r1 - r0
        ambient[r0:r1] = amb.reshape(shape).reshape(rows, s, w, s).mean(axis=(1, 3))
        laser[r0:r1] = lz.reshape(shape).reshape(rows, s, w, s).mean(axis=(1, 3))
        surface[r0:r1] = which.reshape(shape)[s // 2::s, s // 2::s]
        lit_map[r0:r1] = lit.reshape(shape)[s // 2::s, s // 2::s]
    on, off = finish_frames(ambient, laser, o, rng)
    return RenderedScene(on, off, surface, lit_map)


#: only samples this close to the laser plane (mm) get the pixel distance; a surface seen
#: at more than _NEAR_MM / cut mm per px (grazing) loses the profile's far tails
_NEAR_MM = 12.0


@dataclass
class _SceneRenderer:
    """One view of :func:`render_scene`, rendered a block of pixel rows at a time."""

    q: np.ndarray
    o: RenderOptions
    scene: Scene
    s: int  # supersampling
    w: int
    rays: np.ndarray  # camera-frame rays of the samples
    ray_du: np.ndarray  # and their derivatives per pixel
    ray_dv: np.ndarray
    rot: np.ndarray  # base_from_camera
    centre: np.ndarray
    emitter: np.ndarray  # the laser's origin in the base
    light: np.ndarray
    lvec: np.ndarray  # gradient of the laser-plane distance
    laser_shadows: bool

    def block(self, r0: int, r1: int) -> tuple[np.ndarray, ...]:
        """Pixel rows r0:r1 at the samples: (ambient, laser, surface index, lit)."""
        s = self.s
        ray = self.rays[r0 * s:r1 * s].reshape(-1, 3)
        dirs = ray @ self.rot.T
        t, nrm, which = self.scene.intersect(self.centre, dirs)
        hit = np.isfinite(t)
        tt = np.where(hit, t, 0.0)
        pb = self.centre + dirs * tt[:, None]  # base frame
        du = self.ray_du[r0 * s:r1 * s].reshape(-1, 3)
        dv = self.ray_dv[r0 * s:r1 * s].reshape(-1, 3)
        geo = (ray, du, dv, nrm, tt)
        alb = self._albedo(pb, which, geo)
        shade = self.scene.ambient_fraction + (1 - self.scene.ambient_fraction) * np.maximum(
            nrm @ self.light, 0.0)
        amb = np.where(hit, self.o.ambient * alb * shade, 0.0)
        lz, lit = self._laser(pb, hit, alb, geo)
        return amb, lz, which, lit

    def _footprint(self, sel: np.ndarray, geo: tuple[np.ndarray, ...]
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Derivative per pixel (u, v) of the hit point on its tangent plane (camera frame)
        for the samples ``sel``."""
        ray, du_all, dv_all, nrm, tt = geo
        rr = ray[sel]
        du = du_all[sel]
        dv = dv_all[sel]
        nc = nrm[sel] @ self.rot
        ndr = np.einsum("ij,ij->i", nc, rr)
        ndr = np.where(np.abs(ndr) > TINY, ndr, TINY)
        ts = tt[sel, None]
        return (ts * (du - rr * (np.einsum("ij,ij->i", nc, du) / ndr)[:, None]),
                ts * (dv - rr * (np.einsum("ij,ij->i", nc, dv) / ndr)[:, None]))

    def _albedo(self, pb: np.ndarray, which: np.ndarray, geo: tuple[np.ndarray, ...]
                ) -> np.ndarray:
        """Each sample's albedo (a textured table's filtered over the pixel's footprint)."""
        width = 1.5 / self.s
        alb = np.zeros(pb.shape[0])
        for i, prim in enumerate(self.scene.primitives):
            sel = np.nonzero(which == i)[0]
            if not sel.size:
                continue
            if isinstance(prim, Table) and prim.texture is not None:
                gu, gv = self._footprint(sel, geo)
                gu, gv = gu @ self.rot.T, gv @ self.rot.T
                alb[sel] = prim._albedo(pb[sel], np.hypot(gu[:, 0], gv[:, 0]),
                                        np.hypot(gu[:, 1], gv[:, 1]), width)
            else:
                alb[sel] = prim._albedo(pb[sel], None, None, width)
        return alb

    def _laser(self, pb: np.ndarray, hit: np.ndarray, alb: np.ndarray,
               geo: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's laser light (the stripe's profile at its distance in px from the
        laser plane, unless shadowed) and whether the laser reaches it."""
        ray, _, _, nrm, tt = geo
        o = self.o
        cut = 5.0 * o.stripe_sigma  # px: the profile is below 4e-6 beyond
        lz = np.zeros(pb.shape[0])
        lit = np.zeros(pb.shape[0], bool)
        dist = _laser_distance(self.q, ray * tt[:, None])
        near = np.nonzero(hit & (np.abs(dist) < _NEAR_MM))[0]
        if not near.size:
            return lz, lit
        gu, gv = self._footprint(near, geo)
        with np.errstate(divide="ignore", invalid="ignore"):
            dpx = dist[near] / np.hypot(gu @ self.lvec, gv @ self.lvec)
        bi = near[np.abs(dpx) < cut]
        dpx = dpx[np.abs(dpx) < cut]
        to_laser = self.emitter - pb[bi]
        cos_inc = np.einsum("ij,ij->i", nrm[bi], to_laser) / np.linalg.norm(to_laser, axis=1)
        ok = cos_inc > 0
        if self.laser_shadows and ok.any():
            oi = bi[ok]
            ts, _, _ = self.scene.intersect(pb[oi] + 1e-4 * nrm[oi], self.emitter - pb[oi],
                                            1e-9)
            ok[ok] = ~(ts < 1.0 - 1e-6)
        lit[bi] = ok
        lz[bi] = np.where(ok, o.laser * alb[bi] * cos_inc *
                          np.exp(-0.5 * (dpx / o.stripe_sigma) ** 2), 0.0)
        return lz, lit


