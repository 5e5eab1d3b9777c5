"""A camera moving in front of one textured plane: a wall, a door, the back of a lorry that
fills the view.

:func:`surface_scene` renders the plane through a pinhole camera (horizontal field of view
60 degrees) that does not turn. The plane holds a random texture and is seen at a slant (its
normal turned about the vertical axis by ``slant_deg``: 0 faces the camera, 90 runs along its
line of sight); where a ray misses it, a uniform backdrop is seen. Every frame is drawn at
twice its size and area-averaged, so that the far parts of a slanted plane do not alias.

``approach``
    The camera moves at constant speed along its heading (``heading_deg`` from the optical
    axis, to the right for positive angles: the focus of expansion lies ``f tan(heading)``
    pixels right of the frame's centre) until its front, ``standoff`` ahead of the lens,
    touches the plane: ``tau`` seconds after the onset. Then it stands against it for ``tail``
    frames. A collision: the contact frame is the one where the front touches; the centre is
    the focus of expansion.
``recede``
    The same motion backwards, for as long: not a collision.
``alongside``
    The camera moves parallel to a plane that runs along its line of sight (``slant_deg`` 90)
    at ``offset`` to its right, as past a corridor's wall or a hedge, at the speed that would
    take it ``tau`` seconds to cover the distance of the plane's point at the frame's edge: not
    a collision.

Distances are in units of the plane's distance along the optical axis at the onset.

:func:`corridor_scene` is a camera driven down a corridor instead (two walls, a floor, a ceiling
and an end wall, all textured, in metres): every part of the view expands, and the nearer
surfaces faster, yet nothing is ahead until the end wall comes close.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from . import effects
from .render import noise_tile
from .scene import Scene

__all__ = ["SURFACE_MOTIONS", "corridor_scene", "surface_scene"]

SURFACE_MOTIONS = ("approach", "recede", "alongside")
_FIELD_OF_VIEW = math.radians(60.0)
_SUPERSAMPLE = 2


def _rays(size: tuple[int, int], normal: np.ndarray) -> tuple[np.ndarray, ...]:
    """The supersampled pixels' rays ``(rx, ry, 1)`` of a camera that does not turn, and their
    dot product with the plane's ``normal``: the same in every frame."""
    w, h = size
    sw, sh = w * _SUPERSAMPLE, h * _SUPERSAMPLE
    f = 0.5 * sw / math.tan(0.5 * _FIELD_OF_VIEW)
    u = (np.arange(sw) - 0.5 * (sw - 1)) / f
    v = (np.arange(sh) - 0.5 * (sh - 1)) / f
    rx, ry = np.meshgrid(u, v)
    return rx, ry, normal[0] * rx + normal[1] * ry + normal[2]


def _plane_image(size: tuple[int, int], rays: tuple[np.ndarray, ...], camera: np.ndarray,
                 normal: np.ndarray, point: np.ndarray, tile: np.ndarray, texels: float,
                 backdrop: float, contrast: float, mean: float) -> np.ndarray:
    """One frame: the plane through ``point`` with unit ``normal``, seen from ``camera`` along
    ``rays`` (:func:`_rays`)."""
    w, h = size
    rx, ry, facing = rays
    reach = float(normal @ (point - camera))
    with np.errstate(divide="ignore", invalid="ignore"):
        s = reach / facing
    hit = np.isfinite(s) & (s > 0)
    # the plane's own axes: horizontal within it, and the vertical
    across = np.array([normal[2], 0.0, -normal[0]])
    px = camera[0] + s * rx - point[0]
    py = camera[1] + s * ry - point[1]
    pz = camera[2] + s - point[2]
    tx = np.where(hit, (px * across[0] + pz * across[2]) * texels, 0.0).astype(np.float32)
    ty = np.where(hit, py * texels, 0.0).astype(np.float32)
    n = tile.shape[0]
    values = cv2.remap(tile, np.mod(tx, n), np.mod(ty, n), cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_WRAP)
    image = np.where(hit, mean * (1.0 + contrast * values), backdrop)
    return cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)


