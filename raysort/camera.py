"""The pinhole camera shared by generators."""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from raysort.params import number, vector3
from raysort.errors import ConfigError

__all__ = ["Camera"]


def _vec3(name, value):
    return tuple(float(x) for x in vector3(f"camera {name}", value))


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Parameters
    ----------
    eye, look_at, up : 3 floats
        position, a point it looks at, and the up direction.
    vfov : float
        vertical field of view in degrees (0 < vfov < 180).
    """

    eye: tuple
    look_at: tuple
    up: tuple = (0.0, 1.0, 0.0)
    vfov: float = 60.0

    def __post_init__(self):
        for name in ("eye", "look_at", "up"):
            object.__setattr__(self, name, _vec3(name, getattr(self, name)))
        object.__setattr__(self, "vfov", number("camera vfov (degrees)", self.vfov, 0, 180,
                                                 lo_open=True, hi_open=True))
        forward = np.subtract(self.look_at, self.eye)
        if np.linalg.norm(forward) == 0:
            raise ConfigError("camera eye and look_at must differ")
        if np.linalg.norm(np.cross(forward, self.up)) == 0:
            raise ConfigError("camera up must not be parallel to the view direction")

    def frame(self, width, height):
        """``(eye, forward, right, up)`` as read-only float32 arrays; ``right`` and ``up``
        span the image plane at distance 1 (scaled by the field of view and aspect).
        Computed once per camera and image size (a render asks once per tile)."""
        return _cached_frame(self, width, height)

    def _make_frame(self, width, height):
        forward = np.subtract(self.look_at, self.eye)
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        half = math.tan(math.radians(self.vfov) / 2)
        aspect = width / height
        out = tuple(np.asarray(v, dtype=np.float32) for v in
                    (self.eye, forward, right * half * aspect, up * half))
        for v in out:
            v.setflags(write=False)
        return out

    @classmethod
    def framing(cls, lo, hi, vfov=60.0):
        """A camera that sees the whole box [lo, hi] from its -z side, slightly above."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        centre, radius = (lo + hi) / 2, max(np.linalg.norm(hi - lo) / 2, 1e-6)
        dist = radius / math.sin(math.radians(vfov) / 2)
        eye = centre + dist * np.array([0.0, 0.35, -0.94])
        return cls(tuple(eye), tuple(centre), (0.0, 1.0, 0.0), vfov)


@functools.lru_cache(maxsize=64)
def _cached_frame(camera, width, height):
    return camera._make_frame(width, height)
