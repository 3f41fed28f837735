"""Reference solution of the cantilever bending test of fabric (Peirce's cantilever, ASTM D1388).

An inextensible strip of length L is clamped horizontally at s = 0 and free at s = L; it has a
weight w per unit area (N/m^2) and a bending rigidity B per unit width (N m). With theta(s) the
angle of the tangent below the horizontal and u = s / L in [0, 1], the balance of moments
B theta'(s) = M(s) = integral_s^L w (x(s') - x(s)) ds', differentiated once, gives

    theta''(u) = -alpha (1 - u) cos(theta(u)),   theta(0) = 0,   theta'(1) = 0,

with the single parameter alpha = w L^3 / B. The shape follows from x'(u) = cos theta,
y'(u) = -sin theta (y up), x(0) = y(0) = 0, in units of L; the tip's chord angle is
atan2(-y(1), x(1)), positive with the tip below the clamp.

Method: shooting on p = theta'(0), which lies in (0, alpha / 2] (theta'(0) is alpha times the
integral of (1 - u) cos theta). Classical RK4 with a fixed number of steps integrates
(theta, theta', x, y) together with the sensitivities (d theta/dp, d theta'/dp), and a Newton
iteration on the tip condition theta'(1) = 0 is kept inside a bracket, bisecting whenever a step
would leave it. The physical solution has 0 <= theta < pi/2 and theta' > 0 before the tip, so a
shot whose theta' turns negative before the tip counts as too low, and one whose theta reaches
pi/2 as too high; this keeps the bracket on that solution even for large alpha, where the
shooting function has other roots. The iteration stops at |theta'(1)| <= 1e-12 min(1, alpha)
(theta' scales with alpha when alpha is small) or when the Newton step reaches rounding level
in p. Shooting grows ill-conditioned as the hanging strip approaches the vertical
(pi/2 - theta falls to about 1e-7 at alpha = 700), so alpha is limited to ALPHA_MAX = 500, a
chord angle of about 86.1 degrees; there the default 2000 steps still give the chord angle to
about 1e-8 degrees (2e-13 at alpha = 8).

The chord angle increases with alpha from 0 towards 90 degrees; alpha_for_angle inverts it by
bisection, for turning a measured angle into B = w L^3 / alpha.
"""
import math

import numpy as np

SAMPLES = 2001
ALPHA_MAX = 500.0
TIP_TOL = 1e-12


def _check_alpha(alpha):
    """alpha as a float; ValueError unless it is finite, positive and at most ALPHA_MAX."""
    alpha = float(alpha)
    if not (math.isfinite(alpha) and 0.0 < alpha <= ALPHA_MAX):
        raise ValueError(f"alpha must be finite, > 0 and <= {ALPHA_MAX:g}, got {alpha!r}")
    return alpha


def _check_samples(samples):
    """samples as an int; ValueError unless it is at least 2."""
    if int(samples) != samples or samples < 2:
        raise ValueError(f"samples must be an integer >= 2, got {samples!r}")
    return int(samples)


def _shoot(alpha, p, n):
    """RK4 in n steps from theta(0) = 0, theta'(0) = p. Returns (theta'(1), d theta'(1)/dp,
    (theta, x, y) lists at u = i / n); theta'(1) is -inf (derivative nan, path partial) if
    theta' turns negative before the tip and +inf if theta reaches pi/2."""
    h = 1.0 / n
    th, om, x, y, z, zd = 0.0, p, 0.0, 0.0, 0.0, 1.0
    thetas, xs, ys = [th], [x], [y]
    for i in range(n):
        a1 = alpha * (1.0 - i * h)
        a2 = alpha * (1.0 - (i + 0.5) * h)
        a4 = alpha * (1.0 - (i + 1) * h)
        c1, s1 = math.cos(th), math.sin(th)
        k1o, k1d = -a1 * c1, a1 * s1 * z
        t2, o2 = th + 0.5 * h * om, om + 0.5 * h * k1o
        z2, d2 = z + 0.5 * h * zd, zd + 0.5 * h * k1d
        c2, s2 = math.cos(t2), math.sin(t2)
        k2o, k2d = -a2 * c2, a2 * s2 * z2
        t3, o3 = th + 0.5 * h * o2, om + 0.5 * h * k2o
        z3, d3 = z + 0.5 * h * d2, zd + 0.5 * h * k2d
        c3, s3 = math.cos(t3), math.sin(t3)
        k3o, k3d = -a2 * c3, a2 * s3 * z3
        t4, o4 = th + h * o3, om + h * k3o
        z4, d4 = z + h * d3, zd + h * k3d
        c4, s4 = math.cos(t4), math.sin(t4)
        k4o, k4d = -a4 * c4, a4 * s4 * z4
        th += h / 6.0 * (om + 2.0 * o2 + 2.0 * o3 + o4)
        om += h / 6.0 * (k1o + 2.0 * k2o + 2.0 * k3o + k4o)
        x += h / 6.0 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
        y -= h / 6.0 * (s1 + 2.0 * s2 + 2.0 * s3 + s4)
        z += h / 6.0 * (zd + 2.0 * d2 + 2.0 * d3 + d4)
        zd += h / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d)
        thetas.append(th)
        xs.append(x)
        ys.append(y)
        if th >= 0.5 * math.pi:
            return math.inf, math.nan, (thetas, xs, ys)
        if om < 0.0 and i < n - 1:
            return -math.inf, math.nan, (thetas, xs, ys)
    return om, zd, (thetas, xs, ys)


