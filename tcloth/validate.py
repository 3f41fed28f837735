"""Input checks shared by the scene description and the simulator: each returns the
value in a canonical form or raises ``SceneError`` naming the argument and the value."""
import numpy as np

from .errors import SceneError


def fmt(value):
    text = np.array2string(np.asarray(value), threshold=8, precision=6) \
        if np.ndim(value) else repr(value)
    return text if len(text) < 200 else text[:197] + "..."


def as_vec3(name, value):
    """A finite 3-vector as float64, or SceneError naming ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{name} must be a 3-vector of numbers (got {fmt(value)})") from None
    if arr.shape != (3,):
        raise SceneError(f"{name} must be a 3-vector, shape (3,) (got shape {arr.shape}: {fmt(value)})")
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{name} must be finite (got {fmt(value)})")
    return arr


def as_points(name, value):
    """A finite (N,3) float64 array with N >= 1."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{name} must be an (N,3) array of numbers (got {fmt(value)})") from None
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] == 0:
        raise SceneError(f"{name} must have shape (N,3) with N >= 1 (got shape {arr.shape})")
    bad = np.argwhere(~np.isfinite(arr))
    if len(bad):
        r, c = bad[0]
        raise SceneError(f"{name} must be finite (got {name}[{r},{c}] = {arr[r, c]})")
    return arr


def as_scalar(name, value, minimum=None, strict=False):
    """A finite float; ``minimum`` is inclusive unless ``strict``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{name} must be a number (got {fmt(value)})") from None
    if np.ndim(value) != 0:
        raise SceneError(f"{name} must be a scalar (got {fmt(value)})")
    if not np.isfinite(x):
        raise SceneError(f"{name} must be finite (got {x})")
    if minimum is not None and (x <= minimum if strict else x < minimum):
        raise SceneError(f"{name} must be {'>' if strict else '>='} {minimum} (got {x})")
    return x


def as_warp_weft(name, value, minimum=0.0, strict=False):
    """(warp, weft) floats from one number (both) or a pair, finite and bounded below
    (``minimum`` inclusive unless ``strict``)."""
    try:
        pair = np.ravel(np.asarray(value, dtype=np.float64)) if np.ndim(value) else \
            np.array([float(value)] * 2)
    except (TypeError, ValueError):
        pair = np.full(0, np.nan)             # not numbers: refused below
    low = pair <= minimum if strict else pair < minimum
    if pair.shape != (2,) or not np.all(np.isfinite(pair)) or np.any(low):
        raise SceneError(f"{name} must be a number {'>' if strict else '>='} {minimum:g} or a "
                         f"(warp, weft) pair of them (got {fmt(value)})")
    return float(pair[0]), float(pair[1])


def as_warp_weft_per(name, value, count, strict=False):
    """(count, 2) array of (warp, weft) pairs from one number or pair (for all) or a
    (count, 2) array (one each); ``as_warp_weft``'s bounds."""
    v = np.asarray(value, dtype=np.float64) if np.ndim(value) else value
    if np.ndim(v) == 2 and np.shape(v)[0] != count:
        raise SceneError(f"{name} must be one value or pair, or one pair each of {count} "
                         f"(got {fmt(value)})")
    return np.array([as_warp_weft(name, v[k] if np.ndim(v) == 2 else v, strict=strict)
                     for k in range(count)])


def as_per_item(name, value, n, minimum=None, strict=False):
    """A scalar broadcast to (n,), or an (n,) array; finite, bounded below."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{name} must be a number or an array of numbers (got {fmt(value)})") from None
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    elif arr.shape != (n,):
        raise SceneError(f"{name} must be a scalar or have shape ({n},) (got shape {arr.shape})")
    if minimum is None:
        bad = ~np.isfinite(arr)
        rule = "finite"
    else:
        below = arr <= minimum if strict else arr < minimum
        bad = ~np.isfinite(arr) | below
        rule = f"finite and {'>' if strict else '>='} {minimum}"
    if bad.any():
        k = int(np.argmax(bad))
        where = f"{name}[{k}]" if np.ndim(value) else name
        raise SceneError(f"{name} must be {rule} (got {where} = {arr[k]})")
    return arr


def as_index(name, value, n):
    """value as an int in [0, n), or SceneError naming ``name``."""
    i = as_int(name, value, 0)
    if i >= n:
        raise SceneError(f"{name} must be in [0, {n}) (got {value!r})")
    return i


def as_int(name, value, minimum):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise SceneError(f"{name} must be an integer (got {fmt(value)})")
    if value < minimum:
        raise SceneError(f"{name} must be >= {minimum} (got {value})")
    return int(value)


def as_spring_params(name, value):
    """A spring family's (k_s, k_d), or None when the family is absent."""
    if value is None:
        return None
    if np.ndim(value) != 1 or len(value) != 2:
        raise SceneError(f"{name} must be None or a pair (k_s, k_d) (got {fmt(value)})")
    return (as_scalar(f"{name}[0] (k_s)", value[0], minimum=0.0),
            as_scalar(f"{name}[1] (k_d)", value[1], minimum=0.0))


def as_rotation(name, value):
    """A 3x3 rotation matrix (orthonormal, determinant +1); None is the identity."""
    if value is None:
        return np.eye(3)
    try:
        r = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{name} must be a 3x3 matrix (got {fmt(value)})") from None
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise SceneError(f"{name} must be a finite 3x3 matrix (got {fmt(value)})")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise SceneError(f"{name} must be a rotation matrix: orthonormal with "
                         f"determinant +1 (got {fmt(r)}, det {np.linalg.det(r):.6g})")
    return r
