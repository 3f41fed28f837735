"""A perspective camera for the off-screen renderer."""
import math

import numpy as np

from ..errors import SceneError


class Camera:
    """A perspective camera looking from ``eye`` at ``target``.

    Args:
        eye: (3,) metres, where the camera is.
        target: (3,) metres, the point it looks at.
        up: (3,) world up.
        fov: vertical field of view, degrees.
    """

    def __init__(self, eye, target, up=(0.0, 1.0, 0.0), fov=40.0):
        self.eye = np.asarray(eye, dtype=np.float64)
        self.target = np.asarray(target, dtype=np.float64)
        up = np.asarray(up, dtype=np.float64)
        fwd = self.target - self.eye
        if self.eye.shape != (3,) or fwd.shape != (3,) or not np.all(np.isfinite(fwd)) \
                or np.linalg.norm(fwd) == 0:
            raise SceneError(f"camera eye and target must be distinct finite 3-vectors "
                             f"(got eye={self.eye.tolist()}, target={self.target.tolist()})")
        if not 1.0 <= fov <= 170.0:
            raise SceneError(f"camera fov must be within [1, 170] degrees (got {fov})")
        self.fov = float(fov)
        self.forward = fwd / np.linalg.norm(fwd)
        right = np.cross(self.forward, up)
        if np.linalg.norm(right) < 1e-9:
            right = np.cross(self.forward, (1.0, 0.0, 0.0))
        self.right = right / np.linalg.norm(right)
        self.up = np.cross(self.right, self.forward)

    @classmethod
    def fit(cls, points, direction=(0.55, 0.45, 1.0), fov=40.0, margin=1.25):
        """A camera that sees all ``points`` (N,3) from ``direction``."""
        lo, hi = points.min(0), points.max(0)
        centre = 0.5 * (lo + hi)
        radius = max(0.5 * np.linalg.norm(hi - lo), 1e-3)
        d = np.asarray(direction, dtype=np.float64)
        dist = margin * radius / math.sin(math.radians(fov) / 2)
        return cls(centre + dist * d / np.linalg.norm(d), centre, fov=fov)

    @classmethod
    def from_config(cls, config, points):
        """None -> fit to points; a dict of Camera arguments; or a Camera."""
        if config is None:
            return cls.fit(points)
        if isinstance(config, Camera):
            return config
        if isinstance(config, dict):
            return cls(**config)
        raise SceneError(f"camera must be None, a dict or a tcloth.Camera (got {config!r})")
