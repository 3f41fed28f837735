"""The guard's projection (``docs/contact.md``): each candidate pair's vertex pairs moved
onto the pair's separating plane (``guard.planes``: n . (x_a - x_b) >= delta) in proportion
to their inverse masses, and their approaching normal velocity removed (an inelastic
contact), equal and opposite momenta except where a collider holds a vertex this step
(it then moves only along the collider's surface; the collider takes the rest).

Two ways to sweep the candidates (``project``): Gauss-Seidel on one thread, as on CPUs (a
few sweeps, and the same numbers whatever the threads), and Jacobi passes, all candidates
at once, as on GPUs (where one thread over the candidates is one GPU thread): each
correction of a pass scaled by 1 / the larger of its two vertices' corrections in that
pass, the same on both, so the momenta stay equal and opposite and the corrections a vertex
receives sum to at most the largest of them; the velocities in passes of their own after
the positions, over the vertex pairs those moved (each row's ``touched`` bits).
"""
import taichi as ti

from .. import runtime
from ..runtime import serial
from .guard import SLACK
from .normals import VERTEX_PAIRS, kept_apart, plane_row, spans

STOP_ALONG = 0.5         # a stopped vertex moves along a normal only if this much is left
JACOBI = False           # the Jacobi passes on CPUs too (``project``)
LOG_CAPACITY = 1 << 14   # the corrections a step's ``Log`` keeps


@ti.data_oriented
class Log:
    """Gauss-Seidel's corrections of one step in their order, kept where ``on`` is set
    (a gradient's runs: ``tcloth/grad/frozen.py`` takes each as the projection it is):
    each one's vertices (``pair``), plane (``n``, ``delta``), directions ``da`` and ``db``,
    ``w`` and whether it removed approaching velocity (``stopped``): x_a += m_a^-1 lam da,
    x_b += m_b^-1 lam db with lam = (delta - n . (x_a - x_b)) / w, and where ``stopped`` v
    the same with lam = -n . (v_a - v_b) / w; the candidate's ``ids`` and ``kind`` (plus
    ``normals.SURFACE`` where its plane took the surfaces' normal), and x_a - x_b and
    v_a - v_b before it (``gap_x``, ``gap_v``). ``count`` counts them all; past
    ``capacity`` they are not kept."""

    def __init__(self, capacity=LOG_CAPACITY):
        real = runtime.real()
        self.capacity = capacity
        self.pair = ti.Vector.field(2, ti.i32, shape=capacity)
        self.ids = ti.Vector.field(4, ti.i32, shape=capacity)
        self.kind = ti.field(ti.i32, shape=capacity)
        self.n, self.da, self.db, self.gap_x, self.gap_v = (
            ti.Vector.field(3, real, shape=capacity) for _ in range(5))
        self.w, self.delta = (ti.field(real, shape=capacity) for _ in range(2))
        self.stopped = ti.field(ti.i32, shape=capacity)
        self.count = ti.field(ti.i32, shape=())
        self.on = ti.field(ti.i32, shape=())

    def entries(self):
        """The kept corrections as NumPy arrays: (pair, n, delta, da, db, w, stopped,
        ids, kind, gap_x, gap_v)."""
        k = min(int(self.count[None]), self.capacity)
        return tuple(f.to_numpy()[:k] for f in (
            self.pair, self.n, self.delta, self.da, self.db, self.w, self.stopped, self.ids,
            self.kind, self.gap_x, self.gap_v))


@ti.func
def _allowed(m, d):
    """Unit direction d less its part into a collider whose outward normal is m (m = 0:
    none); zero where less than STOP_ALONG of d's length along d is left (the vertex
    would slide far along the collider for a small gain along d)."""
    free = d - ti.min(d.dot(m), 0.0) * m
    return free if free.dot(d) >= STOP_ALONG else ti.Vector.zero(float, 3)


@ti.func
def _bit(a: ti.template(), b: ti.template()):
    """A row's bit for its vertex pair (a, b)."""
    return ti.static(1 << (4 * a + b))


