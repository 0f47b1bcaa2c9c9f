"""The configurations of a trade study: ``--sweep KEY=V1,V2,...`` expanded and validated.

Every sweep key is a dotted scene key (``time.dt``, ``mesh.element_size``,
``element.degree``, ``element.quadrature_degree``, ``time.integrator``, ``solver.preset``,
``material.mass``, ``solver.stopping``, ``solver.petsc.snes_rtol``, ...), each value is
parsed and validated exactly like ``--set`` (:func:`fem_anim.scene.loading.parse_override`,
:func:`fem_anim.scene.loading.load_scene`): a bad key or value is a :class:`SceneError` naming
it. The configurations are the Cartesian product of the sweeps; a combination that the
scene's cross-key rules forbid (lumped mass with P2) is kept as *skipped* with the
reason, not an error.

All configurations simulate the same duration T (the base scene's ``time.steps`` x
``time.dt``) and are compared at common times, multiples of the *comparison interval*
H = the largest time step of the study: every swept dt must divide H (dt = H / k for an
integer k), so every run has a frame at each comparison time.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from fem_anim.errors import SceneError
from fem_anim.solver.presets import preset_options
from fem_anim.scene.loading import Scene, load_scene, parse_override
from fem_anim.bench.pareto import short

__all__ = ["Configuration", "Study", "parse_sweep", "split_values", "expand_study"]

#: Keys a sweep may not set: the study derives them (duration, outputs).
DERIVED_KEYS = ("time.steps", "output.every", "output.directory", "output.render")


def split_values(text: str) -> list[str]:
    """Split ``V1,V2,...`` at commas outside brackets (``[1,2],[3,4]`` is two values)."""
    parts, depth, current = [], 0, ""
    for c in text:
        depth += c in "[{"
        depth -= c in "]}"
        if c == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += c
    parts.append(current)
    return [p.strip() for p in parts]


def parse_sweep(text: str) -> tuple[str, list[str]]:
    """``KEY=V1,V2,...`` -> (key, ["KEY=V1", "KEY=V2", ...]) as ``--set`` overrides.

    Raises:
        SceneError: for a missing ``=``, an empty value, a derived key or a bad value.
    """
    if "=" not in text:
        raise SceneError(f"--sweep expects KEY=V1,V2,..., got {text!r}")
    key, raw = (s.strip() for s in text.split("=", 1))
    if key in DERIVED_KEYS:
        raise SceneError(f"--sweep {key}: the study sets it (all runs simulate the base "
                         "scene's duration); sweep time.dt instead")
    values = split_values(raw)
    if not all(values):
        raise SceneError(f"--sweep {key}: empty value in {raw!r}")
    overrides = [f"{key}={v}" for v in values]
    for item in overrides:
        parse_override(item)  # the same parsing as --set
    if len(set(overrides)) != len(overrides):
        raise SceneError(f"--sweep {key}: repeated value in {raw!r}")
    return key, overrides


@dataclass
class Configuration:
    """One point of the study: its label, overrides and scene (None when skipped)."""

    label: str
    values: dict[str, str]
    overrides: list[str]
    scene: Scene | None
    skipped: str = ""


@dataclass
class Study:
    """The expanded study: configurations, reference and the common time grid."""

    base: Scene
    configurations: list[Configuration]
    reference: Configuration
    duration: float
    interval: float  # comparison interval H
    frames: int  # comparison times k H, k = 1..frames


def _steps_per_interval(dt: float, interval: float, where: str) -> int:
    k = round(interval / dt)
    if k < 1 or abs(k * dt - interval) > 1e-9 * interval:
        raise SceneError(f"{where}: time.dt = {dt:.6g} does not divide the comparison interval "
                         f"{interval:.6g} s (the largest time step of the study): choose dt "
                         "values H/1, H/2, H/4, ...")
    return k


def expand_study(path: str | None, base_overrides: list[str], sweeps: list[str],
                 reference_overrides: list[str]) -> Study:
    """Validate the sweeps and expand them into configurations plus the reference.

    The reference is the base scene with the smallest swept time step divided by 4,
    the smallest swept element size, P2 elements (P1 for a scene that refuses P2: with
    ``[contact]``) and a tight Newton tolerance (``snes_rtol = 1e-10``), then
    ``reference_overrides``.

    Raises:
        SceneError: naming the bad sweep key or value (each value is validated alone on
            the base scene), or a time step that does not divide the comparison interval.
    """
    base = load_scene(path, base_overrides)
    parsed = [parse_sweep(s) for s in sweeps]
    keys = [k for k, _ in parsed]
    if len(set(keys)) != len(keys):
        raise SceneError(f"--sweep: key given twice in {', '.join(keys)}")
    scenes = {}
    for _, overrides in parsed:
        for item in overrides:  # each value alone: a bad key or value is the user's error
            scenes[item] = load_scene(path, [*base_overrides, item])
            try:
                preset_options(scenes[item]["solver"]["preset"])
            except KeyError as err:
                raise SceneError(f"--sweep {item}: {err.args[0]}") from None
    duration = base["time"]["dt"] * base["time"]["steps"]
    dts = [base["time"]["dt"]]
    for key, overrides in parsed:
        if key == "time.dt":
            dts = [scenes[o]["time"]["dt"] for o in overrides]
    interval = max(dts)
    frames = round(duration / interval)
    if frames < 1 or abs(frames * interval - duration) > 1e-9 * duration:
        raise SceneError(f"--sweep time.dt: the largest step {interval:.6g} s must divide the "
                         f"simulated duration {duration:.6g} s (time.steps x time.dt)")
    configurations = []
    for combo in itertools.product(*[overrides for _, overrides in parsed]):
        values = {item.split("=", 1)[0]: item.split("=", 1)[1] for item in combo}
        label = " ".join(f"{k.split('.')[-1]}={short(v)}" for k, v in values.items()) \
            or "base"
        configurations.append(_configuration(path, base_overrides, list(combo), values, label,
                                             duration, interval))
    ref_overrides = [f"time.dt={min(dts) / 4.0!r}", "element.degree=2",
                     "solver.petsc.snes_rtol=1e-10"]
    if _keeps_degree(base):  # contact between surfaces: a finer step and mesh only
        ref_overrides.remove("element.degree=2")
    for key, overrides in parsed:
        if key == "mesh.element_size":
            ref_overrides.append(f"mesh.element_size="
                                 f"{min(scenes[o]['mesh']['element_size'] for o in overrides)!r}")
    if base["material"]["mass"] == "lumped":
        ref_overrides.append("material.mass=consistent")
    ref_overrides += list(reference_overrides)
    last = {item.split("=", 1)[0].strip(): item for item in ref_overrides}  # later ones win
    ref_overrides = list(last.values())
    reference = _configuration(path, base_overrides, ref_overrides, {}, "reference", duration,
                               interval)
    if reference.skipped:
        raise SceneError(f"--reference: {reference.skipped}")
    return Study(base, configurations, reference, duration, interval, frames)


def _keeps_degree(scene: Scene) -> bool:
    """Whether the reference keeps the scene's degree: with ``[contact]`` between surfaces,
    whose P2 surface is the P1 one refined (:mod:`fem_anim.contact.p2_surface`), so a P2
    reference would touch on another surface than the configurations it judges."""
    return "contact" in scene.data


def _configuration(path, base_overrides, overrides, values, label, duration,
                   interval) -> Configuration:
    try:
        scene = load_scene(path, [*base_overrides, *overrides])
    except SceneError as err:  # a forbidden combination of individually valid values
        return Configuration(label, values, overrides, None, skipped=str(err))
    dt = scene["time"]["dt"]
    k = _steps_per_interval(dt, interval, label)
    steps = k * round(duration / interval)
    scene.data["time"]["steps"] = steps
    scene.data["output"]["render"] = False
    if not math.isfinite(dt * steps):
        raise SceneError(f"{label}: time.dt = {dt} gives no finite duration")
    return Configuration(label, values, overrides, scene)
