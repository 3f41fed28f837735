"""Physical fabric (``tcloth.Fabric``): the masses, springs and bending it gives a cloth,
checked against textile tests: uniaxial stretch against the fabric's stretch stiffness,
and Peirce's cantilever against the inextensible elastica (``tcloth.testing.elastica``)."""
from pathlib import Path

import numpy as np
import pytest

import tcloth
from tcloth.scene.fabric import PRESETS

from tcloth.testing import cantilever, elastica


pytestmark = pytest.mark.usefixtures("f64")


def test_fabric_checks_its_parameters():
    with pytest.raises(tcloth.SceneError, match="density"):
        tcloth.Fabric(density=0.0, stretch=100.0, shear=10.0, bending=1e-5)
    with pytest.raises(tcloth.SceneError, match="stretch"):
        tcloth.Fabric(density=0.2, stretch=(100.0, -1.0), shear=10.0, bending=1e-5)
    with pytest.raises(tcloth.SceneError, match="bending"):
        tcloth.Fabric(density=0.2, stretch=100.0, shear=10.0, bending=-1e-5)
    with pytest.raises(tcloth.SceneError, match="damping"):
        tcloth.Fabric(density=0.2, stretch=100.0, shear=10.0, bending=1e-5, damping=-0.1)
    scene = tcloth.Scene()
    with pytest.raises(tcloth.SceneError, match="give either fabric or mass, flexion"):
        scene.add_cloth(fabric="denim", mass=0.3, flexion=None)
    with pytest.raises(tcloth.SceneError, match="one of"):
        scene.add_cloth(fabric="velvet")
    with pytest.raises(tcloth.SceneError, match="warp and weft"):
        vertices, tris = cantilever.equilateral_strip(4, 0.01, 3)
        scene.add_mesh_cloth(vertices, [tuple(t) for t in tris.tolist()], fabric="denim")
    assert scene.num_particles == 0


def test_grid_masses_and_springs_follow_the_fabric():
    """Masses sum to density x area, each a quarter of the cells around it; the interior
    membrane moduli of the springs give the fabric's uniaxial stiffnesses and shear."""
    fabric = PRESETS["denim"]
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(7, 5), size=(0.3, 0.2), fabric=fabric)
    dx, dy = cloth.spacing
    m = scene.masses.reshape(5, 7)
    assert m.sum() == pytest.approx(fabric.density * 0.3 * 0.2, rel=1e-12)
    assert m[2, 3] == pytest.approx(fabric.density * dx * dy, rel=1e-12)
    assert m[0, 0] == pytest.approx(fabric.density * dx * dy / 4, rel=1e-12)
    k1, k2, kd = fabric.grid_stiffness(dx, dy)
    L2 = dx * dx + dy * dy
    c11 = k1 * dx / dy + 2 * kd * dx ** 3 / (L2 * dy)
    c22 = k2 * dy / dx + 2 * kd * dy ** 3 / (L2 * dx)
    c12 = c66 = 2 * kd * dx * dy / L2
    assert c11 - c12 ** 2 / c22 == pytest.approx(fabric.stretch[0], rel=1e-12)
    assert c22 - c12 ** 2 / c11 == pytest.approx(fabric.stretch[1], rel=1e-12)
    assert c66 == pytest.approx(fabric.shear, rel=1e-12)
    ks = scene.springs["stiffness"][cloth.springs["structural"]]
    assert sorted(set(np.round(ks, 9))) == sorted({round(k1, 9), round(k1 / 2, 9),
                                                   round(k2, 9), round(k2 / 2, 9)})


def _pulled_strip(kind, cells, strain, fabric):
    """A strip along x, its two ends pinned, the right end moved by ``strain`` of the
    length; no gravity. Returns (sim, right end ids, width (m), middle ids (2, rows): two
    particles apart along x in its middle, for each row)."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    length, width = 0.3, 0.03
    if kind == "grid":
        rows = max(3, int(round(cells * width / length)) + 1)
        pins = [(i, j) for i in (0, cells) for j in range(rows)]
        cloth = scene.add_cloth(resolution=(cells + 1, rows), size=(length, width),
                                center=(0, 0, 0), pinned=pins, fabric=fabric)
        ids = cloth.particles
        width = cloth.spacing[1] * (rows - 1)
    else:
        spacing = length / cells
        rows = max(3, int(round(width / (spacing * np.sqrt(3) / 2)))) + 1
        vertices, tris = cantilever.equilateral_strip(cells - 2, spacing, rows)
        ids = np.arange(rows * cells).reshape(rows, cells)
        scene.add_mesh_cloth(vertices, [tuple(t) for t in tris.tolist()],
                             pinned=np.concatenate([ids[:, 0], ids[:, -1]]), fabric=fabric)
        width = (rows - 1) * spacing * np.sqrt(3) / 2
    left, right = ids[:, 0], ids[:, -1]
    x = scene.positions
    x[right, 0] += strain * (x[right, 0] - x[left, 0])
    sim = tcloth.Simulator(scene, integrator="backward_euler", dt=0.05)
    sim.set_state(positions=x)
    middle = ids[:, [ids.shape[1] // 2 - 1, ids.shape[1] // 2 + 1]].T
    return sim, right, width, middle


@pytest.mark.slow_cases("mesh-30", "grid-20")
@pytest.mark.parametrize("kind,cells", [("grid", 20), ("grid", 40), ("mesh", 30)])
def test_uniaxial_stretch_force_is_the_fabric_stiffness(kind, cells):
    """Pulled at 1 % strain, the strip's end force over its width and the strain of its
    middle is the fabric's warp stretch stiffness within 5 %."""
    fabric = tcloth.Fabric(density=0.2, stretch=(800.0, 300.0) if kind == "grid" else 800.0,
                           shear=20.0, bending=1e-6, damping=1.0)
    sim, right, width, middle = _pulled_strip(kind, cells, 0.01, fabric)
    sim.step(200)
    x = sim.positions()
    assert np.abs(sim.velocities()).max() < 1e-6          # at rest
    rest = sim.scene.positions
    strain = np.mean((x[middle[1], 0] - x[middle[0], 0])
                     / (rest[middle[1], 0] - rest[middle[0], 0])) - 1.0
    force = -sim.forces()[right, 0].sum()
    assert force / (width * strain) == pytest.approx(fabric.stretch[0], rel=0.05)


