"""The sandbox's logic without a window: the panel's values and what they do to a
``Simulator`` (its live setters), picking and dragging a particle with the grab spring,
pause / step / reset, the integrator switch, the frame loop's instability handling and
statistics, and the panel's lines of contact statistics. Tests drive it directly."""
import math
import time

import numpy as np

from ..errors import InstabilityError
from ..scene.scene import KIND_CODE, SPRING_KINDS
from ..validate import as_int
from .camera import pick


class Controls:
    """The sandbox's logic for one Simulator, without a window.

    ``values`` holds what the panel shows and edits: dt (s), substeps (per frame),
    gravity (m/s^2, downwards along -y), air_damping (1/s, the scene's mass-proportional
    air damping: the same at every resolution), springs {kind: [k_s, k_d]} for the kinds the
    scene has, wind_speed (m/s) and wind_direction (degrees about y, 0 = +x) when the scene
    has wind (not a Python-callable gust, which sets the velocity itself), colliders (one
    bool each), strain_limiting (when the scene has a limit).
    ``apply()`` hands every changed value to the simulator's live setters.
    """

    def __init__(self, sim, substeps=10):
        self.sim = sim
        scene = sim.scene
        springs = scene.springs
        kinds = {k: springs["kind"] == KIND_CODE[k] for k in SPRING_KINDS}
        self.values = {"dt": sim.dt, "substeps": as_int("substeps", substeps, 1),
                       "gravity": float(-scene.gravity[1]),
                       "air_damping": scene.air_damping,
                       "springs": {k: [_typical(springs[q][mask])
                                       for q in ("stiffness", "damping")]
                                   for k, mask in kinds.items() if mask.any()},
                       "colliders": [i not in sim.settings["colliders_off"]
                                     for i in range(len(scene.colliders))]}
        if sim.model.wind is not None and scene.wind["callable"] is None:
            w = scene.wind["velocity"]
            self.values["wind_speed"] = float(np.hypot(w[0], w[2]))
            self.values["wind_direction"] = float(np.degrees(np.arctan2(w[2], w[0])))
        if scene.strain_limit is not None:
            self.values["strain_limiting"] = sim.settings["strain_limiting"]
        self.initial = _copy(self.values)
        self._applied = _copy(self.values)
        self.paused = False
        self.message = ""
        self.frame_seconds = []
        self.substep_seconds = []
        self.dragging = None            # (particle, depth along the view) while held
        self._measured, self._stats_age = None, 0
        self.pickable = np.flatnonzero(~scene.pinned)

    # -- panel values -> simulator ---------------------------------------------------------
    def apply(self):
        """Hand every value changed since the last apply to the simulator."""
        new, old, sim = self.values, self._applied, self.sim
        if new["dt"] != old["dt"]:
            sim.set_dt(new["dt"])
        if new["gravity"] != old["gravity"]:
            g = sim.scene.gravity.copy()
            g[1] = -new["gravity"]
            sim.set_gravity(g)
        if new["air_damping"] != old["air_damping"]:
            sim.set_air_damping(new["air_damping"])
        for kind, (ks, kd) in new["springs"].items():
            if [ks, kd] != old["springs"][kind]:
                sim.set_springs(kind, stiffness=ks, damping=kd)
        if "wind_speed" in new and (new["wind_speed"], new["wind_direction"]) != \
                (old["wind_speed"], old["wind_direction"]):
            a = math.radians(new["wind_direction"])
            vy = sim.scene.wind["velocity"][1]
            sim.set_wind((new["wind_speed"] * math.cos(a), vy, new["wind_speed"] * math.sin(a)))
        for i, (on, was) in enumerate(zip(new["colliders"], old["colliders"])):
            if on != was:
                sim.set_collider_enabled(i, on)
        if "strain_limiting" in new and new["strain_limiting"] != old["strain_limiting"]:
            sim.set_strain_limiting(new["strain_limiting"])
        self._applied = _copy(new)

    def set_integrator(self, name):
        """Continue from the current state with another integrator."""
        self.sim.set_integrator(name)
        self.message = ""

    def reset(self):
        """Back to t = 0 with the panel's initial values; unpaused."""
        self.end_drag()
        self.values = _copy(self.initial)
        self.apply()
        self.sim.reset()
        self.message = ""
        self.paused = False

    # -- stepping --------------------------------------------------------------------------
    def advance(self, force=False):
        """One frame of ``substeps`` steps unless paused (force: even when paused). On
        InstabilityError the simulator keeps its last good state, the viewer pauses and
        ``message`` holds the error and its hint until the next frame that runs (after the
        user resumes, perhaps with other settings). Returns True when it stepped."""
        if self.paused and not force:
            return False
        self.message = ""
        start = time.perf_counter()
        try:
            self.sim.step(self.values["substeps"])      # waits: each step reads its check
        except InstabilityError as e:
            self.message = str(e)
            self.paused = True
            return False
        elapsed = time.perf_counter() - start
        self.substep_seconds = (self.substep_seconds + [elapsed / self.values["substeps"]])[-30:]
        return True

    def frame_done(self, seconds):
        self.frame_seconds = (self.frame_seconds + [seconds])[-30:]

    def stats(self, every=1):
        """dict: fps, ms_per_substep (medians of the last 30 frames), energy (J),
        max_strain, time (s), integrator, contacts (``Simulator.contact_stats``), splits
        (``Simulator.step_stats``). every=k
        reuses the energy, strain and contacts of the last call for k - 1 calls (the
        panel: they cost more than a 64 x 64 cloth's frame)."""
        sim = self.sim
        self._stats_age += 1
        if self._measured is None or self._stats_age >= every:
            self._measured = {"energy": sim.energy()["total"], "max_strain": sim.max_strain(),
                              "contacts": sim.contact_stats(), "splits": sim.step_stats()}
            self._stats_age = 0
        return {"fps": 1.0 / np.median(self.frame_seconds) if self.frame_seconds else 0.0,
                "ms_per_substep": 1e3 * np.median(self.substep_seconds)
                if self.substep_seconds else 0.0,
                **self._measured, "time": sim.time, "integrator": sim.integrator_name}

    # -- dragging --------------------------------------------------------------------------
    def start_drag(self, camera, u, v, aspect):
        """Grab the free particle under window point (u, v); returns its id or None."""
        if self.sim.model.grab is None:
            return None
        origin, direction = camera.ray(u, v, aspect)
        x = self.sim.positions().astype(np.float64)
        p = pick(x, self.pickable, origin, direction)
        if p is None:
            return None
        forward = camera.basis[0]
        self.dragging = (p, float((x[p] - origin) @ forward))
        self.sim.grab(p, x[p])
        return p

    def drag(self, camera, u, v, aspect):
        """Move the held particle's target to the cursor, at the depth it was grabbed at."""
        if self.dragging is None:
            return
        p, depth = self.dragging
        origin, direction = camera.ray(u, v, aspect)
        held = self.sim.grabbed
        self.sim.grab(p, origin + direction * depth / (direction @ camera.basis[0]),
                      held["stiffness"], held["damping"])

    def end_drag(self):
        self.dragging = None
        self.sim.release()


