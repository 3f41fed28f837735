"""``tcloth.testing.crossings`` against a triangle-mesh obstacle (an independent count):
``count_obstacle_crossings`` (cloth edges through obstacle triangles, obstacle edges
through cloth triangles) and ``count_inside`` (points strictly inside a closed obstacle),
each checked against a brute force of its own kind: every pair's signed volumes, and the
generalized winding number summed over every triangle's solid angle.
Also ``tcloth.testing.meshes``'s sphere, which the mesh benchmark and its Newton peer share.
NumPy only, no Taichi."""
import numpy as np

from tcloth.testing.crossings import (count_inside, count_obstacle_crossings, inside_mask,
                                      obstacle_crossing_pairs, triangle_edges)
from tcloth.testing.meshes import sphere_frequency, sphere_mesh

CUBE = (np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float),
        np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]))
TETRA = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float),
         np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
OCTA = (np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                 float),
        np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                  [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]))


def strip(n, length, width, jitter, rng):
    """An n x 2 grid of particles along x (a cloth strip), jittered, and its triangles."""
    i, j = np.meshgrid(np.arange(n), np.arange(2))
    x = np.stack([i * length / (n - 1), np.zeros(i.shape), j * width], -1).reshape(-1, 3)
    x = x + rng.normal(0.0, jitter, x.shape)
    q = np.arange(n - 1)
    tri = np.concatenate([np.stack([q, q + n, q + 1], 1), np.stack([q + 1, q + n, q + n + 1], 1)])
    return x, tri


def volume(a, b, c, d):
    """Six times the signed volume of the tetrahedron abcd."""
    return np.linalg.det(np.array([b - a, c - a, d - a]))


def brute_pairs(xe, edges, xt, triangles):
    """Every (edge, triangle) pair whose segment pq passes through the triangle abc, by
    signed volumes: p and q strictly on either side of abc, and pq turning the same way
    (or not at all) around each of the triangle's edges."""
    hits = set()
    for e, (p, q) in enumerate(xe[edges]):
        for t, (a, b, c) in enumerate(xt[triangles]):
            if volume(a, b, c, p) * volume(a, b, c, q) >= 0:
                continue
            turns = np.array([volume(p, q, a, b), volume(p, q, b, c), volume(p, q, c, a)])
            if (turns >= 0).all() or (turns <= 0).all():
                hits.add((e, t))
    return hits


def winding_numbers(points, vertices, faces):
    """The generalized winding number of each point: the solid angles of all the
    triangles (Van Oosterom and Strackee's formula) over 4 pi."""
    r = vertices[faces][None, :, :, :] - points[:, None, None, :]
    n = np.linalg.norm(r, axis=3)
    a, b, c = r[:, :, 0], r[:, :, 1], r[:, :, 2]
    la, lb, lc = n[:, :, 0], n[:, :, 1], n[:, :, 2]
    det = np.einsum("pti,pti->pt", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("pti,pti->pt", a, b) * lc
           + np.einsum("pti,pti->pt", b, c) * la + np.einsum("pti,pti->pt", c, a) * lb)
    return (2.0 * np.arctan2(det, den)).sum(axis=1) / (4.0 * np.pi)


def placed(mesh, rng):
    """A mesh turned by a random rotation, scaled and moved."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return mesh[0] @ q.T * rng.uniform(0.5, 2.0) + rng.normal(0.0, 0.3, 3), mesh[1]


# -- crossings -------------------------------------------------------------------------------
def check_pairs(x, tri, v, f):
    cloth_through, obstacle_through = obstacle_crossing_pairs(x, tri, v, f)
    assert {tuple(p) for p in cloth_through} == brute_pairs(x, triangle_edges(tri), v, f)
    assert {tuple(p) for p in obstacle_through} == brute_pairs(v, triangle_edges(f), x, tri)
    total = count_obstacle_crossings(x, tri, v, f)
    assert total == len(cloth_through) + len(obstacle_through)
    return len(cloth_through), len(obstacle_through)


def test_a_strip_pushed_through_a_triangle():
    """A strip across a big triangle: its long edges pass through it (cloth edges through
    the obstacle); a small triangle poking up through the strip: its edges pass through
    the strip's triangles (obstacle edges through the cloth)."""
    rng = np.random.default_rng(1)
    x, tri = strip(8, 1.0, 0.1, 0.0, rng)
    wall = (np.array([[0.5, -1.0, -1.0], [0.5, 1.0, -1.0], [0.5, 0.0, 1.5]]),
            np.array([[0, 1, 2]]))
    through, _ = check_pairs(x, tri, *wall)
    assert through == 3         # at x = 0.5: the strip's two long edges and a diagonal
    spike = (np.array([[0.3, -0.5, 0.02], [0.305, 0.5, 0.03], [0.315, -0.5, 0.05]]),
             np.array([[0, 1, 2]]))
    through, poking = check_pairs(x, tri, *spike)
    assert through == 0 and poking == 2
    far = (spike[0] + [0.0, 5.0, 0.0], spike[1])
    assert count_obstacle_crossings(x, tri, *far) == 0


