"""Scenes on the image plane: one labelled object over a background, seen by a camera.

:func:`planar_scene` composes a clip from

- a *mover*, the labelled object (disk, ellipse, square, rectangle or car; dark or light; a
  Weber contrast; optionally a texture of its own, which grows with it), how it moves
  (``motion``), and optionally a walker's :class:`Gait`;
- a :class:`Background`, uniform or a pattern (stripes, grating, checkerboard, random texture)
  that may translate;
- static :class:`Prop` objects;
- camera motion, lighting changes, sensor noise and JPEG artefacts (:mod:`.effects`).

Motion in depth follows a pinhole camera: an object at distance ``Z(t)`` has image size
``f S / Z`` and image centre ``c + f X / Z`` (``c`` the frame centre). With ``Z0`` its distance at
onset and ``v`` the closing speed, ``tau = Z0 / v`` is the time to contact at onset and the image
scales by ``s(t) = Z0 / Z(t)``:

``loom``
    A collision course: ``Z = Z0 - v t`` and a constant bearing, so the image centre stays where
    it is (anywhere in the frame) while the image grows as ``1 / (tau - t)``.
``nearmiss``
    The same object, distance and speed, but moving parallel to the line of sight at a lateral
    offset: its image centre moves away from the frame centre as ``c + (x0 - c) s(t)``, ever
    faster, and leaves the frame (a truck passing close, a car in the next lane).
``recede``
    ``Z = Z0 + v t``: the image shrinks.
``halt``
    Approaches as ``loom`` until its image is ``stop_height`` tall, then stands still.
``approach-recede``
    Approaches to ``stop_height``, stays ``hold`` frames, then recedes at the same speed to where
    it started.
``translate``
    Moves across the image at ``velocity`` pixels per frame, at constant size.
``none``
    No labelled object (backgrounds, camera and lighting alone).

Labels: ``loom``, ``halt`` and ``approach-recede`` are collisions, everything else is not. The
approach starts at ``onset``. For ``loom`` the contact frame is the first frame where the image is
as tall as the frame (the object fills the view; its time to contact is then
``tau * height / H``, 0.1-0.6 s in the suite); for ``halt`` and ``approach-recede`` it is the frame
the approach ends. ``ttc`` is ``Z / v`` in seconds in every frame with the object closing in,
NaN elsewhere.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, is_dataclass, replace

import cv2
import numpy as np

from . import effects
from .render import levels, noise_tile, paint_object, pattern, sample_tile
from .scene import Scene

__all__ = ["MOTIONS", "COLLISION_MOTIONS", "Background", "Gait", "Prop", "distance_ratio",
           "planar_scene"]

MOTIONS = ("loom", "nearmiss", "recede", "halt", "approach-recede", "translate", "none")
COLLISION_MOTIONS = ("loom", "halt", "approach-recede")
_PATTERNS = ("stripes", "grating", "checker")


@functools.lru_cache(maxsize=16)
def _tile(seed: int, scale: float, zoom: float = 1.0) -> np.ndarray:
    return noise_tile(seed, scale, zoom=zoom)


@dataclass(frozen=True)
class Background:
    """What lies behind the objects.

    Attributes
    ----------
    kind : {'uniform', 'stripes', 'grating', 'checker', 'texture'}
    contrast : float
        The pattern's Weber contrast: it spans ``mean +- 255 contrast / 2``.
    period : float
        Pixels per cycle (stripes, grating, checker), or the smallest structure of the random
        texture.
    angle_deg : float
        Direction of the pattern's normal (0: vertical stripes, 90: horizontal, 45: diagonal).
    velocity : (vx, vy)
        Pixels per frame.
    duty : float
        Fraction of a period the stripes cover.
    mean : float or None
        Mean gray level; None takes the mover's background level (mid-gray without a mover).
    seed : int
        Of the texture.
    scale : float
        Drawn with this many times the pixels (:meth:`scaled`): ``period`` and ``velocity``
        are given in the pixels of scale 1, and the texture is the same one, finer sampled.
    """

    kind: str = "uniform"
    contrast: float = 0.0
    period: float = 16.0
    angle_deg: float = 0.0
    velocity: tuple[float, float] = (0.0, 0.0)
    duty: float = 0.5
    mean: float | None = None
    seed: int = 0
    scale: float = 1.0

    def check(self, mean: float) -> None:
        """Raise ValueError unless the pattern fits in 0..255 around ``mean``."""
        if self.kind not in ("uniform", "texture", *_PATTERNS):
            raise ValueError(f"unknown background {self.kind!r}")
        half = 127.5 * self.contrast
        if self.contrast < 0 or mean - half < -1e-9 or mean + half > 255 + 1e-9:
            raise ValueError(f"a {self.kind} of contrast {self.contrast} does not fit around "
                             f"mean level {mean:.1f}")

    @property
    def moving(self) -> bool:
        return self.kind != "uniform" and any(self.velocity)

    def scaled(self, scale: float) -> "Background":
        """The same background seen with ``scale`` times the pixels."""
        return replace(self, scale=self.scale * scale)

    def render(self, index: int, shape: tuple[int, int], origin: tuple[float, float],
               mean: float) -> np.ndarray:
        """The background of frame ``index`` on a canvas whose rest view starts at ``origin``."""
        # pixel centres at whole coordinates: scale 1's pixel x is at scale (x + 1/2) - 1/2
        step, centre = self.scale * index, (self.scale - 1.0) / 2.0
        offset = (origin[0] + centre + self.velocity[0] * step,
                  origin[1] + centre + self.velocity[1] * step)
        if self.kind == "uniform" or self.contrast == 0:
            return np.full(shape, float(mean))
        if self.kind == "texture":
            tile = _tile(self.seed, self.period, self.scale)
            values = 0.5 + 0.5 * sample_tile(tile, shape, offset)
        else:
            values = pattern(shape, self.kind, self.period * self.scale, self.angle_deg, offset,
                             self.duty)
        return mean + 255.0 * self.contrast * (values - 0.5)


@dataclass(frozen=True)
class Gait:
    """A walker's sway: an animal or a person walking up to the camera does not keep its image
    still while it grows; its body swings from side to side once per stride and bobs with every
    step.

    From the motion's onset the mover's image centre moves by ``sway * size * sin(2 pi f t)``
    sideways and ``bob * size * |sin(2 pi f t)|`` down, with ``size`` its image height: the path
    it walks keeps its bearing on average.

    Attributes
    ----------
    sway, bob : float
        Amplitudes, fractions of the mover's image height.
    frequency : float
        Strides per second, Hz.
    """

    sway: float = 0.06
    bob: float = 0.04
    frequency: float = 2.0

    def offsets(self, frames: int, onset: int, fps: float, sizes: np.ndarray) -> np.ndarray:
        """(frames, 2) displacement of the image centre in every frame."""
        phase = 2.0 * math.pi * self.frequency * np.clip(np.arange(frames) - onset, 0, None) / fps
        return np.stack([self.sway * sizes * np.sin(phase),
                         self.bob * sizes * np.abs(np.sin(phase))], axis=1)


@dataclass(frozen=True)
class Prop:
    """A static object of the scene (not labelled): clutter for the camera and the lights.

    ``parallax`` is how much nearer to the camera than the background it stands: under the
    camera's displacement its image moves ``parallax`` times as far as the background's (a
    hand-held camera swaying in front of a desk: the things on it move more than the wall
    behind). A rotation moves everything alike, near or far.
    """

    shape: str
    x: float
    y: float
    height: float
    level: float
    aspect: float = 1.0
    parallax: float = 1.0

    def scaled(self, scale: float) -> "Prop":
        """The same prop seen with ``scale`` times the pixels."""
        x, y = effects.scaled_point((self.x, self.y), scale)
        return replace(self, x=x, y=y, height=self.height * scale)


def distance_ratio(motion: str, frames: int, onset: int, tau_frames: float,
                   stop_ratio: float | None = None, hold: int = 0) -> np.ndarray:
    """``Z(t) / Z0`` in every frame for a motion in depth at closing speed ``Z0 / tau_frames``.

    Parameters
    ----------
    motion : str
        One of :data:`MOTIONS`; ``translate`` and ``none`` stay at 1.
    frames, onset : int
    tau_frames : float
        Time to contact at onset, in frames.
    stop_ratio : float, optional
        ``Z / Z0`` where ``halt`` and ``approach-recede`` stop approaching.
    hold : int
        Frames ``approach-recede`` stays at ``stop_ratio`` before receding.

    Returns
    -------
    ndarray (frames,)
        Never below half a frame's travel, so the image stays finite.
    """
    steps = np.clip(np.arange(frames, dtype=np.float64) - onset, 0.0, None) / tau_frames
    floor = 0.5 / tau_frames
    if motion in ("loom", "nearmiss"):
        return np.maximum(1.0 - steps, floor)
    if motion == "recede":
        return 1.0 + steps
    if motion in ("halt", "approach-recede"):
        if stop_ratio is None or not floor < stop_ratio < 1.0:
            raise ValueError(f"{motion} needs a stop ratio in ({floor:.3g}, 1)")
        z = np.maximum(1.0 - steps, stop_ratio)
        if motion == "approach-recede":
            back = steps - (1.0 - stop_ratio) - hold / tau_frames  # travel after the hold
            z = np.where(back > 0, np.minimum(stop_ratio + back, 1.0), z)
        return z
    if motion in ("translate", "none"):
        return np.ones(frames)
    raise ValueError(f"unknown motion {motion!r}; choose one of {', '.join(MOTIONS)}")


def _first(condition: np.ndarray) -> int | None:
    hits = np.flatnonzero(condition)
    return int(hits[0]) if hits.size else None


def _spec(value):
    """JSON-ready description of an effect or background for the scene's params."""
    if is_dataclass(value):
        return {"type": type(value).__name__, **asdict(value)}
    if isinstance(value, (list, tuple)):
        return [_spec(v) for v in value]
    return value


