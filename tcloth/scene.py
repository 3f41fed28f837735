"""Scene: a plain description of particles, springs and forces (NumPy only, no Taichi).

Units are SI throughout: metres, kilograms, seconds, newtons. A ``Scene`` validates every
input when it is added, so that a ``Simulator`` built from it never sees bad data.
"""
import numpy as np

from . import builders
from .errors import SceneError
from .validate import as_int, as_per_item, as_points, as_rotation, as_scalar, as_vec3, fmt

SPRING_KINDS = ("structural", "shear", "flexion", "custom")
KIND_CODE = {name: code for code, name in enumerate(SPRING_KINDS)}


def wind_velocity(wind, t):
    """The wind velocity (3,) at time t of a ``Scene.wind`` dict (validated)."""
    f = wind["callable"]
    if f is None:
        return wind["velocity"] + wind["amplitude"] * np.sin(
            2 * np.pi * wind["frequency"] * t + wind["phase"])
    try:
        value = f(t)
    except Exception as e:
        raise SceneError(f"wind gust callable raised {type(e).__name__} at t = {t}: {e}") from e
    try:
        return as_vec3("wind gust callable's result", value)
    except SceneError as e:
        raise SceneError(f"{e} at t = {t}") from None


class Scene:
    """A plain description of a mass-spring system.

    Args:
        gravity: (3,) acceleration, m/s^2.
        air_drag: viscous drag coefficient c >= 0: force -c * v on every particle (N s/m).
    """

    def __init__(self, gravity=(0.0, -9.81, 0.0), air_drag=0.0):
        self.gravity = as_vec3("gravity", gravity)
        self.air_drag = as_scalar("air_drag", air_drag, minimum=0.0)
        self._x, self._v, self._m, self._pin = [], [], [], []
        self._pairs, self._ks, self._kd, self._rest, self._kind = [], [], [], [], []
        self._spring_keys = np.zeros(0, dtype=np.int64)
        self.num_particles = 0
        self.num_springs = 0
        self.cloths = []
        self.ropes = []
        self.colliders = []
        self.wind = None
        self.attraction = None
        self.strain_limit = None
        self.self_collision = None

    # -- particles -------------------------------------------------------------------------
    def add_particles(self, positions, mass=1.0, velocities=None, pinned=False):
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
    def add_springs(self, pairs, stiffness, damping=0.0, rest_length=None, kind="custom"):
        """Add M springs ``f_ij = -k_s (|x_ij| - l0) d_ij - k_d (v_ij . d_ij) d_ij``.

        Args:
            pairs: (M,2) particle ids. stiffness k_s (N/m) and damping k_d (N s/m): scalar
                or (M,), >= 0. rest_length: None (the current distance) or scalar/(M,), > 0.
            kind: "structural" | "shear" | "flexion" | "custom".
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
        if (length == 0).any():
            r = int(np.argmax(length == 0))
            raise SceneError(f"pairs[{r}] = {p[r].tolist()} joins two coincident particles "
                             "(zero-length spring: its direction is undefined)")
        rest = length if rest_length is None else \
            as_per_item("rest_length", rest_length, m, minimum=0.0, strict=True)
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

    def set_spring_parameters(self, kind, stiffness=None, damping=None):
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

    def mean_stiffness(self, kind=None):
        """The mean k_s (N/m) of the springs of one kind (None: of all springs), or None
        when there are none."""
        springs = self.springs
        ks = springs["stiffness"] if kind is None else \
            springs["stiffness"][springs["kind"] == KIND_CODE[kind]]
        return float(ks.mean()) if len(ks) else None

    # -- builders --------------------------------------------------------------------------
    def add_cloth(self, resolution=(32, 32), size=(1.0, 1.0), center=(0.0, 1.0, 0.0),
                  plane="xz", mass=0.2, structural=(1000.0, 0.05), shear=(200.0, 0.02),
                  flexion=(50.0, 0.01), pinned=None, rotation=None):
        """Add a Provot cloth: particles on a regular nx x ny grid.

        Args:
            resolution: (nx, ny) particles, each >= 2. size: (w, h) metres.
            center: grid centre. plane: "xz" (i along +x, j along +z, horizontal) or
                "xy" (i along +x, j along -y: row 0 is the top edge; hangs vertically).
            mass: total cloth mass (kg), spread evenly over the particles.
            structural, shear, flexion: (k_s, k_d) per family or None (absent).
                structural = 4-neighbours, shear = diagonals, flexion = 2 apart.
            pinned: list of (i, j) grid coordinates; None pins (0, 0) and (nx-1, 0).
            rotation: None, or a 3x3 rotation matrix turning the grid about its centre.
        Returns:
            Cloth.
        """
        return builders.add_cloth(self, resolution, size, center, plane, mass, structural,
                                  shear, flexion, pinned, rotation)

    def add_mesh_cloth(self, vertices, faces=None, mass=0.2, structural=(1000.0, 0.05),
                       shear=None, flexion=(50.0, 0.01), pinned=()):
        """Add a cloth made from a mesh: a particle at each vertex, springs from the faces.

        Springs: structural on every face edge; shear across both diagonals of each quad
        face (a triangle mesh has none); flexion between the two vertices opposite each
        interior edge (the usual mass-spring bending of triangle meshes; polygons are
        fanned into triangles from their first vertex for this), leaving out pairs that a
        structural or shear spring already joins. Rest lengths are the mesh's.
        Mass: ``mass`` spread by vertex area: each vertex gets an equal share of each
        adjacent face's area (a third of a triangle's, a quarter of a quad's).

        Args:
            vertices: (V,3) metres, or the path of an OBJ file (``tcloth.load_obj``) with
                faces None. faces: a list of faces, each 3 or more vertex ids (0-based).
            mass: total kg, spread by vertex area; or (V,) kg per vertex.
            structural, shear, flexion: (k_s, k_d) or None (absent).
            pinned: vertex ids to pin.
        A face repeating a vertex or of zero area, an edge shared by more than two faces
        (not manifold), or a vertex in no face raises SceneError; duplicate vertices are
        separate particles (a seam); a face joining two coincident ones has zero area.
        Returns:
            MeshCloth (particles (V,) in vertex order, triangles (T,3)).
        """
        return builders.add_mesh_cloth(self, vertices, faces, mass, structural, shear,
                                       flexion, pinned)

    def add_rope(self, start, end, segments, mass, stiffness, damping=0.0, pinned=("start",)):
        """Add a straight rope of ``segments`` springs from ``start`` to ``end``.

        Args:
            start, end: (3,) metres. segments: int >= 1. mass: total kg, spread evenly
            over segments+1 particles. stiffness, damping: per spring (N/m, N s/m).
            pinned: any of "start", "end".
        Returns:
            Rope.
        """
        return builders.add_rope(self, start, end, segments, mass, stiffness, damping, pinned)

    # -- colliders -------------------------------------------------------------------------
    def _add_collider(self, kind, friction, velocity, thickness, stiffness, damping,
                      stick_velocity, **shape):
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

    def add_sphere(self, center, radius, friction=0.0, velocity=(0.0, 0.0, 0.0),
                   thickness=0.005, stiffness=1000.0, damping=0.5, stick_velocity=1e-3):
        """Add a sphere collider (see tcloth.terms.colliders for the contact model).

        Args:
            center: (3,) m at t = 0; it moves with constant ``velocity`` (3,) m/s.
            radius: m, > 0. friction: Coulomb mu >= 0.
            thickness: contact offset (m, default 5 mm): particles rest this far out.
            stiffness: penalty k (N/m, default 1000). damping: normal damping as a ratio
                of critical for each particle (default 0.5). stick_velocity: friction
                regularisation speed eps (m/s, default 1e-3).
        Returns:
            dict describing the collider.
        """
        return self._add_collider("sphere", friction, velocity, thickness, stiffness, damping,
                                  stick_velocity, center=as_vec3("center", center),
                                  radius=as_scalar("radius", radius, minimum=0.0, strict=True))

    def add_plane(self, point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.0,
                  velocity=(0.0, 0.0, 0.0), thickness=0.005, stiffness=1000.0, damping=0.5,
                  stick_velocity=1e-3):
        """Add an infinite plane through ``point`` whose solid side is opposite ``normal``.

        Other arguments as for add_sphere.
        """
        n = as_vec3("normal", normal)
        length = np.linalg.norm(n)
        if length < 1e-12:
            raise SceneError(f"normal must be non-zero (got {n.tolist()})")
        return self._add_collider("plane", friction, velocity, thickness, stiffness, damping,
                                  stick_velocity, center=as_vec3("point", point),
                                  normal=n / length)

    def add_box(self, center, half_extents, rotation=None, friction=0.0,
                velocity=(0.0, 0.0, 0.0), thickness=0.005, stiffness=1000.0, damping=0.5,
                stick_velocity=1e-3):
        """Add a box: ``half_extents`` (3,) > 0 along its local axes, the columns of
        ``rotation`` (a 3x3 rotation matrix; None = axis-aligned).

        Other arguments as for add_sphere.
        """
        h = as_vec3("half_extents", half_extents)
        if (h <= 0).any():
            raise SceneError(f"half_extents must all be > 0 (got {h.tolist()})")
        r = as_rotation("rotation", rotation)
        return self._add_collider("box", friction, velocity, thickness, stiffness, damping,
                                  stick_velocity, center=as_vec3("center", center),
                                  half_extents=h, rotation=r)

    def add_cylinder(self, center, radius, half_height, rotation=None, friction=0.0,
                     velocity=(0.0, 0.0, 0.0), thickness=0.005, stiffness=1000.0, damping=0.5,
                     stick_velocity=1e-3):
        """Add a capped cylinder: ``radius`` and ``half_height`` (m, > 0) along its local
        y axis, the second column of ``rotation`` (None: vertical), centred at ``center``.

        Other arguments as for add_sphere.
        """
        r = as_rotation("rotation", rotation)
        return self._add_collider("cylinder", friction, velocity, thickness, stiffness,
                                  damping, stick_velocity, center=as_vec3("center", center),
                                  radius=as_scalar("radius", radius, minimum=0.0, strict=True),
                                  half_height=as_scalar("half_height", half_height,
                                                        minimum=0.0, strict=True),
                                  rotation=r)

    # -- wind, attraction, strain limiting ------------------------------------------------
    def set_wind(self, velocity=(0.0, 0.0, 0.0), drag=0.5, lift=0.0, tangential=0.0,
                 gust=None):
        """Quadratic wind on cloth triangles (Wejchert & Haumann 1991).

        On a triangle of area A and unit normal n, with relative velocity
        v_rel = wind(t) - (mean velocity of its particles), u = v_rel . n and its in-plane
        part v_t = v_rel - u n, the force is
            drag * A * u |u| n                 (pressure drag, normal)
          + tangential * A * |v_t| v_t         (skin friction, tangential)
          + lift * A * |u| v_t                 (lift: tangential, largest at 45 degrees,
                                                zero face-on and edge-on),
        split equally onto its three particles. drag carries the air density and the 1/2
        (kg/m^3): for air, 0.5 * 1.2 * C_d with C_d about 1 gives 0.6.

        Args:
            velocity: (3,) mean wind, m/s.
            drag, lift, tangential: coefficients >= 0, kg/m^3.
            gust: None; a dict(amplitude=(3,), frequency=Hz, phase=rad) adding
                amplitude * sin(2 pi frequency t + phase) in the kernel; or a callable
                t -> (3,) wind velocity evaluated once per force evaluation (velocity is
                then ignored). Neither recompiles kernels.
        """
        wind = {"velocity": as_vec3("velocity", velocity),
                "drag": as_scalar("drag", drag, minimum=0.0),
                "lift": as_scalar("lift", lift, minimum=0.0),
                "tangential": as_scalar("tangential", tangential, minimum=0.0),
                "amplitude": np.zeros(3), "frequency": 0.0, "phase": 0.0, "callable": None}
        if callable(gust):
            wind["callable"] = gust
            wind_velocity(wind, 0.0)
        elif isinstance(gust, dict):
            unknown = sorted(set(gust) - {"amplitude", "frequency", "phase"})
            if unknown:
                raise SceneError(f"gust has an unknown key {unknown[0]!r} "
                                 "(keys: amplitude, frequency, phase)")
            wind["amplitude"] = as_vec3("gust['amplitude']", gust.get("amplitude", (0, 0, 0)))
            wind["frequency"] = as_scalar("gust['frequency']", gust.get("frequency", 0.0), 0.0)
            wind["phase"] = as_scalar("gust['phase']", gust.get("phase", 0.0))
        elif gust is not None:
            raise SceneError(f"gust must be None, a dict or a callable t -> (3,) (got {gust!r})")
        self.wind = wind
        return wind

    def add_attraction(self, G, softening=0.0):
        """Inverse-square attraction between all particle pairs (O(n^2)):
        f_i = sum_j G m_i m_j (x_j - x_i) / (|x_j - x_i|^2 + softening^2)^(3/2), with
        potential -G m_i m_j / sqrt(r^2 + softening^2) reported as energy()["attraction"].

        Args: G (N m^2/kg^2) >= 0; softening (m) >= 0 (Plummer).
        """
        self.attraction = (as_scalar("G", G, minimum=0.0),
                           as_scalar("softening", softening, minimum=0.0))
        return self.attraction

    def limit_strain(self, max_stretch=0.1, iterations=20, kinds=("structural", "shear"),
                     springs=None):
        """Provot (1995) strain limiting, applied after every step.

        Limited springs longer than (1 + max_stretch) rest length are shortened by moving
        their ends (inverse-mass weighted: a pinned end stays put), ``iterations`` Jacobi
        passes in parallel; velocities get the same correction divided by dt.

        Args:
            max_stretch: > 0 (0.1 = 10 %). iterations: passes per step, >= 1.
            kinds: the spring kinds limited (default structural and shear).
            springs: None, or spring ids to limit instead of whole kinds.
        """
        if springs is None:
            if isinstance(kinds, str) or not kinds or any(k not in KIND_CODE for k in kinds):
                raise SceneError(f"kinds must be a non-empty tuple of {SPRING_KINDS} "
                                 f"(got {kinds!r})")
            ids = np.flatnonzero(np.isin(self.springs["kind"], [KIND_CODE[k] for k in kinds]))
        else:
            ids = np.asarray(springs)
            if ids.ndim != 1 or ids.dtype.kind not in "iu" or len(ids) == 0 or \
                    ids.min() < 0 or ids.max() >= self.num_springs:
                raise SceneError(f"springs must be a 1-D array of spring ids in "
                                 f"[0, {self.num_springs}) (got {fmt(springs)})")
        self.strain_limit = {"max_stretch": as_scalar("max_stretch", max_stretch, 0.0, strict=True),
                             "iterations": as_int("iterations", iterations, 1),
                             "springs": np.unique(ids)}
        return self.strain_limit

    def set_self_collision(self, thickness=0.005, stiffness=None, friction=0.0, damping=0.1,
                           stick_velocity=1e-3, skin=None):
        """Keep every cloth and rope out of itself and out of each other
        (``tcloth.terms.self_contact`` has the contact model).

        Contacts are point-triangle (a cloth or rope particle against a cloth triangle) and
        edge-edge (two cloth edges or rope segments), each a penalty k/2 (thickness - d)^2
        on their distance d below ``thickness``, with normal damping and Coulomb friction
        as the colliders have them. Pairs that touch by construction never repel: a
        particle and a triangle (or two edges) are skipped when they share a particle or
        when a particle of one is a mesh neighbour (joined by a triangle edge or a rope
        segment) of a particle of the other.

        Args:
            thickness: contact distance, m (default 5 mm). Keep it below the cloth's
                spacing (a flat grid cloth has no contact at rest below sqrt(2) spacing)
                and above the distance cloth moves in a step (a penalty sees only what
                ends a step within it).
            stiffness: penalty k, N/m; None (default): the mean stiffness of the scene's
                structural springs, so that a contact is as stiff as one structural spring
                and a dt stable without self-collision stays stable with it.
            friction: Coulomb mu >= 0 (default 0).
            damping: normal damping as a ratio of critical for the pair (default 0.1).
            stick_velocity: friction regularisation speed eps, m/s (default 1e-3).
            skin: the broad phase's margin, m (default: thickness): candidate pairs within
                thickness + skin are listed, and the list is rebuilt only after two
                particles may have moved relative to each other by more than the skin.
        Returns:
            dict of the settings (stiffness None until a Simulator resolves it).
        """
        t = as_scalar("thickness", thickness, minimum=0.0, strict=True)
        self.self_collision = {
            "thickness": t,
            "stiffness": None if stiffness is None else
            as_scalar("stiffness", stiffness, minimum=0.0, strict=True),
            "friction": as_scalar("friction", friction, minimum=0.0),
            "damping": as_scalar("damping", damping, minimum=0.0),
            "stick_velocity": as_scalar("stick_velocity", stick_velocity, minimum=0.0,
                                        strict=True),
            "skin": t if skin is None else as_scalar("skin", skin, minimum=0.0, strict=True)}
        return self.self_collision

    # -- concatenated views (read-only copies) ---------------------------------------------
    def _cat(self, parts, shape, dtype):
        return np.concatenate(parts) if parts else np.zeros(shape, dtype=dtype)

    @property
    def positions(self):
        """(N,3) initial positions, m."""
        return self._cat(self._x, (0, 3), np.float64)

    @property
    def velocities(self):
        """(N,3) initial velocities, m/s."""
        return self._cat(self._v, (0, 3), np.float64)

    @property
    def masses(self):
        """(N,) masses, kg."""
        return self._cat(self._m, (0,), np.float64)

    @property
    def pinned(self):
        """(N,) bool: True where the particle has inverse mass 0."""
        return self._cat(self._pin, (0,), bool)

    @property
    def springs(self):
        """dict of arrays over all M springs: pairs (M,2), stiffness, damping, rest_length,
        kind (codes into SPRING_KINDS)."""
        return {"pairs": self._cat(self._pairs, (0, 2), np.int64),
                "stiffness": self._cat(self._ks, (0,), np.float64),
                "damping": self._cat(self._kd, (0,), np.float64),
                "rest_length": self._cat(self._rest, (0,), np.float64),
                "kind": self._cat(self._kind, (0,), np.int32)}

    @property
    def triangles(self):
        """(T,3) particle ids of every cloth triangle, cloth by cloth."""
        return self._cat([c.triangles for c in self.cloths], (0, 3), np.int64)

    def spring_counts(self):
        """dict kind -> number of springs of that kind."""
        kinds = self.springs["kind"]
        return {name: int((kinds == code).sum()) for name, code in KIND_CODE.items()}