def test_random_strips_through_closed_meshes_match_a_brute_force():
    rng = np.random.default_rng(7)
    found = 0
    for k in range(8):
        v, f = placed((CUBE, TETRA, OCTA)[k % 3], rng)
        x, tri = strip(7, 2.5, 0.4, 0.05, rng)
        centre = v.mean(axis=0)
        x = (x - x.mean(axis=0)) @ np.linalg.qr(rng.normal(size=(3, 3)))[0].T + centre
        found += sum(check_pairs(x, tri, v, f))
    assert found > 10


def test_the_broad_phase_handles_big_triangles_beside_small_ones():
    """A floor of two 100 m triangles under a fine cloth that dips through it: the grid's
    cells are the cloth's size, and the floor costs the cells it shares with the cloth."""
    rng = np.random.default_rng(3)
    floor = (np.array([[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]], float),
             np.array([[0, 2, 1], [0, 3, 2]]))
    x, tri = strip(30, 1.0, 0.05, 0.0, rng)
    x[:, 1] = 0.02 * np.sin(np.arange(len(x)) % 30)     # alternately above and below
    through, _ = check_pairs(x, tri, *floor)
    assert through > 10


# -- inside ----------------------------------------------------------------------------------
def test_points_inside_closed_meshes_match_the_winding_number():
    rng = np.random.default_rng(11)
    for k in range(6):
        v, f = placed((CUBE, TETRA, OCTA)[k % 3], rng)
        points = v.mean(axis=0) + rng.normal(0.0, 0.4, (300, 3)) * np.ptp(v, axis=0)
        expected = winding_numbers(points, v, f) > 0.5
        assert 20 < expected.sum() < 280
        assert (inside_mask(points, v, f) == expected).all()
        assert count_inside(points, v, f) == expected.sum()
        # a winding reversed (normals inward) changes nothing: parity
        assert count_inside(points, v, f[:, ::-1]) == expected.sum()


def test_rays_through_edges_and_vertices_count_once():
    """Axis-aligned meshes and points whose ray along +x meets an edge or a vertex
    exactly: the cube's face diagonals (y = z), the octahedron's vertices (y = z = 0) and
    edges (z = 0); points in the planes of faces along x but off the mesh."""
    cube_v, cube_f = CUBE
    s = np.array([-0.5, 0.25, 0.5, 0.75, 1.5])
    points = np.array([[x, y, z] for x in s for y in s for z in s])
    on_diagonal = points[np.isclose(points[:, 1], points[:, 2])]
    expected = ((points > 0) & (points < 1)).all(axis=1)
    assert (inside_mask(points, cube_v, cube_f) == expected).all()
    assert inside_mask(on_diagonal, cube_v, cube_f).sum() == 3 * 3   # x, y = z in (0, 1)
    beside = np.array([[-1, 0, 0.5], [-1, 1, 0.5], [-1, 0.5, 0], [-1, 0, 0], [2, 1, 1]])
    assert count_inside(beside, cube_v, cube_f) == 0
    octa_v, octa_f = OCTA
    points = np.array([[-0.5, 0, 0], [-2, 0, 0], [0.2, 0, 0], [2, 0, 0], [-0.2, 0.5, 0],
                       [-3, 0.5, 0], [0, 0, 0.5], [-3, 0, 0.5], [-0.1, 0.3, 0.3]])
    expected = np.abs(points).sum(axis=1) < 1
    assert (inside_mask(points, octa_v, octa_f) == expected).all()
    assert expected.sum() == 5


def test_points_on_the_surface_are_not_inside():
    cube_v, cube_f = CUBE
    surface = np.array([[0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5], [1, 0.5, 0.5],
                        [0.5, 1, 0.25], [0.25, 0.25, 1], [0, 0, 0], [1, 1, 1], [0.5, 0, 0],
                        [0.5, 0.5, 1]])
    assert count_inside(surface, cube_v, cube_f) == 0
    assert count_inside(surface * 0.98 + 0.01, cube_v, cube_f) == len(surface)


# -- the shared sphere -----------------------------------------------------------------------
def test_sphere_mesh_is_closed_outward_and_the_closest_count():
    assert [20 * sphere_frequency(n) ** 2 for n in (1, 20, 100, 10000, 100000)] == \
        [20, 20, 80, 9680, 100820]
    v, f = sphere_mesh(0.35, 1280, center=(0.0, 0.35, 0.0))
    assert len(f) == 1280 and len(v) == 642
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    keys = directed[:, 0] * len(v) + directed[:, 1]
    assert len(np.unique(keys)) == len(keys)                    # each directed edge once
    assert set(keys) == set(directed[:, 1] * len(v) + directed[:, 0])  # and its opposite
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c - 3 * np.array([0, .35, 0]))
    assert (outward > 0).all()
    assert np.allclose(np.linalg.norm(v - [0, 0.35, 0], axis=1), 0.35)
    # inside against the analytic sphere, away from the chords (sagitta < 2 mm here)
    rng = np.random.default_rng(5)
    points = rng.uniform(-0.5, 0.5, (3000, 3)) + [0, 0.35, 0]
    r = np.linalg.norm(points - [0, 0.35, 0], axis=1)
    clear = np.abs(r - 0.35) > 0.003
    assert (inside_mask(points[clear], v, f) == (r[clear] < 0.35)).all()
