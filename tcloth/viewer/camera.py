"""The window's camera, which the mouse orbits and zooms, and picking a particle along the
ray under the cursor."""
import math

import numpy as np

from ..render.camera import Camera

PICK_ANGLE = 0.05           # rad: the farthest a picked particle may be from the cursor ray


class OrbitCamera:
    """A camera orbiting ``target``: eye, target, world up (y) and vertical fov (degrees)."""

    def __init__(self, camera):
        self.eye, self.target = camera.eye.copy(), camera.target.copy()
        self.fov = camera.fov

    @property
    def basis(self):
        """(forward, right, up) unit vectors."""
        c = Camera(self.eye, self.target, fov=self.fov)
        return c.forward, c.right, c.up

    def orbit(self, yaw, pitch):
        """Turn the eye about the target: yaw about world y, pitch about the camera's right
        (radians), never over the poles."""
        d = self.eye - self.target
        r = np.linalg.norm(d)
        azimuth = math.atan2(d[0], d[2]) - yaw
        elevation = min(max(math.asin(d[1] / r) + pitch, -1.5), 1.5)
        self.eye = self.target + r * np.array([math.cos(elevation) * math.sin(azimuth),
                                               math.sin(elevation),
                                               math.cos(elevation) * math.cos(azimuth)])

    def zoom(self, factor):
        """Scale the eye's distance to the target by factor (> 0)."""
        self.eye = self.target + factor * (self.eye - self.target)

    def ray(self, u, v, aspect):
        """(origin, unit direction) of the ray through window point (u, v), both in [0, 1]
        from the bottom left (GGUI's cursor), for width / height = aspect."""
        forward, right, up = self.basis
        half = math.tan(math.radians(self.fov) / 2)
        d = forward + (2 * u - 1) * half * aspect * right + (2 * v - 1) * half * up
        return self.eye.copy(), d / np.linalg.norm(d)


def pick(positions, candidates, origin, direction, max_angle=PICK_ANGLE):
    """The id among ``candidates`` whose direction from origin is closest to ``direction``
    (within max_angle radians, in front of the origin), nearest first on ties; or None."""
    if len(candidates) == 0:
        return None
    d = positions[candidates] - origin
    dist = np.linalg.norm(d, axis=1)
    cosine = d @ direction / np.maximum(dist, 1e-30)
    angle = np.arccos(np.clip(cosine, -1.0, 1.0))
    ok = angle <= max_angle
    if not ok.any():
        return None
    order = np.lexsort((dist[ok], np.round(angle[ok], 4)))
    return int(candidates[np.flatnonzero(ok)[order[0]]])
