"""Index structures on the particles, in NumPy: items grouped by key in compressed sparse
row form (``csr_layout``: each particle's springs, hinges or triangles, a graph's
adjacency), and the greedy colouring that the Gauss-Seidel solvers sweep by
(``colour_graph``): VBD colours the particle graph, XPBD each family of constraints
(``colour_springs``: the graph of constraints that share a particle). No two members of
a colour are joined, so a pass updates a colour's members in parallel. ``incidence`` and
``element_fields`` put elements of k particles (hinges, triangles) and each particle's
elements on the device, for the features' fields (``tcloth.features``)."""
import numpy as np
import taichi as ti

from .. import runtime


def csr_layout(keys, n, then=None):
    """Items grouped by key (each in 0..n-1): (start (n+1,), order (len(keys),)), int64,
    with the items of key k at order[start[k]:start[k + 1]], in item order, or by
    ``then`` (a secondary key per item) where it is given."""
    keys = np.asarray(keys, dtype=np.int64).ravel()
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys, minlength=n), out=start[1:])
    order = np.argsort(keys, kind="stable") if then is None else np.lexsort((then, keys))
    return start, order


def colour_graph(start, neighbours, n):
    """Greedy colouring of a graph given as CSR adjacency (neighbours[start[i]:start[i+1]]
    of vertex i): each vertex in index order takes the smallest colour none of its
    coloured neighbours has. Returns (n,) int colours; no two neighbours share one."""
    start, neighbours = np.asarray(start).tolist(), np.asarray(neighbours).tolist()
    colours = [-1] * n
    for i in range(n):
        taken = {colours[j] for j in neighbours[start[i]:start[i + 1]]}
        c = 0
        while c in taken:
            c += 1
        colours[i] = c
    return np.array(colours, dtype=np.int64)


def colour_springs(constraints, n):
    """Greedy colouring of constraints on n particles (springs (S,2), hinges (S,4),
    triangles (S,3)): each in order takes the smallest colour that no constraint at any of
    its particles has yet (``colour_graph`` of the graph joining constraints that share a
    particle). Returns (S,) int colours."""
    ids = np.asarray(constraints, dtype=np.int64)
    slots, k = ids.ravel(), ids.shape[1]
    start, order = csr_layout(slots, n)
    at = order // k                          # each particle's constraints, by particle
    count = (start[1:] - start[:-1])[slots]  # how many constraints at each slot's particle
    first = np.repeat(start[slots] - np.cumsum(count) + count, count)
    owner = np.repeat(np.arange(len(slots)) // k, count)
    graph, rows = csr_layout(owner, len(ids))
    return colour_graph(graph, at[first + np.arange(len(owner))][rows], len(ids))


def colour_order(colours):
    """(order, colour starts) of items with these colours: an i32 field of the items
    sorted by colour (in item order within one; one entry where there are no items) and
    the Python list of each colour's first position in it, and the end."""
    count = int(colours.max()) + 1 if len(colours) else 0
    start, order = csr_layout(colours, count)
    field = ti.field(ti.i32, shape=max(len(order), 1))
    if len(order):
        field.from_numpy(order.astype(np.int32))
    return field, start.tolist()


def incidence(ids, n):
    """Each particle's elements, for elements of k particles ids (E,k), as Taichi fields:
    (start (n+1,), entries): particle p's (element, slot) pairs are entries[start[p]:
    start[p+1]], in element order (a gather per particle needs no atomics)."""
    vertex = np.asarray(ids, dtype=np.int64).ravel()
    k = np.shape(ids)[1] if np.ndim(ids) == 2 else 1
    first, order = csr_layout(vertex, n)
    start = ti.field(ti.i32, shape=n + 1)
    start.from_numpy(first.astype(np.int32))
    entries = ti.Vector.field(2, ti.i32, shape=max(len(order), 1))
    if len(order):
        entries.from_numpy(np.stack([order // k, order % k], 1).astype(np.int32))
    return start, entries


def element_fields(ids, n, *values):
    """Elements of k particles each, ids (E,k), with per-element values (each (E,a), a
    vector an element, or (E,a,b), a matrix) as Taichi fields: (the ids, vec-k i32; one
    field per values array, in the real type; start and entries, each particle's elements
    (``incidence``)). The element fields have one entry where E = 0."""
    ids = np.asarray(ids, dtype=np.int64)
    count, real, npr = max(len(ids), 1), runtime.real(), runtime.numpy_real()
    fields = [ti.Vector.field(ids.shape[1], ti.i32, shape=count)]
    fields += [ti.Vector.field(v.shape[1], real, shape=count) if v.ndim == 2 else
               ti.Matrix.field(v.shape[1], v.shape[2], real, shape=count) for v in values]
    if len(ids):
        arrays = [ids.astype(np.int32)] + [v.astype(npr) for v in values]
        for field, array in zip(fields, arrays):
            field.from_numpy(array)
    return (*fields, *incidence(ids, n))
