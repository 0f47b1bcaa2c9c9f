"""Scenes: what a scene file may hold, how it is read and checked.

:mod:`~fem_anim.scene.schema` lists every key with its type, default, unit and meaning
(:func:`scene_keys`); :mod:`~fem_anim.scene.constraints` says what one key's value may be;
:mod:`~fem_anim.scene.loading` makes a :class:`Scene` from a file, a TOML string or a dict,
with ``--set`` overrides; :mod:`~fem_anim.scene.validation` checks it key by key and
:mod:`~fem_anim.scene.consistency` the keys against each other (contact settings against the
scene's scales in :mod:`~fem_anim.scene.contact_limits`, a shell scene's rules in
:mod:`~fem_anim.scene.shell_rules`); :mod:`~fem_anim.scene.modes`
holds ``solver.mode``'s named sets of solver keys. A scene is validated once, here, at the
boundary; everything downstream reads a checked :class:`Scene`.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "MAX_BARRIER_RATIO": "contact_limits",
    "MAX_FRICTION": "contact_limits",
    "MIN_BARRIER_RATIO": "contact_limits",
    "MIN_DHAT_RATIO": "contact_limits",
    "body_box": "contact_limits",
    "check_contact_limits": "contact_limits",
    "HESSIAN_METHODS": "consistency",
    "MAX_CELLS": "consistency",
    "MIXED_MODELS": "consistency",
    "MIXED_PRESETS": "consistency",
    "OBSTACLE_KEYS": "consistency",
    "REGION_MATERIAL_KEYS": "consistency",
    "check_consistency": "consistency",
    "check_render": "consistency",
    "MIXED_DEFAULT_PRESET": "modes",
    "CONTACT_INTEGRATOR": "contact_integrator",
    "check_integrator": "contact_integrator",
    "integrator_note": "contact_integrator",
    "SOLVER_MODES": "modes",
    "apply_solver_mode": "modes",
    "DEFAULTS": "schema",
    "KeyInfo": "schema",
    "SCHEMA": "schema",
    "SECTIONS": "schema",
    "scene_keys": "schema",
    "Scene": "loading",
    "default_scene_text": "loading",
    "load_scene": "loading",
    "parse_override": "loading",
    "validate_render": "loading",
    "validate_scene": "validation",
    "SHELL_MODELS": "shell_rules",
    "check_shell": "shell_rules",
    "JOINT_INTEGRATORS": "joint_rules",
    "check_joint": "joint_rules",
    "check_joint_parts": "joint_rules",
    "joint_parts": "joint_rules",
    "shell_body": "joint_rules",
})
