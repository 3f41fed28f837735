"""What the backward run keeps of each forward step besides its state (``StepRecord``):
the self-contacts its solve read and the guard's projections, frozen (the active set and
the planes of the forward run), and whether the guard changed the step otherwise.

Self-contact. A step's self-contact force (symplectic Euler) or potential (backward
Euler) sums over the candidate rows of the contact stage's list as the step found it
(``contact/stage.py``: rebuilt only between steps). The adjoint differentiates that sum
over the same rows: the pairs are frozen, each pair's closest points, normal and depth
move with the positions (the derivative of the step the forward run took). A pair that
the list did not hold has no force in the forward step and none in its derivative.

The guard's projection. Where the solver's step would take a vertex pair across its
separating plane, the guard's Gauss-Seidel sweeps (``contact/projection.py``) move it
back onto the plane, x <- x + u (delta - J x) / w, and remove its approaching normal
velocity, v <- v - u (J v) / w (J x = n . (x_a - x_b); u the vertices' inverse masses
times their directions, w = J u): each correction an affine projection. With the planes
(n, delta: the step's start's) and the corrections that fired frozen, the guard is their
composition, and its transposed Jacobian is theirs in reverse order (``pull_back``); the
step's adjoint then takes the solver's end of the step, which the stage keeps
(``ContactStage.record``).

The colliders' sweep. A path the step's first sweep cut (``guard.sweep_colliders``) ends
where it meets the collider's offset surface, x0 + tau (x1 - x0) with phi(x) = the
thickness (or at x0), its velocity into the collider removed along the normal there:
the cuts (which particle, which collider, tau) are kept (``guard.SweepLog``), and the
backward run differentiates each one, tau by the implicit function theorem and the
normal through the surface's curvature (``sweep.SweepAdjoint``).

The fail-safe. Where the rounds left a pair too close, ``guard.truncate`` cuts each
vertex's path at KEEP of its way to the nearest dividing plane of its candidates, x0 + t
(x1 - x0), and scales its velocity by t: the cut vertices and the plane that stopped
each (the candidate and the vertex's slot) are kept (``guard.TruncationLog``) with the
motion they cut, and the backward run differentiates t through the plane (its normal at
x0, its place between the sides' extents and by their speeds: ``sweep.TruncationAdjoint``).

Where planes tie (a flat layer's do for a vertex above it), the log keeps one of them:
the gradient is one branch of the minimum, as reverse mode takes one of a max.

What is not differentiated. The later sweeps of a step whose projection pushed a
particle back into a collider, a particle cut twice in one sweep, the mesh colliders'
planes, the projection's Jacobi passes (on GPUs), a correction that a collider held to
its surface, and a step whose corrections overflow the log: at such a step the gradient
takes the solver's step, not the guard's change; ``Trajectory.gradient`` reports those
steps (``Result.guarded_steps``) and warns.
"""
import numpy as np

# the contact stage's counts (``contact.stage.STATS``) of the guard's changes that the
# gradient does not take, and of its projection's, which it does
NOT_TAKEN = ("obstacle_corrections", "obstacle_carried")
PROJECTED = "guard_corrections"
CUT = "collider_paths_cut"
FAILSAFE = "failsafe_vertices"