@pytest.mark.slow
def test_weft_stretch_is_the_fabric_weft_stiffness():
    """The same strip turned: pulled along j, the weft stiffness (a different number)."""
    fabric = tcloth.Fabric(density=0.2, stretch=(800.0, 300.0), shear=20.0, bending=1e-6,
                           damping=1.0)
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    pins = [(i, j) for i in range(4) for j in (0, 30)]
    cloth = scene.add_cloth(resolution=(4, 31), size=(0.03, 0.3), center=(0, 0, 0),
                            pinned=pins, fabric=fabric)
    ids = cloth.particles
    x = scene.positions
    x[ids[-1], 2] += 0.01 * 0.3
    sim = tcloth.Simulator(scene, integrator="backward_euler", dt=0.05)
    sim.set_state(positions=x)
    sim.step(200)
    y = sim.positions()
    a, b = ids[14], ids[16]
    strain = np.mean((y[b, 2] - y[a, 2]) / (x[b, 2] - x[a, 2])) - 1.0
    force = -sim.forces()[ids[-1], 2].sum()
    assert force / (0.03 * strain) == pytest.approx(fabric.stretch[1], rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("kind,cells", [("grid", 20), ("mesh", 20)])
def test_cantilever_follows_the_elastica(kind, cells):
    """Peirce's cantilever: the strip's static tip chord angle is the inextensible
    elastica's for alpha = w L^3 / B within 2 degrees at alpha = 2, 8 and 16."""
    for alpha in (2.0, 8.0, 16.0):
        angle, _ = cantilever.simulate(kind, alpha, cells)
        assert angle == pytest.approx(elastica.chord_angle(alpha), abs=2.0), alpha


@pytest.mark.slow
def test_flexion_springs_cannot_pass_the_cantilever():
    """The lecture's flexion springs, matched to B at the curvature 1/L, bend the strip
    almost the same whatever alpha (their energy is quartic in the angle: no stiffness at
    small curvature): far off the elastica at alpha = 2 and 16."""
    angles = [cantilever.simulate("flexion", alpha, 10)[0] for alpha in (2.0, 16.0)]
    assert abs(angles[1] - angles[0]) < 5.0
    assert abs(angles[0] - elastica.chord_angle(2.0)) > 10.0
    assert abs(angles[1] - elastica.chord_angle(16.0)) > 10.0


@pytest.mark.slow
def test_cantilever_converges_with_resolution():
    """The angle changes by less than 1 degree from one resolution to the next finer."""
    coarse, _ = cantilever.simulate("grid", 16.0, 10)
    fine, _ = cantilever.simulate("grid", 16.0, 20)
    assert abs(fine - coarse) < 1.0


@pytest.mark.slow
def test_render_takes_a_fabric_preset_by_name(tmp_path):
    """``tcloth render scenes/drape.py --set fabric=NAME`` builds the preset's drape; an
    unknown name is one clear line naming the presets."""
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[1]

    def render(*settings):
        return subprocess.run(
            [sys.executable, "-m", "tcloth", "render", str(root / "scenes" / "drape.py"),
             "--out", str(tmp_path / "frames"), "--frames", "2", "--width", "32",
             "--height", "24", "--supersample", "1", "--quiet", "--set", "rings=6",
             *[arg for s in settings for arg in ("--set", s)]],
            capture_output=True, text=True, timeout=600)

    done = render("fabric=fleece")
    assert done.returncode == 0, done.stderr
    assert len(list((tmp_path / "frames").glob("*.png"))) == 2
    refused = render("fabric=velvet")
    assert refused.returncode == 2 and "denim" in refused.stderr
    assert "Traceback" not in refused.stderr
