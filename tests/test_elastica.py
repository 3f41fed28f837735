"""``tcloth.testing.elastica``, the cantilever (Peirce, ASTM D1388) reference, against independent results:
linear and second-order beam theory, Peirce's formula, the strip's own inextensibility, moment
balance and differential equation, resolution, and the inversion of the chord angle; and
tools/elastica.py, its table on the command line, run as a user runs it."""
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.polynomial import Polynomial

from tcloth.testing import elastica

TOOL = Path(__file__).resolve().parents[1] / "tools" / "elastica.py"


def _second_order_coefficient():
    """c2 in y_tip / L = -(alpha / 8) (1 + c2 alpha^2 + O(alpha^4)), by expanding
    theta = alpha theta1 + alpha^3 theta3 in polynomials (c2 = -1/80)."""
    u = Polynomial([0.0, 1.0])
    theta1 = (1.0 - (1.0 - u) ** 3) / 6.0  # theta1'' = -(1 - u), theta1(0) = theta1'(1) = 0
    theta3 = ((1.0 - u) * theta1 ** 2 / 2.0).integ(lbnd=1.0).integ(lbnd=0.0)
    return 8.0 * (theta3 - theta1 ** 3 / 6.0).integ(lbnd=0.0)(1.0)


def _peirce_angle(alpha):
    """Chord angle in degrees from Peirce's formula alpha = 8 tan(theta) / cos(theta / 2)."""
    lo, hi = 0.0, 0.5 * math.pi
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if 8.0 * math.tan(mid) / math.cos(0.5 * mid) < alpha:
            lo = mid
        else:
            hi = mid
    return math.degrees(0.5 * (lo + hi))


def test_small_alpha_is_linear_beam_theory():
    """Tip deflection w L^4 / (8 B): y_tip / L -> -alpha / 8, chord angle -> atan(alpha / 8)."""
    x, y = elastica.tip(0.01)
    assert y == pytest.approx(-0.01 / 8.0, rel=1e-4)
    assert x == pytest.approx(1.0, abs=1e-5)
    assert elastica.chord_angle(0.01) == pytest.approx(math.degrees(math.atan(0.01 / 8.0)),
                                                       rel=1e-4)
    assert elastica.chord_angle(0.1) == pytest.approx(math.degrees(math.atan(0.1 / 8.0)),
                                                      rel=1e-3)


def test_second_order_correction():
    """The relative deviation from linear theory is c2 alpha^2 up to O(alpha^4)."""
    c2 = _second_order_coefficient()
    assert c2 == pytest.approx(-1.0 / 80.0, rel=1e-12)
    for alpha in (0.1, 0.3):
        _, y = elastica.tip(alpha)
        deviation = -y / (alpha / 8.0) - 1.0
        assert deviation == pytest.approx(c2 * alpha ** 2, abs=1e-3 * alpha ** 4)


def test_astm_angle_and_peirce_formula():
    """ASTM D1388's 41.5 degrees is the chord angle for a bending length c = (B / w)^(1/3)
    of L / 2, alpha = 8; Peirce's approximate formula overestimates the angle, by up to about
    2.6 degrees for alpha in [1, 16]."""
    assert abs(elastica.chord_angle(8.0) - 41.5) < 1.5
    rows = elastica.table(range(1, 17))
    angles = np.array([angle for _, angle, _, _ in rows])
    assert np.all(np.diff(angles) > 0.0)
    deviation = angles - [_peirce_angle(alpha) for alpha, _, _, _ in rows]
    assert np.all(deviation < 0.0)
    assert 2.5 < np.max(np.abs(deviation)) < 2.7


@pytest.mark.parametrize("alpha", [1.0, 8.0, 16.0])
def test_inextensible_in_balance_and_solving_the_equation(alpha):
    """Arc length 1; theta'(0) = alpha * integral of x du (the weight's moment about the clamp);
    theta'(1) = 0; theta'' = -alpha (1 - u) cos theta; tip() and chord_angle() agree."""
    u, theta, x, y = elastica.shape(alpha)
    h = u[1] - u[0]
    assert u[0] == 0.0 and u[-1] == 1.0 and np.allclose(np.diff(u), h)
    assert np.sum(np.hypot(np.diff(x), np.diff(y))) == pytest.approx(1.0, abs=1e-6)
    assert theta[0] == 0.0 and x[0] == 0.0 and y[0] == 0.0
    assert np.all(np.diff(theta) > 0.0) and theta[-1] < 0.5 * math.pi
    stencil = np.array([-25.0, 48.0, -36.0, 16.0, -3.0]) / (12.0 * h)  # 4th order, one-sided
    slope0, slope1 = stencil @ theta[:5], -stencil @ theta[::-1][:5]
    simpson = h / 3.0 * (x[0] + 4.0 * x[1:-1:2].sum() + 2.0 * x[2:-1:2].sum() + x[-1])
    assert slope0 == pytest.approx(alpha * simpson, abs=1e-6)
    assert abs(slope1) < 1e-6
    curvature_rate = (theta[2:] - 2.0 * theta[1:-1] + theta[:-2]) / h ** 2
    residual = curvature_rate + alpha * (1.0 - u[1:-1]) * np.cos(theta[1:-1])
    assert np.max(np.abs(residual)) < 1e-5
    assert elastica.tip(alpha) == (x[-1], y[-1])
    assert elastica.chord_angle(alpha) == pytest.approx(math.degrees(math.atan2(-y[-1], x[-1])),
                                                        abs=1e-12)


@pytest.mark.parametrize("alpha", [1.0, 8.0, 16.0])
def test_resolution_converged(alpha):
    fine = 4 * (elastica.SAMPLES - 1) + 1
    assert abs(elastica.chord_angle(alpha, fine) - elastica.chord_angle(alpha)) < 1e-8


def test_alpha_for_angle_inverts_chord_angle():
    alpha = elastica.alpha_for_angle(41.5)
    assert abs(elastica.chord_angle(alpha) - 41.5) < 1e-8
    assert alpha == pytest.approx(8.0, abs=0.01)
    assert elastica.alpha_for_angle(elastica.chord_angle(3.0)) == pytest.approx(3.0, rel=1e-8)


@pytest.mark.parametrize("alpha", [0.0, -1.0, float("nan"), float("inf")])
def test_rejects_bad_alpha(alpha):
    for func in (elastica.shape, elastica.tip, elastica.chord_angle):
        with pytest.raises(ValueError, match="alpha"):
            func(alpha)
    with pytest.raises(ValueError, match="alpha"):
        elastica.table([1.0, alpha])


@pytest.mark.parametrize("degrees", [0.0, -5.0, float("nan"), 90.0])
def test_rejects_bad_angle(degrees):
    with pytest.raises(ValueError, match="degrees"):
        elastica.alpha_for_angle(degrees)


def test_cli_prints_and_writes_csv(tmp_path):
    path = tmp_path / "cantilever.csv"
    lines = subprocess.run([sys.executable, str(TOOL), "--alphas", "1", "4", "--csv", str(path)],
                           capture_output=True, text=True, check=True).stdout.splitlines()
    assert len(lines) == 3 and "chord angle" in lines[0]
    header, *rows = path.read_text().splitlines()
    assert header.split(",") == ["alpha", "chord_angle_deg", "x_tip_over_L", "y_tip_over_L"]
    alpha, angle, x, y = map(float, rows[1].split(","))
    assert (alpha, angle, x, y) == (4.0, elastica.chord_angle(4.0), *elastica.tip(4.0))