@ti.func
def _violated(ids, a: ti.template(), b: ti.template(), n, delta, x1, v1, inv_mass, stop_normal,
              touched, velocity: ti.template()):
    """Whether vertices a and b of a candidate need a correction, with what ``_correct``
    needs: their directions da and db (+n for a, -n for b, less the part into a collider
    that holds the vertex this step: ``stop_normal`` is the collider's outward normal m where it
    stopped the vertex's path, else 0; the collider takes the rest), the sum w of their
    inverse masses along n and how much to take away: with ``velocity`` False, their
    distance along n short of delta (a correction where it is above SLACK delta); with
    ``velocity``, their approaching normal velocity -n . (v_a - v_b), where a position
    pass moved them (``touched``, the row's bits ``_bit``; a correction where it is above
    0)."""
    pa, pb = ids[a], ids[b]
    short = delta - n.dot(x1[pa] - x1[pb])
    da, db = _allowed(stop_normal[pa], n), _allowed(stop_normal[pb], -n)
    w = inv_mass[pa] * n.dot(da) - inv_mass[pb] * n.dot(db)
    need = short
    needed = short > SLACK * delta
    if ti.static(velocity):
        need = -n.dot(v1[pa] - v1[pb])
        needed = (touched & _bit(a, b)) != 0 and need > 0.0
    return needed and w > 0.0, da, db, w, need


@ti.func
def _count(ids, a: ti.template(), b: ti.template(), n, delta, x1, v1, inv_mass, stop_normal, hits,
           touched, velocity: ti.template()):
    """Count the vertex pair's correction on both its vertices (``_violated``)."""
    if _violated(ids, a, b, n, delta, x1, v1, inv_mass, stop_normal, touched, velocity)[0]:
        hits[ids[a]] += 1
        hits[ids[b]] += 1


@ti.func
def _correct(ids, a: ti.template(), b: ti.template(), n, delta, x1, v1, inv_mass, stop_normal,
             hits, dx, touched, velocity: ti.template()):
    """The move that takes vertices a and b of a candidate apart along n until
    n . (x_a - x_b) = delta (with ``velocity``: the impulse that removes their approaching
    normal velocity, an inelastic contact), in proportion to their inverse masses (equal
    and opposite momenta), scaled by 1 / the larger of the two vertices' corrections this
    pass (``hits``), summed into dx. The same scale on both keeps the momenta equal and
    opposite; with it, the corrections a vertex receives sum to at most the largest of
    them (a Jacobi pass that cannot overshoot where several pairs push one vertex the
    same way). Returns (1 if they needed it, else 0; ``touched`` with their bit set where
    a position pass moved them)."""
    pa, pb = ids[a], ids[b]
    needed, da, db, w, need = _violated(ids, a, b, n, delta, x1, v1, inv_mass, stop_normal,
                                        touched, velocity)
    corrected = 0
    mark = touched
    if needed:
        lam = need / (w * ti.max(hits[pa], hits[pb]))
        dx[pa] += inv_mass[pa] * lam * da
        dx[pb] += inv_mass[pb] * lam * db
        corrected = 1
        if ti.static(not velocity):
            mark |= _bit(a, b)
    return corrected, mark


@ti.func
def _correct_now(ids, kind, a: ti.template(), b: ti.template(), n, delta, x1, v1, inv_mass,
                 stop_normal, log):
    """``_correct`` in place, positions and velocities at once (a Gauss-Seidel step):
    the vertex pair moved onto its plane and its approaching normal velocity removed,
    written to ``log`` where it is on. 1 if they were closer, else 0."""
    pa, pb = ids[a], ids[b]
    closer, da, db, w, short = _violated(ids, a, b, n, delta, x1, v1, inv_mass, stop_normal, 0,
                                         False)
    corrected = 0
    if closer:
        gap_x, gap_v = x1[pa] - x1[pb], v1[pa] - v1[pb]
        lam = short / w
        x1[pa] += inv_mass[pa] * lam * da
        x1[pb] += inv_mass[pb] * lam * db
        approach = n.dot(gap_v)
        stopped = 0
        if approach < 0.0:
            stop = -approach / w
            v1[pa] += inv_mass[pa] * stop * da
            v1[pb] += inv_mass[pb] * stop * db
            stopped = 1
        corrected = 1
        if log.on[None]:
            _log(log, ids, kind, pa, pb, n, delta, w, da, db, gap_x, gap_v, stopped)
    return corrected