def surface_scene(motion: str = "approach", *, name: str = "surface",
                  size: tuple[int, int] = (160, 120), fps: float = 20.0, onset: int = 20,
                  tau: float = 3.0, heading_deg: float = 0.0, slant_deg: float = 0.0,
                  offset: float = 0.5, standoff: float = 0.12, contrast: float = 0.5,
                  period: float = 3.0, mean: float = 127.5, backdrop: float = 150.0,
                  tail: int = 2, noise: float = 0.0, seed: int = 0,
                  category: Sequence[str] = (), twin: str | None = None,
                  scale: float = 1.0) -> Scene:
    """A labelled clip of a camera moving in front of a textured plane (module text).

    Parameters
    ----------
    motion : str
        One of :data:`SURFACE_MOTIONS`.
    name : str
    size : (width, height)
    fps : float
    onset : int
        Frames of still camera before the motion.
    tau : float
        Time to contact at the onset, seconds (``approach``; the same speed for ``recede``).
    heading_deg : float
        The camera's heading from its optical axis, degrees (positive: to the right).
    slant_deg : float
        The plane's slant, degrees: 0 faces the camera; ``alongside`` needs 90.
    offset : float
        The plane's distance to the right of the camera's path (``alongside``).
    standoff : float
        How far the camera's front is ahead of its lens (it touches the plane there).
    contrast : float
        The texture's Weber contrast: it spans ``mean * (1 +- contrast)``.
    period : float
        The texture's smallest structure, in pixels where the plane is at distance 1.
    mean, backdrop : float
        Gray levels of the texture's mean and of what lies beyond the plane.
    tail : int
        Frames after contact (``approach``).
    noise : float
        Standard deviation of the per-frame Gaussian sensor noise, gray levels.
    seed : int
        Of the texture and the noise.
    category : sequence of str
    twin : str, optional
    scale : float
        Drawn with this many times the pixels (the frame size and ``period``).

    Returns
    -------
    Scene

    Raises
    ------
    ValueError
        For an unknown motion, a plane the camera does not face, an ``alongside`` plane that
        does not run along the line of sight, or levels outside 0..255.
    """
    if motion not in SURFACE_MOTIONS:
        raise ValueError(f"unknown motion {motion!r}; choose one of {', '.join(SURFACE_MOTIONS)}")
    if not scale > 0:
        raise ValueError(f"scale must be positive, got {scale!r}")
    if not 0.0 <= contrast < 1.0 or not 0.0 <= mean * (1 + contrast) <= 255:
        raise ValueError(f"a texture of contrast {contrast} does not fit around mean {mean}")
    if not tau > 0 or not 0 < standoff < 1:
        raise ValueError(f"tau must be positive and standoff within (0, 1), got {tau}, {standoff}")
    if motion == "alongside" and slant_deg != 90.0:
        raise ValueError("a plane alongside the camera's path runs along its line of sight: "
                         "slant_deg must be 90")
    if motion != "alongside" and not abs(slant_deg) < 80.0:
        raise ValueError(f"the camera must face the plane: |slant_deg| < 80, got {slant_deg}")
    params = dict(motion=motion, size=tuple(size), fps=fps, onset=onset, tau=tau,
                  heading_deg=heading_deg, slant_deg=slant_deg, offset=offset,
                  standoff=standoff, contrast=contrast, period=period, mean=mean,
                  backdrop=backdrop, tail=tail, noise=noise, seed=seed, scale=scale)
    if scale != 1.0:
        size = effects.scaled_size(size, scale)
        period *= scale
    w, h = size
    slant, heading = math.radians(slant_deg), math.radians(heading_deg)
    normal = np.array([math.sin(slant), 0.0, -math.cos(slant)])  # toward the camera
    direction = np.array([math.sin(heading), 0.0, math.cos(heading)])
    f = 0.5 * w / math.tan(0.5 * _FIELD_OF_VIEW)
    texels = f * _SUPERSAMPLE  # one texel a supersampled pixel at distance 1
    tile = noise_tile(seed, period * _SUPERSAMPLE, size=512)
    if motion == "alongside":
        point = np.array([offset, 0.0, 0.0])
        edge = offset / math.tan(0.5 * _FIELD_OF_VIEW)  # the plane's point at the frame's edge
        speed, steps = edge / tau, round(tau * fps)
        collision = False
    else:
        point = np.array([0.0, 0.0, 1.0])
        along = float(normal @ point) / float(normal @ direction)  # lens to the plane
        if not along > standoff:
            raise ValueError("the camera's heading does not meet the plane ahead of it")
        speed = (along - standoff) / tau
        steps = round(tau * fps)
        collision = motion == "approach"
    sign = -1.0 if motion == "recede" else 1.0
    total = onset + steps + 1 + (tail if collision else 0)
    clip = np.empty((total, h, w))
    ttc = np.full(total, np.nan)
    rays = _rays((w, h), normal)
    for k in range(total):
        moved = min(max(k - onset, 0), steps) / fps
        clip[k] = _plane_image((w, h), rays, sign * speed * moved * direction, normal, point,
                               tile, texels, backdrop, contrast, mean)
        if collision and onset <= k <= onset + steps:
            ttc[k] = tau - moved
    frames = np.clip(np.rint(effects.sensor_noise(clip, noise, seed)), 0, 255).astype(np.uint8)
    focus = ((w - 1) / 2 + f * math.tan(heading), (h - 1) / 2)
    track = None
    if collision:
        track = np.full((total, 2), np.nan)
        track[onset:] = focus
    return Scene(name=name, frames=frames, fps=fps, collision=collision,
                 onset_frame=onset if collision else None,
                 contact_frame=onset + steps if collision else None,
                 center=focus if collision else None, params=params, track=track,
                 ttc=ttc if collision else None, category=tuple(category), twin=twin)


