"""Scene: a plain description of particles, springs and forces (NumPy data; it makes no
Taichi fields).

Units are SI throughout: metres, kilograms, seconds, newtons. A ``Scene`` validates every
input when it is added, so that a ``Simulator`` built from it never sees bad data.
"""
from __future__ import annotations

from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike

from . import builders, meshcollider, seams
from .builders import unset
from ..errors import SceneError
from ..geometry.shapes import SHAPE_NAMES, SHAPES, collider_builder
from ..validate import as_per_item, as_points, as_scalar, as_vec3, fmt

SPRING_KINDS = ("structural", "shear", "flexion", "custom", "seam")
KIND_CODE = {name: code for code, name in enumerate(SPRING_KINDS)}
Spring = Tuple[float, float]        # a spring family's (stiffness N/m, damping N s/m)


class Scene:
    """A plain description of a mass-spring system.

    Particles, springs, cloths and ropes are added here, and colliders by one builder per
    shape (``add_sphere``, ``add_plane``, ... from ``shapes.SHAPES``); the optional features
    (``set_wind``, ``add_attraction``, ``set_pressure``, ``limit_strain``,
    ``set_self_collision``) are methods given by ``tcloth.features``, each defined in the
    feature's module there.

    Args:
        gravity: (3,) acceleration, m/s^2.
        air_drag: viscous drag coefficient c >= 0: force -c * v on every particle (N s/m),
            whatever its mass: a finer grid of the same cloth (lighter particles) is damped
            harder.
        air_damping: mass-proportional (Rayleigh) damping rate gamma >= 0: force
            -gamma * m_p * v on particle p (1/s). A body falls at the terminal speed
            g / gamma at any resolution. With both, particle p's coefficient is
            c + gamma * m_p (``drag_coefficients``).
    """

    def __init__(self, gravity: ArrayLike = (0.0, -9.81, 0.0), air_drag: float = 0.0,
                 air_damping: float = 0.0):
        self.gravity = as_vec3("gravity", gravity)
        self.air_drag = as_scalar("air_drag", air_drag, minimum=0.0)
        self.air_damping = as_scalar("air_damping", air_damping, minimum=0.0)
        self._x, self._v, self._m, self._pin = [], [], [], []
        self._pairs, self._ks, self._kd, self._rest, self._kind = [], [], [], [], []
        self._spring_keys = np.zeros(0, dtype=np.int64)
        self.num_particles = 0
        self.num_springs = 0
        self.cloths = []
        self.ropes = []
        self.colliders = []
        self.welds = []

    # -- particles -------------------------------------------------------------------------
    def add_particles(self, positions: ArrayLike, mass: ArrayLike = 1.0,
                      velocities: Optional[ArrayLike] = None,
                      pinned: ArrayLike = False) -> np.ndarray:
        """Add N particles.

        Args:
            positions: (N,3) metres. mass: scalar or (N,) kg, > 0.
            velocities: None (at rest) or (N,3) m/s.
            pinned: bool or (N,) bool; a pinned particle has inverse mass 0 and moves only
                with its own velocity (kinematic).
        Returns:
            (N,) int array of particle ids.
        """
        x = as_points("positions", positions)
        n = len(x)
        m = as_per_item("mass", mass, n, minimum=0.0, strict=True)
        v = np.zeros_like(x) if velocities is None else as_points("velocities", velocities)
        if v.shape != x.shape:
            raise SceneError(f"velocities must have shape {x.shape} like positions (got {v.shape})")
        pin = np.asarray(pinned)
        if pin.dtype != bool or pin.shape not in ((), (n,)):
            raise SceneError(f"pinned must be a bool or a ({n},) bool array (got {fmt(pinned)})")
        ids = self.num_particles + np.arange(n)
        self._x.append(x)
        self._v.append(v)
        self._m.append(m)
        self._pin.append(np.broadcast_to(pin, (n,)).copy())
        self.num_particles += n
        return ids

    # -- springs ---------------------------------------------------------------------------
    def add_springs(self, pairs: ArrayLike, stiffness: ArrayLike, damping: ArrayLike = 0.0,
                    rest_length: Optional[ArrayLike] = None,
                    kind: str = "custom") -> np.ndarray:
        """Add M springs ``f_ij = -k_s (|x_ij| - l0) d_ij - k_d (v_ij . d_ij) d_ij``.

        Args:
            pairs: (M,2) particle ids. stiffness k_s (N/m) and damping k_d (N s/m): scalar
                or (M,), >= 0. rest_length: None (the current distance) or scalar/(M,), > 0.
            kind: "structural" | "shear" | "flexion" | "custom" | "seam" (``sew``: rest
                length 0 and nothing else, its ends may coincide).
        Returns:
            (M,) int array of spring ids.
        """
        if kind not in KIND_CODE:
            raise SceneError(f"kind must be one of {SPRING_KINDS} (got {kind!r})")
        try:
            p = np.asarray(pairs)
        except (TypeError, ValueError):
            raise SceneError(f"pairs must be an (M,2) integer array (got {fmt(pairs)})") from None
        if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] == 0 or p.dtype.kind not in "iu":
            raise SceneError(f"pairs must be an (M,2) integer array with M >= 1 "
                             f"(got shape {p.shape}, dtype {p.dtype})")
        p = p.astype(np.int64)
        bad = (p < 0) | (p >= self.num_particles)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise SceneError(f"pairs[{r},{c}] = {p[r, c]} is out of range: the scene has "
                             f"{self.num_particles} particles")
        same = p[:, 0] == p[:, 1]
        if same.any():
            r = int(np.argmax(same))
            raise SceneError(f"pairs[{r}] = {p[r].tolist()} joins a particle to itself")
        m = len(p)
        ks = as_per_item("stiffness", stiffness, m, minimum=0.0)
        kd = as_per_item("damping", damping, m, minimum=0.0)
        x = self.positions
        length = np.linalg.norm(x[p[:, 0]] - x[p[:, 1]], axis=1)
        if kind == "seam":
            if rest_length is None or np.any(np.asarray(rest_length) != 0.0):
                raise SceneError(f"a seam spring has rest length 0 (got rest_length="
                                 f"{fmt(rest_length)})")
            rest_length, length = np.zeros(m), np.ones(m)
        elif rest_length is not None and np.any(np.asarray(rest_length) == 0.0):
            raise SceneError("rest_length 0 is a seam's: Scene.sew (got rest_length="
                             f"{fmt(rest_length)} for kind={kind!r})")
        if (length == 0).any():
            r = int(np.argmax(length == 0))
            raise SceneError(f"pairs[{r}] = {p[r].tolist()} joins two coincident particles "
                             "(zero-length spring: its direction is undefined)")
        rest = length if rest_length is None else \
            as_per_item("rest_length", rest_length, m, minimum=0.0, strict=kind != "seam")
        keys = np.minimum(p[:, 0], p[:, 1]) << 32 | np.maximum(p[:, 0], p[:, 1])
        uniq, first, counts = np.unique(keys, return_index=True, return_counts=True)
        if (counts > 1).any():
            k = np.flatnonzero(keys == uniq[counts > 1][0])
            raise SceneError(f"pairs has a duplicate spring: pairs[{k[0]}] = {p[k[0]].tolist()} "
                             f"and pairs[{k[1]}] = {p[k[1]].tolist()}")
        clash = np.isin(keys, self._spring_keys)
        if clash.any():
            r = int(np.argmax(clash))
            raise SceneError(f"pairs[{r}] = {p[r].tolist()} duplicates a spring already in the scene")
        sids = self.num_springs + np.arange(m)
        self._pairs.append(p)
        self._ks.append(ks)
        self._kd.append(kd)
        self._rest.append(rest)
        self._kind.append(np.full(m, KIND_CODE[kind], dtype=np.int32))
        self._spring_keys = np.concatenate([self._spring_keys, keys])
        self.num_springs += m
        return sids

    def sew(self, a: ArrayLike, b: ArrayLike, stiffness: float, damping: float = 0.0, *,
            weld: bool = False, weld_distance: Optional[float] = None) -> np.ndarray:
        """Sew particle a[i] to particle b[i]: seam springs of rest length 0 (kind "seam",
        force -k_s x_ij - k_d (v_ij . d) d) that pull each pair together; self-contact
        treats a pair as one particle, so a seam closes through the contact thickness
        (docs/sewing.md).

        Args:
            a: (K,) particle ids, a[i] sewn to b[i] (e.g. a panel's outline edges,
                ``tcloth.panel``; one of them reversed where the edges run opposite ways).
            b: (K,) particle ids, as ``a``.
            stiffness: k_s (N/m), scalar or (K,), >= 0.
            damping: k_d (N s/m), scalar or (K,), >= 0.
            weld: True merges each pair into one particle when it first comes within
                ``weld_distance``: from then on the two move as one, of their summed mass
                (``Simulator.welded()``, ``Simulator.triangles()``: the cloths' triangles
                with the pair's one particle). A particle welds to one other at most.
            weld_distance: m, > 0; None: the self-collision thickness where the scene
                has self-collision, else 1 mm.
        Returns:
            (K,) int array of the seam springs' ids.
        """
        return seams.sew(self, a, b, stiffness, damping, weld, weld_distance)

    def set_masses(self, masses: ArrayLike) -> None:
        """Every particle's mass (N,), kg, > 0 (a number: the same for all). What the scene
        gives per mass or as a ratio of critical follows it (the air damping, the
        membrane's and the colliders' damping); the springs' k_d (N s/m) stay."""
        masses = as_per_item("masses", masses, self.num_particles, minimum=0.0, strict=True)
        ends = np.cumsum([len(part) for part in self._m])[:-1]
        self._m = list(np.split(masses, ends))

    def set_spring_parameters(self, kind: str, stiffness: Optional[ArrayLike] = None,
                              damping: Optional[ArrayLike] = None) -> None:
        """Set the stiffness k_s (N/m, >= 0) and/or damping k_d (N s/m, >= 0) of every spring
        of one kind, and the cloths' family parameters with them (None: unchanged)."""
        if kind not in KIND_CODE:
            raise SceneError(f"kind must be one of {SPRING_KINDS} (got {kind!r})")
        code = KIND_CODE[kind]
        if not any((k == code).any() for k in self._kind):
            raise SceneError(f"the scene has no {kind} springs (kind={kind!r})")
        values = {}
        if stiffness is not None:
            values["stiffness"] = as_scalar("stiffness", stiffness, minimum=0.0)
        if damping is not None:
            values["damping"] = as_scalar("damping", damping, minimum=0.0)
        for key, parts in (("stiffness", self._ks), ("damping", self._kd)):
            if key in values:
                parts[:] = [np.where(kinds == code, values[key], part)
                            for kinds, part in zip(self._kind, parts)]
        for cloth in self.cloths:
            old = cloth.params.get(kind)
            if old is not None:
                cloth.params[kind] = (values.get("stiffness", old[0]),
                                      values.get("damping", old[1]))

    def mean_stiffness(self, kind: Optional[str] = None) -> Optional[float]:
        """The mean k_s (N/m) of the springs of one kind (None: of all springs), or None
        when there are none."""
        springs = self.springs
        ks = springs["stiffness"] if kind is None else \
            springs["stiffness"][springs["kind"] == KIND_CODE[kind]]
        return float(ks.mean()) if len(ks) else None

    # -- builders --------------------------------------------------------------------------
    def add_cloth(self, resolution: Tuple[int, int] = (32, 32),
                  size: Tuple[float, float] = (1.0, 1.0), center: ArrayLike = (0.0, 1.0, 0.0),
                  *, plane: str = "xz", mass: float = unset(0.2),
                  structural: Optional[Spring] = unset((1000.0, 0.05)),
                  shear: Optional[Spring] = unset((200.0, 0.02)),
                  flexion: Optional[Spring] = unset((50.0, 0.01)),
                  pinned: Optional[Sequence] = None, rotation: Optional[ArrayLike] = None,
                  fabric: Union[str, Any, None] = None) -> builders.Cloth:
        """Add a Provot cloth: particles on a regular nx x ny grid.

        Args:
            resolution: (nx, ny) particles, each >= 2. size: (w, h) metres.
            center: grid centre. plane: "xz" (i along +x, j along +z, horizontal) or
                "xy" (i along +x, j along -y: row 0 is the top edge; hangs vertically).
            mass: total cloth mass (kg), spread evenly over the particles (default 0.2).
            structural: (k_s, k_d) of the springs between 4-neighbours, or None (absent);
                default (1000, 0.05).
            shear: (k_s, k_d) of the diagonal springs, or None; default (200, 0.02).
            flexion: (k_s, k_d) of the springs between particles 2 apart, or None;
                default (50, 0.01).
            pinned: list of (i, j) grid coordinates; None pins (0, 0) and (nx-1, 0).
            rotation: None, or a 3x3 rotation matrix turning the grid about its centre.
            fabric: a ``tcloth.Fabric`` or a preset's name (``tcloth.scene.fabric.PRESETS``)
                instead of mass and springs: masses from its density, structural and shear
                springs from its stretch and shear stiffness (warp along i, weft along j),
                hinge bending (``set_bending``) from its rigidity, docs/fabric.md. Giving
                it with mass, structural, shear or flexion is a SceneError.
        Returns:
            Cloth.
        """
        return builders.add_cloth(self, resolution, size, center, plane, mass, structural,
                                  shear, flexion, pinned, rotation, fabric)

    def add_mesh_cloth(self, vertices: Union[ArrayLike, str], faces: Optional[ArrayLike] = None,
                       *, mass: float = unset(0.2),
                       structural: Optional[Spring] = unset((1000.0, 0.05)),
                       shear: Optional[Spring] = unset(None),
                       flexion: Optional[Spring] = unset((50.0, 0.01)),
                       pinned: ArrayLike = (), fabric: Union[str, Any, None] = None,
                       uvs: Optional[ArrayLike] = None,
                       prim: Optional[str] = None) -> builders.MeshCloth:
        """Add a cloth made from a mesh: a particle at each vertex, springs from the faces.

        Springs: structural on every face edge; shear across both diagonals of each quad
        face (a triangle mesh has none); flexion between the two vertices opposite each
        interior edge (the usual mass-spring bending of triangle meshes; polygons are
        fanned into triangles from their first vertex for this), leaving out pairs that a
        structural or shear spring already joins. Rest lengths are the mesh's.
        Mass: ``mass`` spread by vertex area: each vertex gets an equal share of each
        adjacent face's area (a third of a triangle's, a quarter of a quad's).

        Args:
            vertices: (V,3) metres, or the path of an OBJ file (``tcloth.load_obj``) or a
                USD file (.usd, .usda, .usdc, .usdz: ``tcloth.load_usd``; needs the extra
                ``usd``) with faces None; a file's texture coordinates come with it.
            faces: a list of faces, each 3 or more vertex ids (0-based).
            mass: total kg, spread by vertex area; or (V,) kg per vertex.
            structural: (k_s, k_d) of the edge springs, or None (absent).
            shear: (k_s, k_d) of the quads' diagonal springs, or None (absent).
            flexion: (k_s, k_d) of the springs across interior edges, or None (absent).
            pinned: vertex ids to pin.
            fabric: a ``tcloth.Fabric`` or a preset's name instead of mass and springs:
                masses from its density, no springs but a triangle membrane
                (``set_membrane``) with its stretch (warp along the world x axis) and
                shear, hinge bending from its rigidity (one number on a mesh),
                docs/fabric.md. Giving it with mass, structural, shear or flexion is a
                SceneError.
            uvs: texture coordinates of vertices and faces given as arrays (the cloth's
                ``uv``, exported as USD's ``primvars:st``): (V,2), one (u, v) a vertex, or
                one (n,2) array a face, a (u, v) for each of its n corners; None: none.
            prim: with a USD path, the Mesh prim's path in the stage (e.g.
                "/World/cloth"); None: the only Mesh, or the first in the stage's order.
        A face repeating a vertex or of zero area, an edge shared by more than two faces
        (not manifold), or a vertex in no face raises SceneError; duplicate vertices are
        separate particles (a seam); a face joining two coincident ones has zero area.
        Returns:
            MeshCloth (particles (V,) in vertex order, triangles (T,3)).
        """
        return builders.add_mesh_cloth(self, vertices, faces, mass, structural, shear,
                                       flexion, pinned, fabric, uvs, prim)

    def add_rope(self, start: ArrayLike, end: ArrayLike, segments: int, mass: float,
                 stiffness: float, damping: float = 0.0, *,
                 pinned: Sequence = ("start",)) -> builders.Rope:
        """Add a straight rope of ``segments`` springs from ``start`` to ``end``.

        Args:
            start: (3,) metres, the first particle.
            end: (3,) metres, the last particle.
            segments: int >= 1.
            mass: total kg, spread evenly over segments+1 particles.
            stiffness: per spring, N/m.
            damping: per spring, N s/m.
            pinned: any of "start", "end".
        Returns:
            Rope.
        """
        return builders.add_rope(self, start, end, segments, mass, stiffness, damping, pinned)

    # -- colliders -------------------------------------------------------------------------
    def add_mesh_collider(self, mesh, position=(0.0, 0.0, 0.0), rotation=None, scale=1.0, *,
                          friction=0.0, thickness=0.005, stiffness=1000.0, damping=0.5,
                          stick_velocity=1e-3, velocity=None, angular_velocity=None,
                          keyframes=None, deform=None, deform_fps=30.0, prim=None,
                          sdf="auto"):
        """Add a triangle mesh as an obstacle (docs/mesh_colliders.md).

        Args:
            mesh: an OBJ or USD path (``prim``: the Mesh prim in a USD file), or a pair
                (vertices (V,3), faces: F faces of 3 or more vertex ids, polygons fanned
                into triangles). A closed mesh, each edge in two faces wound alike, has an
                inside no particle may end in; an open one (a table top, a wall) is
                two-sided.
            position: with rotation and scale, its pose at t = 0: vertices scaled
                (scale: a number or three), turned (rotation: 3x3; None: none), moved by
                position (m).
            rotation: see position.
            scale: see position.
            friction: as add_sphere.
            thickness: as add_sphere.
            stiffness: as add_sphere.
            damping: as add_sphere.
            stick_velocity: as add_sphere.
            velocity: m/s, constant. One motion at most: velocity and angular_velocity,
                keyframes, or deform.
            angular_velocity: rad/s about ``position``, constant.
            keyframes: [(time, position, rotation), ...] interpolated.
            deform: a callable t -> (V,3) vertices (the mesh's own frame, before the
                pose) or a (frames, V, 3) array at deform_fps.
            sdf: "auto" (default): a closed rigid mesh with no part thinner than two of
                its cells (a cell is the thickness) is baked into a signed distance
                field, sampled per particle like the analytic shapes (no particle's path
                enters the mesh); any other keeps the certified pairs (no cloth edge
                crosses a mesh triangle either). True: the field, or a SceneError saying
                why not; False: the pairs. ``Simulator.contact_stats()["mesh_paths"]``
                says which each took and why (docs/mesh_colliders.md).
        Returns:
            dict describing the collider.
        """
        common = {"friction": friction, "thickness": as_scalar("thickness", thickness,
                                                                 minimum=0.0),
                  "stiffness": stiffness, "damping": damping, "stick_velocity": stick_velocity}
        return meshcollider.add_mesh_collider(self, mesh, position, rotation, scale, common,
                                              velocity, angular_velocity, keyframes, deform,
                                              deform_fps, prim, sdf)

    def add_collider(self, kind: str, shape: dict, *, friction: float = 0.0,
                     velocity: ArrayLike = (0.0, 0.0, 0.0), thickness: float = 0.005,
                     stiffness: float = 1000.0, damping: float = 0.5,
                     stick_velocity: float = 1e-3) -> dict:
        """Add a collider of shape ``kind`` whose own values, ``shape`` (a dict keyed as
        the collider dict stores them), its builder has checked; the builders
        ``add_sphere``, ``add_plane``, ``add_box``, ``add_cylinder`` and ``add_capsule``
        (one per entry of ``shapes.SHAPES``) call this. Other arguments as for add_sphere.
        Returns the collider dict."""
        if kind not in SHAPE_NAMES:
            raise SceneError(f"unknown collider kind {kind!r} (known: {', '.join(SHAPE_NAMES)})")
        c = {"kind": kind, **shape,
             "friction": as_scalar("friction", friction, minimum=0.0),
             "velocity": as_vec3("velocity", velocity),
             "thickness": as_scalar("thickness", thickness, minimum=0.0),
             "stiffness": as_scalar("stiffness", stiffness, minimum=0.0, strict=True),
             "damping": as_scalar("damping", damping, minimum=0.0),
             "stick_velocity": as_scalar("stick_velocity", stick_velocity, minimum=0.0,
                                         strict=True)}
        self.colliders.append(c)
        return c

    # -- concatenated views (read-only copies) ---------------------------------------------
    def _cat(self, parts, shape, dtype):
        return np.concatenate(parts) if parts else np.zeros(shape, dtype=dtype)

    @property
    def positions(self) -> np.ndarray:
        """(N,3) initial positions, m."""
        return self._cat(self._x, (0, 3), np.float64)

    @property
    def velocities(self) -> np.ndarray:
        """(N,3) initial velocities, m/s."""
        return self._cat(self._v, (0, 3), np.float64)

    @property
    def masses(self) -> np.ndarray:
        """(N,) masses, kg."""
        return self._cat(self._m, (0,), np.float64)

    def drag_coefficients(self) -> np.ndarray:
        """(N,) each particle's viscous drag coefficient c + gamma m_p (N s/m) from
        ``air_drag`` c and ``air_damping`` gamma."""
        return self.air_drag + self.air_damping * self.masses

    @property
    def pinned(self) -> np.ndarray:
        """(N,) bool: True where the particle has inverse mass 0."""
        return self._cat(self._pin, (0,), bool)

    @property
    def springs(self) -> dict:
        """dict of arrays over all M springs: pairs (M,2), stiffness, damping, rest_length,
        kind (codes into SPRING_KINDS)."""
        return {"pairs": self._cat(self._pairs, (0, 2), np.int64),
                "stiffness": self._cat(self._ks, (0,), np.float64),
                "damping": self._cat(self._kd, (0,), np.float64),
                "rest_length": self._cat(self._rest, (0,), np.float64),
                "kind": self._cat(self._kind, (0,), np.int32)}

    @property
    def triangles(self) -> np.ndarray:
        """(T,3) particle ids of every cloth triangle, cloth by cloth."""
        return self._cat([c.triangles for c in self.cloths], (0, 3), np.int64)

    def spring_counts(self) -> dict:
        """dict kind -> number of springs of that kind."""
        kinds = self.springs["kind"]
        return {name: int((kinds == code).sum()) for name, code in KIND_CODE.items()}


for _shape in SHAPES:
    if not _shape.meshed:
        setattr(Scene, f"add_{_shape.name}", collider_builder(_shape))