def _solve(alpha, n, guess=None):
    """(p, (theta, x, y) lists at u = i / n) of the solution for alpha, by bracketed Newton on
    p = theta'(0) in (0, alpha / 2], starting from `guess` if it lies there, else alpha / 2."""
    lo, hi = 0.0, 0.5 * alpha
    p = guess if guess is not None and lo < guess <= hi else hi
    for _ in range(200):
        f, dfdp, path = _shoot(alpha, p, n)
        step = -f / dfdp
        if abs(f) <= TIP_TOL * min(1.0, alpha) or abs(step) <= 4.0 * np.finfo(float).eps * p:
            return p, path
        if f < 0.0:
            lo = p
        else:
            hi = p
        p = p + step if lo < p + step < hi else 0.5 * (lo + hi)
    raise RuntimeError(f"shooting did not converge for alpha = {alpha!r}")


def shape(alpha, samples=SAMPLES):
    """(u, theta, x, y) of the strip for alpha = w L^3 / B at `samples` equally spaced points,
    lengths in units of L and theta in radians below the horizontal."""
    alpha, samples = _check_alpha(alpha), _check_samples(samples)
    _, (thetas, xs, ys) = _solve(alpha, samples - 1)
    return np.linspace(0.0, 1.0, samples), np.array(thetas), np.array(xs), np.array(ys)


def tip(alpha, samples=SAMPLES):
    """(x_tip, y_tip) of the free end in units of L; y_tip < 0 is below the clamp."""
    alpha, samples = _check_alpha(alpha), _check_samples(samples)
    _, (_, xs, ys) = _solve(alpha, samples - 1)
    return xs[-1], ys[-1]


def chord_angle(alpha, samples=SAMPLES):
    """Angle in degrees of the chord from the clamp to the tip, below the horizontal."""
    x, y = tip(alpha, samples)
    return math.degrees(math.atan2(-y, x))


def table(alphas):
    """[(alpha, chord angle in degrees, x_tip / L, y_tip / L)] for each alpha."""
    rows = []
    for alpha in alphas:
        x, y = tip(alpha)
        rows.append((float(alpha), math.degrees(math.atan2(-y, x)), x, y))
    return rows


def alpha_for_angle(degrees):
    """The alpha = w L^3 / B whose chord angle is `degrees`, by bisection; ValueError unless
    0 < degrees <= chord_angle(ALPHA_MAX) (about 86.1)."""
    degrees = float(degrees)
    if not (math.isfinite(degrees) and degrees > 0.0):
        raise ValueError(f"degrees must be finite and > 0, got {degrees!r}")
    ratio = 0.5  # theta'(0) / alpha of the last solution, to start the next shooting from

    def below(alpha):
        nonlocal ratio
        p, (_, xs, ys) = _solve(alpha, SAMPLES - 1, ratio * alpha)
        ratio = p / alpha
        return math.degrees(math.atan2(-ys[-1], xs[-1])) < degrees

    lo, hi = 0.0, 1.0
    while below(hi):
        if hi == ALPHA_MAX:
            raise ValueError(f"degrees must be <= chord_angle({ALPHA_MAX:g}) = "
                             f"{chord_angle(ALPHA_MAX):.4f}, got {degrees!r}")
        lo, hi = hi, min(2.0 * hi, ALPHA_MAX)
    while hi - lo > 1e-13 * hi:
        mid = 0.5 * (lo + hi)
        if below(mid):
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
