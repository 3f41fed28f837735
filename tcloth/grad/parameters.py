"""A parameter's gradient from the gradients of what the model makes of it: the hinge
weights of the bending rigidities, the membrane's coefficients of its moduli, and every
field the masses reach (``Trajectory._reduce`` calls these after the backward run)."""
import numpy as np

# the membrane's parameters: name -> (its settings key, column)
MEMBRANE = {"stretch_warp": ("stretch", 0), "stretch_weft": ("stretch", 1),
            "shear": ("shear", None)}


def bending_gradient(model, adjoint):
    """dL/dB, (cloths, 2) as the settings' rigidity, from the hinge weights' gradient:
    each hinge's c = sqrt(share B / A) K, so dc/dB = c / (2 B)."""
    data = model.bending
    rigidity = np.asarray(model.scene.bending["rigidity"], dtype=np.float64)
    c = data.scaled(rigidity)
    c_bar = adjoint.hinge_weights.grad.to_numpy()[:data.count].astype(np.float64)
    out = np.zeros_like(rigidity)
    np.add.at(out, (data.cloth, data.family),
              (c_bar * c).sum(axis=1) / (2.0 * rigidity[data.cloth, data.family]))
    return out


def membrane_gradient(model, adjoint, what):
    """dL/d(a stretch or the shear) from the coefficients' gradient: each triangle's
    (A C_u, A C_v, A G, beta), beta = 2 zeta sqrt(m / max(C_u, C_v))."""
    data, settings = model.membrane, model.scene.membrane
    c_bar = adjoint.membrane_c.grad.to_numpy()[:data.count].astype(np.float64)
    key, column = MEMBRANE[what]
    if column is None:
        return float((c_bar[:, 2] * data.area).sum())
    stretch = np.asarray(settings["stretch"], dtype=np.float64)[data.cloth]
    beta = data.coefficients_for(settings)[:, 3]
    stiffer = stretch.argmax(axis=1) == column
    dbeta = np.where(stiffer, -beta / (2.0 * stretch[:, column]), 0.0)
    return float((c_bar[:, column] * data.area + c_bar[:, 3] * dbeta).sum())


def masses_gradient(model, adjoint, inv_mass, explicit):
    """dL/dm (n,): the mass fields' gradients (inv_mass's through -1/m^2, ``inv_mass``
    the model's inverse masses in NumPy), the drag's through c_p = c + gamma m_p, the
    membrane's damping through beta = 2 zeta sqrt(m_reduced / max(C_u, C_v)) (m_reduced a
    sixth of the triangle's corner masses), and ``explicit`` (or None): the share computed
    in NumPy, symplectic Euler's through M^-1 (``StepAdjoints._explicit_adjoint``) and the
    guard's corrections' (``frozen.pull_back``)."""
    scene = model.scene
    out = (adjoint.mass.grad.to_numpy() - adjoint.inv_mass.grad.to_numpy() * inv_mass ** 2
           + scene.air_damping * adjoint.drag.grad.to_numpy()).astype(np.float64)
    data = model.membrane
    if data is not None:
        c_bar = adjoint.membrane_c.grad.to_numpy()[:data.count, 3].astype(np.float64)
        beta = data.coefficients_for(scene.membrane)[:, 3]
        np.add.at(out, data.ids, (c_bar * beta / (12.0 * data.reduced))[:, None])
    if explicit is not None:
        out += explicit
    return out