def corridor_scene(*, name: str = "corridor", size: tuple[int, int] = (160, 120),
                   fps: float = 20.0, speed: float = 2.0, seconds: float = 6.0,
                   half_width: float = 1.0, below: float = 0.5, above: float = 1.9,
                   end: float = 60.0, standoff: float = 0.3, contrast: float = 0.5,
                   obstacle: float | None = None,
                   obstacle_size: tuple[float, float] = (0.5, 1.7),
                   obstacle_shade: float = 0.55, noise: float = 0.0, seed: int = 0,
                   category: Sequence[str] = (), twin: str | None = None,
                   scale: float = 1.0) -> Scene:
    """A labelled clip of a camera driven down a corridor at ``speed`` m/s for ``seconds``.

    The corridor is ``2 half_width`` m wide, its floor ``below`` and its ceiling ``above`` the
    lens, its end wall ``end`` m ahead at the start; the camera (60 degrees across, as
    :func:`surface_scene`'s) looks along it. A collision where its front, ``standoff`` m ahead
    of the lens, reaches the end wall within the clip (the contact frame, after which it stands
    there), else not. With ``obstacle``, a board ``obstacle_size`` m wide and high (a person's
    size by default) stands on the floor in the corridor's middle, across the lens's height,
    ``obstacle`` m ahead at the start, shaded ``obstacle_shade`` (the walls are 0.75-1.1): the
    collision is then with it. Walls, floor, ceiling, end wall and board carry the same random
    texture (its finest structure about 6.5 cm: 9 px at 1 m, 160 px across), shaded
    differently, drawn at twice the size and area-averaged; at another ``scale`` the same
    texture, magnified with the frame.

    Raises
    ------
    ValueError
        For a corridor the camera is not inside, a speed or duration that is not positive, or
        levels outside 0..255.
    """
    if not (half_width > 0 and below > 0 and above > 0 and end > standoff > 0):
        raise ValueError("the camera must be inside the corridor, its end wall ahead of its "
                         "front")
    board_w, board_h = (float(v) for v in obstacle_size)
    if obstacle is not None and not (end > obstacle > standoff and 0 < board_w <= 2 * half_width
                                     and below <= board_h <= below + above and obstacle_shade > 0):
        raise ValueError("the obstacle must stand between the camera's front and the end wall, "
                         "within the corridor and across the lens's height, with a positive shade")
    if not (speed > 0 and seconds > 0 and fps > 0 and scale > 0):
        raise ValueError("speed, seconds, fps and scale must be positive")
    if not 0.0 <= contrast < 1.0 or not 127.5 * 1.1 * (1 + contrast) <= 255:
        raise ValueError(f"a texture of contrast {contrast} does not fit the levels")
    params = dict(size=tuple(size), fps=fps, speed=speed, seconds=seconds,
                  half_width=half_width, below=below, above=above, end=end,
                  standoff=standoff, contrast=contrast, obstacle=obstacle,
                  obstacle_size=(board_w, board_h), obstacle_shade=obstacle_shade, noise=noise,
                  seed=seed, scale=scale)
    if scale != 1.0:
        size = effects.scaled_size(size, scale)
    w, h = size
    rx, ry, _ = _rays((w, h), np.array([0.0, 0.0, -1.0]))
    f = 0.5 * w / math.tan(0.5 * _FIELD_OF_VIEW)
    texels = f * _SUPERSAMPLE / 3.0  # texels per metre
    # structures of 3 texels at 160 px across (6.5 cm), magnified with the frame
    tile = noise_tile(seed, 3.0 * _SUPERSAMPLE, size=512, zoom=w / params["size"][0])
    n = tile.shape[0]
    with np.errstate(divide="ignore"):
        # distance along the axis to each side, per ray: left, right, floor, ceiling
        sides = np.stack([np.where(rx < 0, -half_width / rx, np.inf),
                          np.where(rx > 0, half_width / rx, np.inf),
                          np.where(ry > 0, below / ry, np.inf),
                          np.where(ry < 0, -above / ry, np.inf)])
    ahead = end if obstacle is None else obstacle
    shade = np.array([0.9, 0.9, 0.75, 1.1, 1.0, obstacle_shade])
    total = round(seconds * fps) + 1
    clip = np.empty((total, h, w))
    for k in range(total):
        # the camera stops where its front meets the end wall or the board
        travelled = min(speed * k / fps, ahead - standoff)
        surfaces = [sides, np.full((1, *rx.shape), end - travelled)]
        if obstacle is not None:
            z = obstacle - travelled
            board = ((z > 0) & (np.abs(z * rx) <= 0.5 * board_w) & (z * ry <= below)
                     & (z * ry >= below - board_h))
            surfaces.append(np.where(board, z, np.inf)[None])
        depth = np.concatenate(surfaces)
        which = depth.argmin(axis=0)
        z = depth.min(axis=0)
        x, y = z * rx, z * ry
        # each surface's own two coordinates (metres), the surfaces apart in the texture
        a = np.choose(which, [z + travelled, z + travelled, x, x, x, x])
        b = np.choose(which, [y, y, z + travelled, z + travelled, y, y]) + 37.0 * which
        values = cv2.remap(tile, np.mod(a * texels, n).astype(np.float32),
                           np.mod(b * texels, n).astype(np.float32), cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_WRAP)
        image = 127.5 * shade[which] * (1.0 + contrast * values)
        clip[k] = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
    frames = np.clip(np.rint(effects.sensor_noise(clip, noise, seed)), 0, 255).astype(np.uint8)
    contact = (ahead - standoff) / speed * fps
    collision = contact <= total - 1
    ttc = track = None
    centre = (0.5 * (w - 1), 0.5 * (h - 1))  # the point the lens heads at, on the wall or board
    if collision:
        contact = int(math.ceil(contact))
        ttc = np.full(total, np.nan)
        ttc[:contact + 1] = (ahead - standoff) / speed - np.arange(contact + 1) / fps
        track = np.tile(centre, (total, 1))
    return Scene(name=name, frames=frames, fps=fps, collision=collision,
                 onset_frame=0 if collision else None,
                 contact_frame=contact if collision else None,
                 center=centre if collision else None, params=params,
                 track=track, ttc=ttc, category=tuple(category), twin=twin)

