"""Checkpoints: a simulator's scene, settings and state in one ``.npz`` file.

The scene is stored as plain arrays plus a JSON description and rebuilt through the same
validating ``Scene`` methods a script uses, so a damaged or hand-edited file is refused
with a ``SceneError`` naming what is wrong. Files are written to a temporary name, flushed
and renamed: a crash mid-write never leaves a corrupt checkpoint under the real name.
"""
import json
import os
import zipfile

import numpy as np

from .errors import SceneError
from .builders import Cloth, MeshCloth, Rope
from .scene import KIND_CODE, SPRING_KINDS, Scene

FORMAT = "tcloth-checkpoint"
VERSION = 1
_COLLIDER_SHAPE = {"sphere": ("center", "radius"), "plane": ("center", "normal"),
                   "box": ("center", "half_extents", "rotation"),
                   "cylinder": ("center", "radius", "half_height", "rotation")}
_COLLIDER_COMMON = ("friction", "velocity", "thickness", "stiffness", "damping",
                    "stick_velocity")


def _plain(value):
    return value.tolist() if isinstance(value, np.ndarray) else value


def _plain_dict(d):
    return None if d is None else {k: _plain(v) for k, v in d.items()}


def scene_to_arrays(scene):
    """(JSON-able description, dict of arrays) of a Scene."""
    if scene.wind is not None and scene.wind["callable"] is not None:
        raise SceneError("a scene whose wind gust is a Python callable cannot be saved in a "
                         "checkpoint; use gust=dict(amplitude=..., frequency=..., phase=...)")
    sp = scene.springs
    arrays = {"positions": scene.positions, "velocities": scene.velocities,
              "masses": scene.masses, "pinned": scene.pinned, "spring_pairs": sp["pairs"],
              "spring_stiffness": sp["stiffness"], "spring_damping": sp["damping"],
              "spring_rest": sp["rest_length"], "spring_kind": sp["kind"]}
    desc = {"gravity": scene.gravity.tolist(), "air_drag": scene.air_drag,
            "cloths": [], "ropes": [], "colliders": [], "wind": None, "attraction": None,
            "strain_limit": None}
    for k, c in enumerate(scene.cloths):
        if c.is_grid:
            desc["cloths"].append({"offset": int(c.offset), "resolution": list(c.resolution),
                                   "spacing": list(c.spacing), "params": c.params,
                                   "plane": c.plane})
        else:
            desc["cloths"].append({"mesh": True, "offset": int(c.offset),
                                   "count": len(c.particles), "params": c.params})
            arrays[f"cloth{k}_triangles"] = c.triangles - c.offset
        for family, ids in c.springs.items():
            arrays[f"cloth{k}_{family}"] = ids
    for k, r in enumerate(scene.ropes):
        arrays[f"rope{k}_particles"] = r.particles
        arrays[f"rope{k}_springs"] = r.springs
    desc["ropes"] = len(scene.ropes)
    for c in scene.colliders:
        desc["colliders"].append(_plain_dict(c))
    if scene.wind is not None:
        desc["wind"] = {k: _plain(v) for k, v in scene.wind.items() if k != "callable"}
    if scene.attraction is not None:
        desc["attraction"] = list(scene.attraction)
    if scene.strain_limit is not None:
        lim = scene.strain_limit
        desc["strain_limit"] = {"max_stretch": lim["max_stretch"],
                                "iterations": lim["iterations"]}
        arrays["strain_springs"] = lim["springs"]
    if scene.self_collision is not None:
        desc["self_collision"] = dict(scene.self_collision)
    return desc, arrays


def _runs(kinds):
    """Start/stop of runs of equal spring kinds, in order."""
    if len(kinds) == 0:
        return []
    cuts = np.flatnonzero(np.diff(kinds)) + 1
    starts = np.concatenate([[0], cuts])
    stops = np.concatenate([cuts, [len(kinds)]])
    return list(zip(starts, stops))


def scene_from_arrays(desc, arrays):
    """Rebuild a Scene with the validating Scene methods."""
    scene = Scene(gravity=desc["gravity"], air_drag=desc["air_drag"])
    scene.add_particles(arrays["positions"], mass=arrays["masses"],
                        velocities=arrays["velocities"], pinned=arrays["pinned"].astype(bool))
    kinds = arrays["spring_kind"]
    if len(kinds) and (kinds.min() < 0 or kinds.max() >= len(SPRING_KINDS)):
        raise SceneError(f"checkpoint field spring_kind holds codes outside "
                         f"0..{len(SPRING_KINDS) - 1}")
    for a, b in _runs(kinds):
        scene.add_springs(arrays["spring_pairs"][a:b], arrays["spring_stiffness"][a:b],
                          arrays["spring_damping"][a:b], arrays["spring_rest"][a:b],
                          kind=SPRING_KINDS[kinds[a]])
    for k, c in enumerate(desc["cloths"]):
        params = {f: (tuple(p) if p is not None else None) for f, p in c["params"].items()}
        if c.get("mesh"):
            cloth = MeshCloth(c["offset"], c["count"], arrays[f"cloth{k}_triangles"], params)
        else:
            cloth = Cloth(c["offset"], tuple(c["resolution"]), tuple(c["spacing"]), params,
                          c["plane"])
        if cloth.particles.max() >= scene.num_particles:
            raise SceneError(f"checkpoint cloth {k} refers to particles beyond the "
                             f"{scene.num_particles} stored")
        for family in ("structural", "shear", "flexion"):
            ids = arrays[f"cloth{k}_{family}"]
            if len(ids) and (ids.max() >= scene.num_springs or
                             np.any(scene.springs["kind"][ids] != KIND_CODE[family])):
                raise SceneError(f"checkpoint cloth {k}'s {family} springs do not match "
                                 "the stored spring list")
            cloth.springs[family] = ids
        scene.cloths.append(cloth)
    for k in range(desc["ropes"]):
        scene.ropes.append(Rope(arrays[f"rope{k}_particles"], arrays[f"rope{k}_springs"]))
    for c in desc["colliders"]:
        kind = c.get("kind")
        if kind not in _COLLIDER_SHAPE:
            raise SceneError(f"checkpoint holds a collider of unknown kind {kind!r}")
        args = {key: c[key] for key in _COLLIDER_COMMON}
        shape = [c[key] for key in _COLLIDER_SHAPE[kind]]
        if kind == "plane":
            scene.add_plane(*shape, **args)
        else:
            getattr(scene, f"add_{kind}")(*shape, **args)
    if desc["wind"] is not None:
        w = desc["wind"]
        scene.set_wind(w["velocity"], drag=w["drag"], lift=w["lift"],
                       tangential=w["tangential"],
                       gust={"amplitude": w["amplitude"], "frequency": w["frequency"],
                             "phase": w["phase"]})
    if desc["attraction"] is not None:
        scene.add_attraction(*desc["attraction"])
    if desc["strain_limit"] is not None:
        scene.limit_strain(desc["strain_limit"]["max_stretch"],
                           desc["strain_limit"]["iterations"],
                           springs=arrays["strain_springs"])
    if desc.get("self_collision") is not None:
        scene.set_self_collision(**desc["self_collision"])
    return scene


