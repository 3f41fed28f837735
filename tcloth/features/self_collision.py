"""``Scene.set_self_collision`` and the model's ``contact.topology.SelfCollisionTable``
(``tcloth.terms.self_contact`` has the contact model, ``tcloth.contact`` the contact set)."""
from ..contact.topology import SelfCollisionTable
from ..validate import as_scalar
from .base import Feature


class SelfCollisionFeature(Feature):
    """``Scene.set_self_collision``; the model's ``contact.topology.SelfCollisionTable``."""
    name, method = "self_collision", "set_self_collision"

    def set(self, scene, thickness=0.005, stiffness=None, friction=0.0, damping=0.1,
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
        return {
            "thickness": t,
            "stiffness": None if stiffness is None else
            as_scalar("stiffness", stiffness, minimum=0.0, strict=True),
            "friction": as_scalar("friction", friction, minimum=0.0),
            "damping": as_scalar("damping", damping, minimum=0.0),
            "stick_velocity": as_scalar("stick_velocity", stick_velocity, minimum=0.0,
                                        strict=True),
            "skin": t if skin is None else as_scalar("skin", skin, minimum=0.0, strict=True)}

    def build(self, model, settings):
        return SelfCollisionTable(model.scene)


SELF_COLLISION = SelfCollisionFeature()