@ti.func
def _log(log, ids, kind, pa, pb, n, delta, w, da, db, gap_x, gap_v, stopped):
    """A correction into the ``Log`` (with its candidate's ids and kind, and the vertex
    pair's x_a - x_b and v_a - v_b before it)."""
    k = log.count[None]
    if k < log.capacity:
        log.pair[k] = ti.Vector([pa, pb])
        log.ids[k], log.kind[k] = ids, kind
        log.n[k], log.delta[k], log.w[k] = n, delta, w
        log.da[k], log.db[k] = da, db
        log.gap_x[k], log.gap_v[k] = gap_x, gap_v
        log.stopped[k] = stopped
    log.count[None] = k + 1


@ti.kernel
def _gauss_seidel(cl: ti.template(), pl: ti.template(), count: ti.i32, x1: ti.template(),
                  v1: ti.template(), inv_mass: ti.template(), stop_normal: ti.template(),
                  sweeps: ti.i32, log: ti.template()) -> ti.types.vector(2, ti.i32):
    """Serial sweeps of ``_correct_now`` over the candidates until one corrects nothing,
    at most ``sweeps``: (corrections of the first sweep, the sweeps run)."""
    found = 0
    ran = 0
    ti.loop_config(serialize=True)
    for _ in range(sweeps):
        corrected = 0
        for c in range(count):
            ids, kind, n, delta = plane_row(cl, pl, c)
            for a, b in ti.static(VERTEX_PAIRS):
                if kept_apart(kind, delta, a, b):
                    corrected += _correct_now(ids, kind + pl.surface[c], a, b, n, delta, x1,
                                              v1, inv_mass, stop_normal, log)
        if ran == 0:
            found = corrected
        ran += 1
        if corrected == 0:
            break
    return ti.Vector([found, ran])


@ti.kernel
def _project_pass(cl: ti.template(), pl: ti.template(), count: ti.i32, x1: ti.template(),
                  v1: ti.template(), inv_mass: ti.template(), stop_normal: ti.template(),
                  hits: ti.template(), dx: ti.template(), velocity: ti.template(),
                  first: ti.template()) -> ti.i32:
    """One Jacobi pass of ``project`` on x1 (with ``velocity``: on v1): every vertex pair
    that needs a correction counted, then corrected (``_correct``) from the same x1 and
    v1, all candidates at once; the corrections. ``first``: the rows' ``touched`` bits
    cleared before."""
    ti.loop_config(serialize=ti.static(serial(x1)))
    for p in range(x1.shape[0]):
        hits[p] = 0
        dx[p] = ti.Vector.zero(float, 3)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        if ti.static(first):
            pl.touched[c] = 0
        ids, kind, n, delta = plane_row(cl, pl, c)
        touched = pl.touched[c]
        for a, b in ti.static(VERTEX_PAIRS):
            if kept_apart(kind, delta, a, b):
                _count(ids, a, b, n, delta, x1, v1, inv_mass, stop_normal, hits, touched, velocity)
    corrected = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids, kind, n, delta = plane_row(cl, pl, c)
        touched = pl.touched[c]
        if delta > 0.0:
            for a, b in ti.static(VERTEX_PAIRS):
                if spans(kind, a, b):
                    done, touched = _correct(ids, a, b, n, delta, x1, v1, inv_mass, stop_normal,
                                             hits, dx, touched, velocity)
                    corrected += done
            pl.touched[c] = touched
    ti.loop_config(serialize=ti.static(serial(x1)))
    for p in range(x1.shape[0]):
        if hits[p] > 0:
            if ti.static(velocity):
                v1[p] += dx[p]
            else:
                x1[p] += dx[p]
    return corrected