def _typical(values):
    """The common value of equal values, else their mean."""
    return float(values[0] if np.all(values == values[0]) else np.mean(values))


def _copy(values):
    return {k: ({kk: list(vv) for kk, vv in v.items()} if isinstance(v, dict) else
                list(v) if isinstance(v, list) else v) for k, v in values.items()}


def split_line(stats):
    """The panel's line for ``Simulator.step_stats()``: how many steps were split so far,
    and the split the next step takes."""
    now = stats["pieces_now"]
    return (f"split steps: {stats['split_steps']} (finest 1/{stats['finest']}), "
            f"now {'whole' if now == 1 else f'1/{now}'}")


def contact_lines(stats):
    """The panel's lines for ``Simulator.contact_stats()`` (none for a scene without
    contact): the contacts active now, then what the stage did so far."""
    if not stats:
        return []
    lines = []
    if stats.get("rebuilds"):
        lines.append(f"self-contacts: {stats['point_triangle']} point-triangle, "
                     f"{stats['edge_edge']} edge-edge")
        lines.append(f"  {stats['candidates']} candidates, {stats['rebuilds']} rebuilds")
        lines.append(f"  guard: {stats['guard_corrections']} corrections, "
                     f"{stats['failsafe_steps']} fail-safe steps")
    lines.append(f"collider contacts: {stats['collider']}, "
                 f"{stats['collider_paths_cut']} paths cut")
    lines.append(f"contact stage: {stats['seconds']:.2f} s so far")
    return lines
