"""Scene construction: Provot spring counts and bad input."""
import numpy as np
import pytest

import tcloth
from tcloth import SceneError


@pytest.mark.parametrize("nx,ny", [(2, 2), (3, 5), (8, 6), (17, 4)])
def test_spring_counts_match_closed_forms(nx, ny):
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(nx, ny))
    counts = scene.spring_counts()
    assert counts["structural"] == (nx - 1) * ny + nx * (ny - 1)
    assert counts["shear"] == 2 * (nx - 1) * (ny - 1)
    assert counts["flexion"] == max(nx - 2, 0) * ny + nx * max(ny - 2, 0)
    assert cloth.particles.shape == (ny, nx)
    assert cloth.triangles.shape == (2 * (nx - 1) * (ny - 1), 3)


def test_cloth_rest_lengths_and_families():
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(5, 4), size=(2.0, 1.5), flexion=None)
    sp = scene.springs
    dx, dy = 2.0 / 4, 1.5 / 3
    rest = sp["rest_length"]
    assert set(np.round(rest[cloth.springs["structural"]], 12)) == {dx, dy}
    assert np.allclose(rest[cloth.springs["shear"]], np.hypot(dx, dy))
    assert len(cloth.springs["flexion"]) == 0


@pytest.mark.parametrize("plane,normal", [("xz", (0, 1, 0)), ("xy", (0, 0, 1))])
def test_cloth_grid_axes_and_triangle_orientation(plane, normal):
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(4, 3), size=(3.0, 2.0), center=(0, 1, 0), plane=plane)
    x = scene.positions
    p = cloth.particles
    assert np.allclose(x[p[0, 1]] - x[p[0, 0]], (1.0, 0, 0))
    step_j = x[p[1, 0]] - x[p[0, 0]]
    assert np.allclose(step_j, (0, 0, 1.0) if plane == "xz" else (0, -1.0, 0))
    a, b, c = (x[cloth.triangles[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    assert np.allclose(n / np.linalg.norm(n, axis=1, keepdims=True), normal)


def test_rope_builder():
    scene = tcloth.Scene()
    rope = scene.add_rope((0, 2, 0), (1, 2, 0), segments=10, mass=0.5, stiffness=100.0,
                          pinned=("start", "end"))
    assert len(rope.particles) == 11 and len(rope.springs) == 10
    assert np.isclose(scene.masses.sum(), 0.5)
    assert scene.pinned.tolist() == [True] + [False] * 9 + [True]
    assert np.allclose(scene.springs["rest_length"], 0.1)


def _scene2():
    s = tcloth.Scene()
    s.add_particles([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    return s


BAD = [
    ("positions", lambda: tcloth.Scene().add_particles(np.zeros((3, 2)))),
    ("positions", lambda: tcloth.Scene().add_particles([[0, np.nan, 0]])),
    ("positions", lambda: tcloth.Scene().add_particles([[0, np.inf, 0]])),
    ("mass", lambda: tcloth.Scene().add_particles([[0, 0, 0]], mass=0.0)),
    ("mass", lambda: tcloth.Scene().add_particles([[0, 0, 0], [1, 0, 0]], mass=[1.0, -2.0])),
    ("mass", lambda: tcloth.Scene().add_particles([[0, 0, 0]], mass=[1.0, 2.0])),
    ("velocities", lambda: tcloth.Scene().add_particles([[0, 0, 0]], velocities=[[0, 0]])),
    ("pinned", lambda: tcloth.Scene().add_particles([[0, 0, 0]], pinned="yes")),
    ("gravity", lambda: tcloth.Scene(gravity=(0, 1))),
    ("air_drag", lambda: tcloth.Scene(air_drag=-1.0)),
    ("stiffness", lambda: _scene2().add_springs([[0, 1]], stiffness=-5.0)),
    ("damping", lambda: _scene2().add_springs([[0, 1]], stiffness=5.0, damping=-1.0)),
    ("damping", lambda: _scene2().add_springs([[0, 1]], stiffness=5.0, damping=np.nan)),
    ("pairs", lambda: _scene2().add_springs([[0, 3]], stiffness=1.0)),
    ("pairs", lambda: _scene2().add_springs([[0, -1]], stiffness=1.0)),
    ("pairs", lambda: _scene2().add_springs([[1, 1]], stiffness=1.0)),
    ("pairs", lambda: _scene2().add_springs([[0, 1], [1, 0]], stiffness=1.0)),
    ("pairs", lambda: _scene2().add_springs([[0.5, 1]], stiffness=1.0)),
    ("pairs", lambda: _scene2().add_springs([0, 1], stiffness=1.0)),
    ("rest_length", lambda: _scene2().add_springs([[0, 1]], stiffness=1.0, rest_length=0.0)),
    ("kind", lambda: _scene2().add_springs([[0, 1]], stiffness=1.0, kind="elastic")),
    ("resolution", lambda: tcloth.Scene().add_cloth(resolution=(1, 4))),
    ("size", lambda: tcloth.Scene().add_cloth(size=(1.0, 0.0))),
    ("plane", lambda: tcloth.Scene().add_cloth(plane="yz")),
    ("structural", lambda: tcloth.Scene().add_cloth(structural=(-1.0, 0.0))),
    ("shear", lambda: tcloth.Scene().add_cloth(shear=(1.0,))),
    ("pinned", lambda: tcloth.Scene().add_cloth(resolution=(4, 4), pinned=[(4, 0)])),
    ("segments", lambda: tcloth.Scene().add_rope((0, 0, 0), (1, 0, 0), 0, 1.0, 10.0)),
    ("pinned", lambda: tcloth.Scene().add_rope((0, 0, 0), (1, 0, 0), 3, 1.0, 10.0, pinned="start")),
]


@pytest.mark.parametrize("argument,make", BAD, ids=[f"{a}-{k}" for k, (a, _) in enumerate(BAD)])
def test_bad_scene_input_names_the_argument(argument, make):
    with pytest.raises(SceneError, match=argument):
        make()


def test_spring_between_coincident_particles_is_refused():
    s = tcloth.Scene()
    s.add_particles([[0, 0, 0], [0, 0, 0]])
    with pytest.raises(SceneError, match="coincident"):
        s.add_springs([[0, 1]], stiffness=1.0)


def test_spring_duplicating_a_cloth_spring_is_refused():
    s = tcloth.Scene()
    cloth = s.add_cloth(resolution=(3, 3))
    with pytest.raises(SceneError, match="duplicates"):
        s.add_springs([[cloth.particles[0, 1], cloth.particles[0, 0]]], stiffness=1.0)


def test_scene_error_is_a_value_error():
    assert issubclass(SceneError, ValueError)
    assert issubclass(tcloth.InstabilityError, RuntimeError)