def project(cl, pl, count, x1, v1, inv_mass, stop_normal, sweeps, work, log):
    """The candidates' projection (their ``planes``): sweeps until one corrects nothing,
    at most ``sweeps``. On CPUs (unless JACOBI) Gauss-Seidel on one thread
    (``_gauss_seidel``: a few sweeps where Jacobi's passes take many, and the same
    numbers whatever the threads); on GPUs (or with JACOBI) Jacobi passes in parallel
    (``_project_pass``): on the positions, then on the velocities of the pairs the
    positions' passes moved (an inelastic contact, as Gauss-Seidel's). pl: the list's
    ``guard.Planes``; work: (hits, dx), a particle's count and sum; log: Gauss-Seidel's
    corrections are written there where it is on (``Log``). Returns (the vertex
    pairs the first sweep corrected, the sweeps run); the last corrected nothing when
    fewer than ``sweeps`` ran."""
    if JACOBI or not runtime.cpu():
        found = ran = 0
        while ran < sweeps:
            corrected = int(_project_pass(cl, pl, count, x1, v1, inv_mass, stop_normal, *work,
                                          False, ran == 0))
            found = found or corrected
            ran += 1
            if corrected == 0:
                break
        if found:
            for _ in range(sweeps):
                if not int(_project_pass(cl, pl, count, x1, v1, inv_mass, stop_normal, *work,
                                         True, False)):
                    break
        return found, ran
    return (int(v) for v in _gauss_seidel(cl, pl, count, x1, v1, inv_mass, stop_normal, sweeps,
                                          log))


def warm(cl, pl, x1, v1, inv_mass, stop_normal, work, log):
    """Compile the kernels ``project`` launches for these fields, each run on no rows
    (nothing moves; ``contact/warm.py``)."""
    if JACOBI or not runtime.cpu():
        for velocity, first in ((False, True), (False, False), (True, False)):
            _project_pass(cl, pl, 0, x1, v1, inv_mass, stop_normal, *work, velocity, first)
    else:
        _gauss_seidel(cl, pl, 0, x1, v1, inv_mass, stop_normal, 1, log)


@ti.data_oriented
class ProjectionLog:
    """The corrections of one step of the self-contact term's projection (projective
    dynamics', after its iterations: ``terms/self_contact.py``) in their order, kept
    where ``on`` is set (a gradient's runs: ``tcloth/grad/projected.py`` differentiates
    each): the contact's particles (``ids``) and ``kind``, whether it was a velocity
    pass (``velocity``), the four particles' positions and velocities before it
    (``x``, ``v``: (capacity, 4)) and the two sides' vertex normals the velocity pass's
    normal read (``sides``: (capacity, 2); ``kind`` plus ``normals.SURFACE`` where it
    took them). ``count`` counts them all; past ``capacity`` they are not kept."""

    def __init__(self, capacity):
        real = runtime.real()
        self.capacity = capacity
        self.ids = ti.Vector.field(4, ti.i32, shape=capacity)
        self.kind, self.velocity = (ti.field(ti.i32, shape=capacity) for _ in range(2))
        self.x, self.v = (ti.Vector.field(3, real, shape=(capacity, 4)) for _ in range(2))
        self.sides = ti.Vector.field(3, real, shape=(capacity, 2))
        self.count, self.on = (ti.field(ti.i32, shape=()) for _ in range(2))

    @ti.func
    def keep(self, ids, kind, velocity, x, v, a, b):
        if self.on[None]:
            e = ti.atomic_add(self.count[None], 1)
            if e < self.capacity:
                self.ids[e], self.kind[e], self.velocity[e] = ids, kind, velocity
                self.sides[e, 0], self.sides[e, 1] = a, b
                for j in ti.static(range(4)):
                    self.x[e, j], self.v[e, j] = x[ids[j]], v[ids[j]]

    def entries(self):
        """The kept corrections as NumPy arrays (ids, kind, velocity, x, v, sides), or
        None where the step made more than the log keeps."""
        if int(self.count[None]) > self.capacity:
            return None
        k = int(self.count[None])
        return tuple(f.to_numpy()[:k] for f in (self.ids, self.kind, self.velocity, self.x,
                                                 self.v, self.sides))
