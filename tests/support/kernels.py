"""Taichi kernels that read tcloth's device structures for the tests' checks."""
import taichi as ti


@ti.kernel
def collider_contacts(table: ti.template(), row: ti.i32, x: ti.types.ndarray(), t: float,
                      out: ti.types.ndarray()):
    """out[k] = (phi, normal, surface velocity) of point x[k] against collider ``row`` of
    the table's one group at time t (``ColliderTable.contact``)."""
    for k in range(x.shape[0]):
        p = ti.Vector([x[k, 0], x[k, 1], x[k, 2]])
        for g in ti.static(table.groups):
            phi, n, u = table.contact(g.shape, table.data[g.first + row], p, t)
            out[k, 0] = phi
            for j in ti.static(range(3)):
                out[k, 1 + j] = n[j]
                out[k, 4 + j] = u[j]