@dataclass(frozen=True)
class _Path:
    """Where the mover is in every frame of a long horizon, and the frames that matter."""

    z: np.ndarray           # Z / Z0
    sizes: np.ndarray       # image height
    centres: np.ndarray     # (T, 2) image centre, rest view
    contact: int | None     # contact, or where the approach ends (collisions)
    end: int                # default clip length
    clearance: float | None


def _mover_path(motion: str, name: str, size: tuple[int, int], horizon: int, onset: int,
                n_tau: float, height: float, extent: np.ndarray, x0: np.ndarray,
                velocity: tuple[float, float], stop_height: float | None, hold: int,
                tail: int) -> _Path:
    w, h = size
    center = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    stop_ratio = height / stop_height if stop_height else None
    z = distance_ratio(motion, horizon, onset, n_tau, stop_ratio, hold)
    sizes = height / z
    centres = np.broadcast_to(x0, (horizon, 2)).copy()
    contact = clearance = None
    end = 70
    if motion == "loom":
        contact = _first(sizes >= h)
        if contact is None:
            raise ValueError(f"{name}: the looming image never fills the frame height")
        end = contact + tail + 1
    elif motion in ("halt", "approach-recede"):
        contact = _first(z <= stop_ratio + 1e-12)
        back = _first((np.arange(horizon) > contact) & (z >= 1.0))
        end = contact + 30 if motion == "halt" else (back or horizon - 10) + 10
    elif motion == "recede":
        end = onset + int(round(n_tau)) + 5
    elif motion == "translate":
        centres += np.clip(np.arange(horizon) - onset, 0, None)[:, None] * np.asarray(velocity)
    elif motion == "nearmiss":
        # the gap between the object's edge and the camera's line of sight, in object sizes,
        # along the axis where it passes: not positive means it would hit
        clearance = float(np.max((np.abs(x0 - center) - extent / 2) / extent))
        if clearance <= 0:
            raise ValueError(f"{name}: a near miss must start further off-centre (clearance "
                             f"{clearance:.2f} object sizes)")
        centres = center + (x0 - center) / z[:, None]
        half = np.outer(1.0 / z, extent / 2)
        gone = np.any((centres - half > np.array([w, h]) - 0.5) | (centres + half < -0.5), axis=1)
        exit_frame = _first(gone)
        if exit_frame is None:
            raise ValueError(f"{name}: the near miss never leaves the frame; move it off-centre")
        end = exit_frame + tail + 1
    return _Path(z, sizes, centres, contact, min(end, horizon), clearance)