def save(sim, path):
    """Write ``sim`` to ``path`` (.npz) atomically."""
    desc, arrays = scene_to_arrays(sim.scene)
    meta = {"format": FORMAT, "version": VERSION, "scene": desc,
            "integrator": sim.integrator_name, "dt": sim.dt, "options": sim.integrator.options,
            "settings": sim.settings, "precision": sim.precision,
            "num_steps": sim.num_steps, "time_base": sim._time_base,
            "step_base": sim._step_base, "grabbed": _plain_dict(sim.grabbed),
            "forces_valid": sim.integrator.holds_forces(sim.state)}
    state = sim.state
    payload = {f"scene_{k}": v for k, v in arrays.items()}
    payload.update(meta=np.array(json.dumps(meta)), state_x=state.x.to_numpy(),
                   state_v=state.v.to_numpy(), state_f=state.f.to_numpy())
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise SceneError(f"cannot save checkpoint: folder {folder!r} does not exist")
    atomic_write(path, lambda f: np.savez(f, **payload))


def atomic_write(path, write, mode="wb"):
    """``write(f)`` into ``PATH.partial``, flushed to disk, then renamed to ``path``: a
    reader sees the old file or the whole new one, never part of it (the partial file is
    removed if ``write`` fails)."""
    path = os.fspath(path)
    tmp = path + ".partial"
    try:
        with open(tmp, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def read(path):
    """(meta dict, scene arrays, state arrays) from a checkpoint, checked."""
    if not os.path.isfile(path):
        raise SceneError(f"checkpoint {path!r} does not exist")
    if not zipfile.is_zipfile(path):
        # np.load would try the bytes as a pickle, and say so
        raise SceneError(f"checkpoint {path!r} is not a readable .npz file: not a zip "
                         "archive (truncated or damaged, or not written by Simulator.save)")
    try:
        with np.load(path, allow_pickle=False) as data:
            files = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise SceneError(f"checkpoint {path!r} is not a readable .npz file "
                         f"(truncated or damaged?): {e}") from None
    if "meta" not in files:
        raise SceneError(f"checkpoint {path!r} lacks its 'meta' field: not a tcloth checkpoint")
    try:
        meta = json.loads(str(files["meta"]))
    except json.JSONDecodeError as e:
        raise SceneError(f"checkpoint {path!r}: its 'meta' field is not valid JSON: {e}") from None
    if meta.get("format") != FORMAT:
        raise SceneError(f"checkpoint {path!r} is not a tcloth checkpoint "
                         f"(format {meta.get('format')!r})")
    if meta.get("version") != VERSION:
        raise SceneError(f"checkpoint {path!r} has format version {meta.get('version')!r}; "
                         f"this tcloth reads version {VERSION}")
    needed = ["state_x", "state_v", "state_f", "scene_positions", "scene_velocities",
              "scene_masses", "scene_pinned", "scene_spring_pairs", "scene_spring_stiffness",
              "scene_spring_damping", "scene_spring_rest", "scene_spring_kind"]
    desc = meta["scene"]
    needed += [f"scene_cloth{k}_{f}" for k in range(len(desc["cloths"]))
               for f in ("structural", "shear", "flexion")]
    needed += [f"scene_rope{k}_{f}" for k in range(desc["ropes"]) for f in ("particles", "springs")]
    if desc["strain_limit"] is not None:
        needed.append("scene_strain_springs")
    missing = [k for k in needed if k not in files]
    if missing:
        raise SceneError(f"checkpoint {path!r} lacks field {missing[0]!r}")
    n = len(files["scene_positions"])
    for key in ("state_x", "state_v", "state_f"):
        if files[key].shape != (n, 3):
            raise SceneError(f"checkpoint {path!r}: field {key!r} has shape {files[key].shape}, "
                             f"expected ({n}, 3) for its {n} particles")
    scene_arrays = {k[len("scene_"):]: v for k, v in files.items() if k.startswith("scene_")}
    return meta, scene_arrays, files