class StepRecord:
    """Per step of a run (``before(n)`` and ``after(n)`` around step n): the repelling
    self-contact rows its forward step read (``rows[n]``: ids (r, 4) and kinds (r,)), the
    guard's changes where it changed the step (``projections[n]``: the projection's
    corrections, the first collider sweep's cuts and the fail-safe's, each or None, and
    the solver's x1, v1), projective dynamics' self-contact projection's corrections
    (``corrections[n]``: ``ProjectionLog.entries``), each where ``keep`` is set; the
    steps whose guard changed them in a way the gradient does not take, or whose
    projection made more corrections than its log keeps (``guarded``), and those whose
    guard's changes it takes (``projected``)."""

    def __init__(self, model, contact, projection=None):
        self.stage = contact
        # the rows the solve reads (projective dynamics projects its self-contacts instead:
        # ``projection``, the self-contact term whose corrections are kept)
        self.self_contact = model.self_collision is not None and projection is None
        self.projection = projection
        self.rows, self.projections, self.corrections = {}, {}, {}
        self.guarded, self.projected = set(), set()
        self.keep = False
        self._counts = {}
        if self.stage is not None:
            self.stage.record(True)
        if projection is not None:
            projection.record(True)

    def start(self, keep):
        """A new run (its rows and projections kept where ``keep``: a segment of the
        backward run)."""
        self.rows, self.projections, self.corrections = {}, {}, {}
        self.guarded, self.projected = set(), set()
        self.keep = keep

    def before(self, n):
        if self.stage is None:
            return
        self._counts = dict(self.stage.stats)
        if self.keep and self.self_contact:
            cl, count = self.stage.candidates, self.stage.count
            repels = cl.repels.to_numpy()[:count].astype(bool)
            self.rows[n] = (cl.ids.to_numpy()[:count][repels],
                            cl.kind.to_numpy()[:count][repels])

    def after(self, n):
        if self.projection is not None:
            log = self.projection.log
            made = int(log.count[None])
            if made > log.capacity:     # more corrections than the log keeps
                self.guarded.add(n)
            elif self.keep and made:    # (the forward run reads the count alone)
                self.corrections[n] = log.entries()
        if self.stage is None:
            return
        stats = self.stage.stats
        projected = stats[PROJECTED] != self._counts[PROJECTED]
        cut = stats[CUT] - self._counts[CUT]
        failsafe = stats[FAILSAFE] - self._counts[FAILSAFE]
        if any(stats[key] != self._counts[key] for key in NOT_TAKEN):
            self.guarded.add(n)
        elif projected or cut or failsafe:
            entries = self._corrections() if projected else None
            cuts = self._cuts(cut) if cut else None
            truncation = self._truncation(failsafe) if failsafe else None
            if ((projected and entries is None) or (cut and cuts is None)
                    or (failsafe and truncation is None)):
                self.guarded.add(n)
                return
            self.projected.add(n)
            if self.keep:
                self.projections[n] = (entries, cuts, truncation,
                                       *(f.to_numpy().astype(np.float64)
                                         for f in self.stage.solved))

    def _corrections(self):
        """The projection's corrections of the step, or None where the gradient does not
        take them (Jacobi passes, an overflow of the log, a vertex a collider held)."""
        log = self.stage.log
        kept = int(log.count[None])
        entries = log.entries() if 0 < kept <= log.capacity else None
        return entries if entries is not None and along_normals(entries) else None

    def _truncation(self, cut):
        """The fail-safe's cuts of the step with the motion they cut ((particle, ids,
        kind, slot), x1, v1), one plane a vertex (where planes tie, one branch of the
        minimum, as reverse mode takes one of a max), or None where not every cut
        vertex found its plane again."""
        entries = self.stage.truncation_log.entries()
        if len(entries[0]) != cut:
            return None
        return entries, *(f.to_numpy().astype(np.float64) for f in self.stage.truncated)

    def _cuts(self, cut):
        """The first collider sweep's cuts of the step, or None where the step's sweeps
        cut more paths than it (later rounds' sweeps) or one particle twice."""
        entries = self.stage.sweep_log.entries()
        particles = entries[0]
        if len(particles) != cut or len(np.unique(particles)) != cut:
            return None
        return entries

    @property
    def nbytes(self):
        """The memory the rows and projections kept take."""
        rows = sum(ids.nbytes + kinds.nbytes for ids, kinds in self.rows.values())
        def size(part):         # (a tuple of arrays, tuples or None)
            if part is None or isinstance(part, np.ndarray):
                return 0 if part is None else part.nbytes
            return sum(size(a) for a in part)
        return rows + sum(size(changes) for changes in (*self.projections.values(),
                                                         *self.corrections.values()))


def pull_back(entries, inv_mass, x_bar, v_bar):
    """The adjoints of the guard's input (the solver's x1, v1) from those of its output,
    its corrections' in reverse order, of the inverse masses, and of their planes:
    (x_bar, v_bar, inv_mass_bar, (ids, kinds, n_bar, delta_bar)), the last for
    ``StepAdjoint.plane_vjp`` (the planes' dependence on the step's start). A correction
    x_a += m_a^-1 lam n, x_b -= m_b^-1 lam n with lam = (delta - n . g) / w (g = x_a - x_b
    before it, w = m_a^-1 + m_b^-1), y_a and y_b its output's adjoints, takes s = (m_a^-1
    n . y_a - m_b^-1 n . y_b) / w (lam's adjoint over w), passes -s n and s n to its
    input's, and adds to the adjoints of n: lam (m_a^-1 y_a - m_b^-1 y_b) - s g; of
    delta: s; of m_a^-1: lam (n . y_a - s); of m_b^-1: -lam (n . y_b + s). A velocity
    correction likewise with lam = -n . g_v / w (g_v = v_a - v_b before it), no delta."""
    pair, n, delta, _, _, w, stopped, ids, kinds, gap_x, gap_v = entries
    x_bar, v_bar = x_bar.copy(), v_bar.copy()
    n_bar, delta_bar = np.zeros_like(n), np.zeros(len(w))
    inv_bar = np.zeros(len(inv_mass))
    for k in range(len(w) - 1, -1, -1):
        a, b = pair[k]
        moves = ((x_bar, gap_x[k], True), (v_bar, gap_v[k], False))
        for y, g, positions in moves if stopped[k] else moves[:1]:
            lam = ((delta[k] if positions else 0.0) - n[k] @ g) / w[k]
            ya, yb = inv_mass[a] * y[a], inv_mass[b] * y[b]
            s = n[k] @ (ya - yb) / w[k]
            n_bar[k] += lam * (ya - yb) - s * g
            inv_bar[a] += lam * (n[k] @ y[a] - s)
            inv_bar[b] -= lam * (n[k] @ y[b] + s)
            if positions:
                delta_bar[k] += s
            y[a] -= s * n[k]
            y[b] += s * n[k]
    return x_bar, v_bar, inv_bar, (ids, kinds, n_bar, delta_bar)


def along_normals(entries):
    """Whether every correction moved its vertices along its normal (+n, -n): none was
    held by a collider, the case ``pull_back`` differentiates."""
    _, n, _, da, db = entries[:5]
    return bool(np.allclose(da, n, rtol=0, atol=1e-12) and
                np.allclose(db, -n, rtol=0, atol=1e-12))