# the mover's own texture spans this many tile pixels per image height, so it grows with the mover
_TEXTURE_SPAN = 30.0


def _mover_texture(shape: tuple[int, int], kind: str, cx: float, cy: float, height: float,
                   aspect: float, contrast: float, tile: np.ndarray) -> np.ndarray:
    """What a texture of Weber contrast ``contrast`` adds to a mover painted at (cx, cy): the
    tile scaled with the mover's image height, inside its outline (anti-aliased)."""
    cover = np.zeros(shape)
    paint_object(cover, kind, cx, cy, height, 1.0, aspect)
    k = _TEXTURE_SPAN / height
    half = tile.shape[0] / 2
    image_to_tile = np.float32([[k, 0, half - k * cx], [0, k, half - k * cy]])
    texture = cv2.warpAffine(tile, image_to_tile, shape[::-1],
                             flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                             borderMode=cv2.BORDER_WRAP)
    return cover * (127.5 * contrast) * texture


def _render(frames: int, size: tuple[int, int], fps: float, background: Background,
            mean: float, props: Sequence[Prop], mover, camera, lighting: Sequence) -> tuple:
    """Float frames (T, H, W) and the camera path: the rest view (background, props and
    ``mover`` = (shape, level, aspect, centres, sizes, texture) or None, ``texture`` = (Weber
    contrast, tile) or None) seen by the moving camera under the lighting."""
    w, h = size
    path = effects.camera_path(camera, frames, fps)
    left, top, right, bottom = effects.canvas_margins(path, size) if camera else (0, 0, 0, 0)
    canvas_shape = (h + top + bottom, w + left + right)
    origin = (float(left), float(top))
    gain = effects.gains(lighting, frames, fps)
    glows = [g for g in lighting if hasattr(g, "glow")]

    def scenery(t: int) -> np.ndarray:
        canvas = background.render(t, canvas_shape, origin, mean)
        dx, dy = path[t, :2]
        for prop in props:  # the camera's warp moves it once more, as the background
            near = prop.parallax - 1.0
            paint_object(canvas, prop.shape, prop.x + left + near * dx, prop.y + top + near * dy,
                         prop.height, prop.level, prop.aspect)
        return canvas

    parallax = camera is not None and any(prop.parallax != 1.0 for prop in props)
    still = None if background.moving or parallax else scenery(0)
    clip = np.empty((frames, h, w))
    for t in range(frames):
        canvas = still.copy() if still is not None else scenery(t)
        if mover is not None:
            shape, level, aspect, centres, sizes, texture = mover
            cx, cy = centres[t, 0] + left, centres[t, 1] + top
            paint_object(canvas, shape, cx, cy, sizes[t], level, aspect)
            if texture:
                canvas += _mover_texture(canvas.shape, shape, cx, cy, sizes[t], aspect, *texture)
        if camera is not None:
            canvas = cv2.warpAffine(canvas, effects.camera_matrix(*path[t], size, origin), (w, h),
                                    flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        frame = canvas * gain[t]
        for light in glows:
            glow = light.glow(t, (h, w))
            if glow is not None:
                frame = frame + glow
        clip[t] = frame
    return clip, path


def planar_scene(motion: str = "loom", *, name: str = "planar", size: tuple[int, int] = (160, 120),
                 fps: float = 20.0, frames: int | None = None, onset: int = 10,
                 shape: str = "disk", polarity: str = "dark", contrast: float = 0.6,
                 height: float = 12.0, aspect: float = 1.0, texture: float = 0.0,
                 gait: Gait | None = None,
                 position: tuple[float, float] | None = None, tau: float = 3.0,
                 velocity: tuple[float, float] = (2.0, 0.0), stop_height: float | None = None,
                 hold: int = 10, tail: int = 2, background: Background = Background(),
                 props: Sequence[Prop] = (), camera=None, lighting: Sequence = (),
                 noise: float = 0.0, jpeg_quality: int | None = None, seed: int = 0,
                 category: Sequence[str] = (), twin: str | None = None,
                 scale: float = 1.0) -> Scene:
    """Compose a labelled clip on the image plane (see the module text for the motions).

    Parameters
    ----------
    motion : str
        One of :data:`MOTIONS`.
    name : str
    size : (width, height)
    fps : float
    frames : int, optional
        Clip length. Default: contact + ``tail`` + 1 (``loom``); until the image has left the
        frame, + ``tail`` (``nearmiss``); 30 frames after the halt (``halt``); 10 after the
        recession (``approach-recede``); until the image is half its size (``recede``); 70
        otherwise.
    onset : int
        First frame of the motion.
    shape : {'disk', 'ellipse', 'square', 'rect', 'car'}
    polarity : {'dark', 'light'}
    contrast : float
        Weber contrast of the mover against the background's mean.
    height : float
        The mover's image height at onset (a disk's diameter), pixels.
    aspect : float
        Width over height (``ellipse``, ``rect``, ``car``).
    texture : float
        Weber contrast of a random texture on the mover (spanning ``level +- 255 texture / 2``),
        which grows with it; 0 for a uniform mover. Not for ``car``, which has its own parts.
    gait : Gait, optional
        A walker's sway of the mover's image from the onset on.
    position : (x, y), optional
        The mover's image centre at onset; default the frame centre.
    tau : float
        Time to contact at onset, seconds (``Z0 / v``; the same speed recedes).
    velocity : (vx, vy)
        Pixels per frame, for ``translate``.
    stop_height : float, optional
        Image height where ``halt`` and ``approach-recede`` stop approaching.
    hold, tail : int
        Frames ``approach-recede`` holds; frames after contact (or after a near miss has left).
    background : Background
    props : sequence of Prop
    camera : Shake, Pan or Sweep, optional
    lighting : sequence of Ramp, Flicker, Step or Headlights
    noise : float
        Standard deviation of the per-frame Gaussian sensor noise, gray levels.
    jpeg_quality : int, optional
        Re-encode every frame as JPEG at this quality.
    seed : int
        Of the sensor noise.
    category : sequence of str
        Tags for the label.
    twin : str, optional
        The collision-course twin of a near miss.
    scale : float
        Render the scene seen with this many times the pixels: the frame size (rounded), and
        every length, position and speed given in pixels above (the mover's, the background's,
        the props', the camera's motion and the headlights') are multiplied by it, so that the
        same scene is drawn with more (or fewer) pixels rather than resized. The label is in
        the pixels rendered; ``params`` holds the scaled values and ``scale``.

    Returns
    -------
    Scene

    Raises
    ------
    ValueError
        For an unknown motion, shape or background, levels outside 0..255, a scale that is not
        positive, or a clip too short for its motion (no contact, or a near miss that never
        leaves the frame).
    """
    if motion not in MOTIONS:
        raise ValueError(f"unknown motion {motion!r}; choose one of {', '.join(MOTIONS)}")
    if not scale > 0:
        raise ValueError(f"scale must be positive, got {scale!r}")
    if scale != 1.0:
        size = effects.scaled_size(size, scale)
        height *= scale
        stop_height = None if stop_height is None else stop_height * scale
        position = None if position is None else effects.scaled_point(position, scale)
        velocity = (velocity[0] * scale, velocity[1] * scale)
        background = background.scaled(scale)
        props = [prop.scaled(scale) for prop in props]
        camera = None if camera is None else camera.scaled(scale)
        # brightness ramps, flicker and exposure steps have nothing in pixels
        lighting = [light.scaled(scale) if hasattr(light, "scaled") else light
                    for light in lighting]
    w, h = size
    if w < 32 or h < 32:
        raise ValueError(f"scene size must be at least 32x32, got {w}x{h}")
    if tau <= 0 or height <= 0:
        raise ValueError("tau and height must be positive")
    has_mover = motion != "none"
    if texture and (texture < 0 or shape == "car"):
        raise ValueError(f"a texture must be positive and not on a car, got {texture} on {shape}")
    if has_mover:
        background_level, level = levels(contrast, polarity)
        if texture and not 127.5 * texture <= min(level, 255.0 - level):
            raise ValueError(f"a texture of contrast {texture} does not fit around the mover's "
                             f"level {level:.1f}")
    else:
        background_level, level = 127.5, None
    mean = background.mean if background.mean is not None else background_level
    background.check(mean)
    x0 = np.asarray(position if position is not None else ((w - 1) / 2.0, (h - 1) / 2.0),
                    dtype=np.float64)
    extent = height * np.array([aspect if shape in ("ellipse", "rect", "car") else 1.0, 1.0])
    n_tau = tau * fps
    horizon = frames or onset + int(math.ceil(n_tau)) + 400
    move = _mover_path(motion, name, size, horizon, onset, n_tau, height, extent, x0, velocity,
                       stop_height, hold, tail)
    frames = frames or move.end
    z, sizes, centres = move.z[:frames], move.sizes[:frames], move.centres[:frames]
    if gait is not None:
        centres = centres + gait.offsets(frames, onset, fps, sizes)

    mover = None
    if has_mover:
        mover = (shape, level, aspect, centres, sizes,
                 (texture, _tile(seed + 1, 1.5)) if texture else None)
    clip, path = _render(frames, size, fps, background, mean, props, mover, camera, lighting)
    clip = effects.sensor_noise(clip, noise, seed)
    video = np.clip(np.rint(clip), 0, 255).astype(np.uint8)
    if jpeg_quality is not None:
        video = effects.jpeg(video, jpeg_quality)

    collision = motion in COLLISION_MOTIONS
    contact = move.contact
    if collision and contact >= frames:
        raise ValueError(f"{name}: {frames} frames end before the approach does ({contact})")
    track = sizes_label = ttc = None
    if has_mover:
        track = effects.transform_points(centres, path, size)
        sizes_label = sizes.copy()
        closing = np.append(z[1:] < z[:-1], len(z) > 1 and z[-1] < z[-2])  # closing in next
        ttc = np.where(closing, z * tau, np.nan)
    params = dict(motion=motion, size=size, fps=fps, frames=frames, onset=onset, shape=shape,
                  polarity=polarity, contrast=contrast, height=height, aspect=aspect,
                  texture=texture, gait=_spec(gait),
                  position=tuple(float(v) for v in x0), tau=tau, velocity=velocity,
                  stop_height=stop_height, hold=hold, background=_spec(background),
                  props=_spec(list(props)), camera=_spec(camera), lighting=_spec(list(lighting)),
                  noise=noise, jpeg_quality=jpeg_quality, seed=seed)
    if scale != 1.0:
        params["scale"] = scale
    if move.clearance is not None:
        params["clearance"] = round(move.clearance, 3)
    return Scene(name=name, frames=video, fps=fps, collision=collision,
                 onset_frame=onset if collision else None,
                 contact_frame=contact if collision else None,
                 center=tuple(float(v) for v in track[contact]) if collision else None,
                 params=params, track=track, target_size=sizes_label, ttc=ttc,
                 category=tuple(category), twin=twin)
