"""Perspective driving scenes: a pinhole camera on a car moving over a textured road.

The world is a flat ground plane with a three-lane road: our lane (lateral position ``d = 0``),
an oncoming lane on the left (``d = -3.5`` m) and a lane in our direction on the right
(``d = +3.5`` m), each 3.5 m wide, with dashed lane lines, solid edge lines, asphalt grain and a
textured verge. The road is straight or bends with a constant curvature; the camera follows our
lane's centre at ``speed``, ``camera_height`` above the road, pitched down a little, with
optional bumps (a pitch oscillation). Poles, trees, reflector posts and boxes stand beside the
road and flow outward as we pass them. Other vehicles drive in the lanes, or cross the road (cross
traffic at a junction: the T-bone collisions and crossings ahead of dashcam footage); one of them
may be the labelled target.

Drawing: every ground pixel is the ray's hit on the plane; the texture is sampled from a mipmap at
the pixel's footprint and the lines are box-filtered by it, so distant road neither shimmers nor
aliases; roadside objects and vehicles are upright boxes drawn by area coverage
(:mod:`.render`), far to near. Haze by day, and our headlights' beam by night, shade everything
by its distance.

Labels for the target vehicle: its image centre (the centre of its near face) and height in every
frame; ``ttc = Z / v`` with ``Z`` its distance along the camera axis and ``v = -dZ/dt``, where
``v > 0``; a collision when its near face reaches our front bumper (``front`` metres ahead of the
camera) while it overlaps our lane, the contact frame being the first frame at or under that
distance. A crossing vehicle that has left our lane by then is passed behind: no collision.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from .render import car_lamps, noise_tile, paint_disk, paint_object
from .scene import Scene

__all__ = ["LANE_WIDTH", "Vehicle", "driving_scene", "road_coordinates", "path_pose"]

LANE_WIDTH = 3.5
_ROAD_HALF = 1.5 * LANE_WIDTH          # three lanes, ours in the middle
_LANE_LINES = (-0.5 * LANE_WIDTH, 0.5 * LANE_WIDTH)
_LINE_WIDTH, _EDGE_WIDTH = 0.12, 0.15
_DASH_PERIOD, _DASH_DUTY = 9.0, 1.0 / 3.0
_TEXEL = 0.05                          # metres per texel of the fine asphalt grain
_NEAR = 0.5                            # nothing nearer than this is drawn (m)
# ... except that the near clip moves closer for a short bumper or a fast closing speed, so
# the target is still drawn and labelled at contact (the frame its near face is at the bumper)
_EGO_WIDTH = 1.8


@dataclass(frozen=True)
class Vehicle:
    """Another road user, an upright box seen from behind (oncoming: from the front; crossing:
    from the side).

    Attributes
    ----------
    lane : float
        Lateral position of its centre, metres right of our lane's centre.
    distance : float
        Metres along the road from our camera to its near face at frame 0.
    speed : float
        Metres per second along the road; negative for oncoming traffic.
    lateral_speed : float
        Metres per second across the road, to the right: a vehicle crossing at a junction (its
        near face is then its side, so give a car's length as its ``width``), or one changing
        lanes (seen from behind).
    brake : float
        Deceleration from ``brake_frame`` until it stands, m/s^2.
    brake_frame : int
    width, height : float
        Metres.
    shape : {'car', 'rect'}
        A car (window band and lamps) or a plain box (a truck's rear).
    albedo : float
        Reflectance of its body, 0..1 (by day its gray level is ``255 * albedo``).

    Raises
    ------
    ValueError
        For a negative (or NaN) ``brake`` or a negative ``brake_frame``.
    """

    lane: float
    distance: float
    speed: float
    lateral_speed: float = 0.0
    brake: float = 0.0
    brake_frame: int = 0
    width: float = 1.8
    height: float = 1.5
    shape: str = "car"
    albedo: float = 0.22

    def __post_init__(self):
        _check_braking(self.brake, self.brake_frame)

    def travelled(self, t: np.ndarray, fps: float) -> np.ndarray:
        """Metres along the road since frame 0, at frames ``t``."""
        t0 = self.brake_frame / fps
        seconds = t / fps
        if self.brake <= 0 or self.speed == 0:
            return self.speed * seconds
        stop = abs(self.speed) / self.brake
        dt = np.clip(seconds - t0, 0.0, stop)
        sign = math.copysign(1.0, self.speed)
        return self.speed * np.minimum(seconds, t0) + sign * (abs(self.speed) * dt
                                                              - 0.5 * self.brake * dt ** 2)

    def lateral(self, t: np.ndarray, fps: float) -> np.ndarray:
        """Lateral position of its centre (metres right of our lane's centre) at frames ``t``."""
        return self.lane + self.lateral_speed * np.asarray(t, dtype=np.float64) / fps


def _check_braking(brake: float, brake_frame: int) -> None:
    """Refuse a braking that would accelerate, or start before the clip (it moved frame 0)."""
    if not brake >= 0:
        raise ValueError(f"brake is a deceleration, 0 or more m/s^2, got {brake}")
    if brake_frame < 0:
        raise ValueError(f"brake_frame must be 0 or more, got {brake_frame}")


def path_pose(s: np.ndarray, curvature: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World (X, Z) and heading of the point ``s`` metres along our lane's centre.

    X points right, Z forward at ``s = 0``; the heading turns right for a positive curvature.
    """
    s = np.asarray(s, dtype=np.float64)
    if curvature == 0:
        return np.zeros_like(s), s, np.zeros_like(s)
    heading = curvature * s
    return (1.0 - np.cos(heading)) / curvature, np.sin(heading) / curvature, heading


def road_coordinates(x: np.ndarray, z: np.ndarray, curvature: float) -> tuple[np.ndarray, np.ndarray]:
    """(s, d): distance along our lane's centre and lateral offset (right positive) of world
    points (X, Z)."""
    if curvature == 0:
        return z, x
    radius = 1.0 / abs(curvature)
    sign = math.copysign(1.0, curvature)
    cx = 1.0 / curvature
    r = np.hypot(x - cx, z)
    return radius * np.arctan2(z, sign * (cx - x)), sign * (radius - r)


def _world(s, d, curvature):
    x, z, heading = path_pose(s, curvature)
    return x + d * np.cos(heading), z - d * np.sin(heading)


@functools.lru_cache(maxsize=4)
def _pyramid(seed: int) -> tuple[np.ndarray, ...]:
    level = noise_tile(seed, 0.7)
    levels = [level]
    while level.shape[0] > 2:
        level = cv2.resize(level, (level.shape[1] // 2, level.shape[0] // 2),
                           interpolation=cv2.INTER_AREA)
        levels.append(level)
    return tuple(levels)


def _mip_sample(pyramid: Sequence[np.ndarray], u: np.ndarray, v: np.ndarray,
                lod: np.ndarray) -> np.ndarray:
    """Trilinear lookup of a periodic texture at texel coordinates (u, v) and mip level ``lod``
    (log2 of the pixel's footprint in texels; 0 is the full-resolution tile)."""
    lod = np.clip(lod, 0.0, len(pyramid) - 1.0)
    out = np.zeros(u.shape, dtype=np.float32)
    for k in range(int(lod.min()), int(np.ceil(lod.max())) + 1):
        weight = np.clip(1.0 - np.abs(lod - k), 0.0, 1.0).astype(np.float32)
        rows = np.flatnonzero(weight.any(axis=1))  # the level of detail changes mostly by row
        if rows.size == 0:
            continue
        band = slice(rows[0], rows[-1] + 1)
        scale = 0.5 ** k  # remap wraps coordinates of any size (within +-32767 texels)
        out[band] += weight[band] * cv2.remap(
            pyramid[k], (u[band] * scale).astype(np.float32), (v[band] * scale).astype(np.float32),
            cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    return out


def _band(x: np.ndarray, lo: float, hi: float, footprint: np.ndarray) -> np.ndarray:
    """Fraction of the window ``x +- footprint / 2`` inside ``[lo, hi]`` (box-filtered interval)."""
    half = footprint / 2
    return np.clip((np.minimum(x + half, hi) - np.maximum(x - half, lo)) / footprint, 0.0, 1.0)


@dataclass(frozen=True)
class _Look:
    """Gray levels and light of a time of day."""

    sky_top: float
    sky_horizon: float
    haze: float
    asphalt: float
    verge: float
    marking: float
    night: bool


_DAY = _Look(sky_top=170.0, sky_horizon=205.0, haze=190.0, asphalt=88.0, verge=112.0,
             marking=215.0, night=False)
_NIGHT = _Look(sky_top=6.0, sky_horizon=14.0, haze=10.0, asphalt=88.0, verge=112.0,
               marking=215.0, night=True)


def _light(look: _Look, x: np.ndarray, z: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """Fraction of its day brightness a surface at ego coordinates (x right, z ahead) shows."""
    if not look.night:
        return np.ones_like(distance)
    beam = np.exp(-(np.maximum(z, 0.0) / 40.0) ** 2) * np.exp(-(x / (2.0 + 0.25 * np.abs(z))) ** 2)
    return 0.1 + 0.9 * beam * (z > 0)


def _haze(look: _Look, value, distance):
    keep = np.exp(-distance / (90.0 if look.night else 160.0))
    return value * keep + look.haze * (1.0 - keep)


def _roadside(seed: int, length: float, density: float) -> list[dict]:
    """Poles, trees, reflector posts and boxes beside the road over ``length`` metres."""
    rng = np.random.default_rng(seed)
    items = []
    s = 4.0
    while s < length:
        s += rng.uniform(6.0, 16.0) / max(density, 1e-3)
        side = rng.choice((-1.0, 1.0))
        d = side * (_ROAD_HALF + rng.uniform(1.0, 5.0))
        kind = rng.choice(("pole", "tree", "post", "box"), p=(0.3, 0.35, 0.2, 0.15))
        items.append({"s": s, "d": d, "kind": str(kind), "shade": rng.uniform(0.8, 1.2)})
    return items


def _billboards(item: dict) -> list[tuple]:
    """(shape, width, bottom, top, albedo) boxes of a roadside item, metres."""
    shade = item["shade"]
    if item["kind"] == "pole":
        return [("rect", 0.18, 0.0, 5.0, 0.25 * shade)]
    if item["kind"] == "tree":
        return [("rect", 0.35, 0.0, 2.6, 0.2 * shade), ("disk", 3.0, 2.2, 5.2, 0.3 * shade)]
    if item["kind"] == "post":
        return [("rect", 0.12, 0.0, 1.0, 0.85)]
    return [("rect", 1.2, 0.0, 1.0, 0.55 * shade)]


@dataclass(frozen=True)
class _Camera:
    """Our camera in every frame: intrinsics, pose on the road and pitch."""

    size: tuple[int, int]
    f: float
    height: float
    curvature: float
    s: np.ndarray          # distance travelled along our lane
    x: np.ndarray          # world position and heading
    z: np.ndarray
    heading: np.ndarray
    pitch: np.ndarray
    near: float = _NEAR

    @property
    def center(self) -> tuple[float, float]:
        w, h = self.size
        return (w - 1) / 2.0, (h - 1) / 2.0

    def point(self, s: float, d: float, up: float, k: int) -> tuple[float, float, float]:
        """Camera coordinates (x right, y down, z ahead) of the point at road (s, d), ``up`` m
        above the road, in frame k."""
        wx, wz = _world(s, d, self.curvature)
        rx, rz = wx - self.x[k], wz - self.z[k]
        c, sn = math.cos(self.heading[k]), math.sin(self.heading[k])
        x_e, z_e = c * rx - sn * rz, sn * rx + c * rz
        y_e = self.height - up
        cp, sp = math.cos(self.pitch[k]), math.sin(self.pitch[k])
        return x_e, y_e * cp - z_e * sp, y_e * sp + z_e * cp

    def box(self, s: float, d: float, bottom: float, top: float, k: int):
        """(x, z) of an upright box's base and the image rows of its bottom and top, or None
        when it is not in front of us."""
        x, yb, z = self.point(s, d, bottom, k)
        _, yt, zt = self.point(s, d, top, k)
        if min(z, zt) < self.near:
            return None
        _, cy = self.center
        return x, z, cy + self.f * yb / z, cy + self.f * yt / zt


def _ground(camera: _Camera, k: int, look: _Look, pyramid) -> np.ndarray:
    """Sky and road of frame k: each pixel's ray hits the ground plane (or the sky)."""
    w, h = camera.size
    cx, cy = camera.center
    ray_x = np.broadcast_to((np.arange(w) - cx)[None, :] / camera.f, (h, w))
    rows = np.arange(h, dtype=np.float64)[:, None]
    ray_y = np.broadcast_to((rows - cy) / camera.f, (h, w))
    cp, sp = math.cos(camera.pitch[k]), math.sin(camera.pitch[k])
    down = ray_y * cp + sp            # the ray in our (level) frame: down and ahead
    ahead = -ray_y * sp + cp
    ground = down > 1e-4
    scale = np.where(ground, camera.height / np.where(ground, down, 1.0), 0.0)
    gx, gz = ray_x * scale, ahead * scale
    distance = np.hypot(gx, gz)
    c, sn = math.cos(camera.heading[k]), math.sin(camera.heading[k])
    wx = camera.x[k] + c * gx + sn * gz
    wz = camera.z[k] - sn * gx + c * gz
    s_road, d_road = road_coordinates(wx, wz, camera.curvature)
    foot_d = np.abs(np.gradient(d_road, axis=1)) + np.abs(np.gradient(d_road, axis=0)) + 1e-4
    foot_s = np.abs(np.gradient(s_road, axis=1)) + np.abs(np.gradient(s_road, axis=0)) + 1e-4

    lod = np.log2(np.maximum(foot_d, foot_s) / _TEXEL)
    fine = _mip_sample(pyramid, wx / _TEXEL, wz / _TEXEL, lod)
    coarse = _mip_sample(pyramid, wx / (8 * _TEXEL) + 97.0, wz / (8 * _TEXEL), lod - 3.0)
    asphalt = look.asphalt + 14.0 * fine + 8.0 * coarse
    verge = look.verge + 18.0 * fine + 22.0 * coarse
    surface = verge + _band(d_road, -_ROAD_HALF, _ROAD_HALF, foot_d) * (asphalt - verge)
    dash = _band(np.mod(s_road, _DASH_PERIOD), 0.0, _DASH_PERIOD * _DASH_DUTY, foot_s)
    marks = np.zeros_like(surface)
    for line in _LANE_LINES:
        marks = np.maximum(marks, dash * _band(d_road, line - _LINE_WIDTH / 2,
                                               line + _LINE_WIDTH / 2, foot_d))
    for edge in (-_ROAD_HALF + 0.1, _ROAD_HALF - 0.1):
        marks = np.maximum(marks, _band(d_road, edge - _EDGE_WIDTH / 2, edge + _EDGE_WIDTH / 2,
                                        foot_d))
    surface += marks * (look.marking - surface)
    surface = _haze(look, surface * _light(look, gx, gz, distance), distance)
    horizon = cy - camera.f * math.tan(camera.pitch[k])
    sky = look.sky_top + (look.sky_horizon - look.sky_top) * np.clip(
        1.0 - (horizon - rows) / (0.6 * h), 0.0, 1.0)
    below = np.clip(rows + 0.5 - horizon, 0.0, 1.0)
    return sky * (1.0 - below) + np.where(ground, surface, look.haze) * below


def _draw_boxes(image: np.ndarray, camera: _Camera, k: int, look: _Look, boxes) -> None:
    """Draw upright boxes (s, d, shape, width, bottom, top, albedo, vehicle) far to near, and at
    night the vehicles' lamps."""
    cx, _ = camera.center
    drawn = []
    for s, d, shape, width, bottom, top, albedo, vehicle in boxes:
        if -30.0 < s - camera.s[k] < 220.0:
            seen = camera.box(s, d, bottom, top, k)
            if seen is not None and seen[2] > seen[3]:
                drawn.append((seen, shape, width, top - bottom, albedo, vehicle))
    drawn.sort(key=lambda b: -b[0][1])
    lamps = []
    for (x, z, v_bottom, v_top), shape, width, tall, albedo, vehicle in drawn:
        u = cx + camera.f * x / z
        v, height_px, width_px = (v_top + v_bottom) / 2, v_bottom - v_top, camera.f * width / z
        level = float(_haze(look, 255.0 * albedo * float(_light(look, x, z, z)), z))
        if shape == "disk":
            paint_disk(image, u, v, height_px / 2 * width / tall, level)
        else:
            paint_object(image, shape, u, v, height_px, level, width_px / height_px)
        if vehicle is not None and look.night:
            lamps += [(lamp, width_px, vehicle.speed < 0)
                      for lamp in car_lamps(u, v, width_px, height_px)]
    for (x, y), width_px, oncoming in lamps:  # head lamps glare, tail lamps glow
        sigma = max(0.6, 0.04 * width_px) * (3.0 if oncoming else 1.0)
        _glow(image, x, y, sigma, 255.0 if oncoming else 170.0)


def _target_label(camera: _Camera, vehicle: Vehicle, s_v: np.ndarray, d_v: np.ndarray,
                  fps: float, near: float = _NEAR):
    """Image centre (of the near face), image height and time to contact of a vehicle at road
    positions (``s_v``, ``d_v``) frame by frame."""
    cx, cy = camera.center
    f = camera.f
    x, yb, z = np.array([camera.point(s, d, 0.0, k)
                         for k, (s, d) in enumerate(zip(s_v, d_v))]).T
    _, yt, zt = np.array([camera.point(s, d, vehicle.height, k)
                          for k, (s, d) in enumerate(zip(s_v, d_v))]).T
    seen = np.minimum(z, zt) >= near  # NaN once it is beside or behind us
    with np.errstate(divide="ignore", invalid="ignore"):
        track = np.where(seen[:, None],
                         np.stack([cx + f * x / z, cy + f * (yb / z + yt / zt) / 2], axis=1),
                         np.nan)
        size = np.where(seen, f * (yb / z - yt / zt), np.nan)
    # closing speed over the step into each frame (out of it for the first frame)
    closing = np.empty(len(z))
    closing[1:] = (z[:-1] - z[1:]) * fps
    closing[0] = closing[1] if len(z) > 1 else 0.0
    moving_in = seen & (closing > 0.05)
    ttc = np.where(moving_in, z / np.where(moving_in, closing, 1.0), np.nan)
    return track, size, ttc


def driving_scene(*, name: str = "driving", size: tuple[int, int] = (192, 128),
                  fps: float = 20.0, frames: int = 90, speed: float = 12.0,
                  curvature: float = 0.0, bumps_deg: float = 0.0, night: bool = False,
                  vehicles: Sequence[Vehicle] = (), target: int | None = None, onset: int = 0,
                  roadside: float = 1.0, hfov_deg: float = 70.0, camera_height: float = 1.3,
                  pitch_deg: float = 2.0, front: float = 2.0, tail: int = 2, seed: int = 0,
                  brake: float = 0.0, brake_frame: int = 0,
                  category: Sequence[str] = (), twin: str | None = None) -> Scene:
    """Render a labelled driving clip.

    Parameters
    ----------
    name : str
    size : (width, height)
    fps : float
    frames : int
        Length of the clip; a collision ends it ``tail`` frames after contact.
    speed : float
        Our speed, m/s.
    curvature : float
        Of the road, 1/m (positive bends right); our yaw rate is ``speed * curvature``.
    bumps_deg : float
        Amplitude of the pitch oscillation (1.3 Hz, with half as much at 3.1 Hz), degrees.
    night : bool
        A dark scene lit by our headlights; other vehicles show their lamps.
    vehicles : sequence of Vehicle
    target : int, optional
        Index of the labelled vehicle in ``vehicles``.
    onset : int
        Frame the target's approach starts (its braking, or 0 for one closing in from the start).
    roadside : float
        Density of roadside objects (1: one every 11 m on average; 0: none).
    hfov_deg, camera_height, pitch_deg : float
        Horizontal field of view, height above the road (m), downward pitch.
    front : float
        Metres from the camera to our front bumper.
    tail : int
    seed : int
        Of the textures and the roadside.
    brake : float
        Our deceleration from ``brake_frame`` until we stand, m/s^2 (0: none): a robot
        stopping short of something (as a :class:`Vehicle`'s ``brake``). ``bumps_deg`` go on
        while we stand (they follow time, not distance).
    brake_frame : int
    category : sequence of str
    twin : str, optional

    Returns
    -------
    Scene

    Raises
    ------
    ValueError
        For a target index out of range, a size below 32x32, or a negative ``brake`` or
        ``brake_frame``.
    """
    w, h = size
    _check_braking(brake, brake_frame)
    if w < 32 or h < 32:
        raise ValueError(f"scene size must be at least 32x32, got {w}x{h}")
    if target is not None and not 0 <= target < len(vehicles):
        raise ValueError(f"target {target} is not one of the {len(vehicles)} vehicles")
    look = _NIGHT if night else _DAY
    f = (w / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
    # the target's contact ends the clip and stops every motion (the crash)
    t = np.arange(frames, dtype=np.float64)

    def ego_travelled(t: np.ndarray) -> np.ndarray:
        # without braking exactly as before (the suite's drives stay bit-identical)
        if brake <= 0:
            return speed * t / fps
        return Vehicle(0.0, 0.0, speed, brake=brake, brake_frame=brake_frame).travelled(t, fps)

    contact = None
    if target is not None:
        vehicle = vehicles[target]
        gap = vehicle.distance + vehicle.travelled(t, fps) - ego_travelled(t)
        reached = np.flatnonzero(gap <= front)  # our bumper at its near face
        if reached.size and abs(vehicle.lateral(reached[0], fps)) < (vehicle.width
                                                                     + _EGO_WIDTH) / 2:
            contact = int(reached[0])
        if contact is not None:
            frames = min(frames, contact + tail + 1)
            t = np.minimum(t[:frames], contact)
    ego_s = ego_travelled(t)
    pitch = math.radians(pitch_deg) + math.radians(bumps_deg) * (
        np.sin(2 * math.pi * 1.3 * t / fps) + 0.5 * np.sin(2 * math.pi * 3.1 * t / fps + 1.0))
    near = min(_NEAR, 0.5 * front)
    if contact is not None:  # the gap at contact can be a whole frame's travel under the bumper
        gap_at_contact = vehicles[target].distance + vehicles[target].travelled(
            np.array([contact]), fps)[0] - ego_travelled(np.array([float(contact)]))[0]
        near = max(0.02, min(near, 0.5 * gap_at_contact))
    camera = _Camera(size, f, camera_height, curvature, ego_s, *path_pose(ego_s, curvature),
                     pitch, near)
    vehicle_s = [v.distance + v.travelled(t, fps) for v in vehicles]
    vehicle_d = [v.lateral(t, fps) for v in vehicles]
    pyramid = _pyramid(seed)
    scenery = [(item["s"], item["d"], *box, None)
               for item in (_roadside(seed + 1, ego_s[-1] + 200.0, roadside) if roadside else [])
               for box in _billboards(item)]

    clip = np.empty((frames, h, w))
    for k in range(frames):
        image = _ground(camera, k, look, pyramid)
        traffic = [(s_v[k], d_v[k], v.shape, v.width, 0.0, v.height, v.albedo, v)
                   for v, s_v, d_v in zip(vehicles, vehicle_s, vehicle_d)]
        _draw_boxes(image, camera, k, look, scenery + traffic)
        clip[k] = image
    video = np.clip(np.rint(clip), 0, 255).astype(np.uint8)

    track = target_size = ttc = None
    if target is not None:
        track, target_size, ttc = _target_label(camera, vehicles[target], vehicle_s[target],
                                                vehicle_d[target], fps, near)
    collision = contact is not None
    params = dict(size=size, fps=fps, frames=frames, speed=speed, curvature=curvature,
                  bumps_deg=bumps_deg, night=night, vehicles=[asdict(v) for v in vehicles],
                  target=target, onset=onset, roadside=roadside, hfov_deg=hfov_deg,
                  camera_height=camera_height, pitch_deg=pitch_deg, front=front, seed=seed,
                  focal_px=round(f, 3))
    if brake > 0:  # only where used, so the other drives' params stay as they were
        params.update(brake=brake, brake_frame=brake_frame)
    return Scene(name=name, frames=video, fps=fps, collision=collision,
                 onset_frame=onset if collision else None,
                 contact_frame=contact, params=params,
                 center=tuple(float(c) for c in track[contact]) if collision else None,
                 track=track, target_size=target_size, ttc=ttc, category=tuple(category),
                 twin=twin)


def _glow(image: np.ndarray, cx: float, cy: float, sigma: float, amplitude: float) -> None:
    """Add a Gaussian spot of light in place (a lamp), within 3 sigma."""
    h, w = image.shape
    r = 3.0 * sigma
    rows = slice(max(int(cy - r), 0), min(int(cy + r) + 2, h))
    cols = slice(max(int(cx - r), 0), min(int(cx + r) + 2, w))
    if rows.start >= rows.stop or cols.start >= cols.stop:
        return
    y = np.arange(rows.start, rows.stop)[:, None] - cy
    x = np.arange(cols.start, cols.stop)[None, :] - cx
    image[rows, cols] += amplitude * np.exp(-(x ** 2 + y ** 2) / (2.0 * sigma ** 2))
