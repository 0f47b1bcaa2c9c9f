"""Scenes: the TOML schema with its defaults, loading and ``--set`` overrides, the cross-key
consistency rules, and ``solver.mode``'s named sets of solver keys. A scene is validated once,
here, at the boundary; everything downstream reads a checked :class:`Scene`.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "HESSIAN_METHODS": "consistency",
    "MAX_CELLS": "consistency",
    "MIXED_MODELS": "consistency",
    "MIXED_PRESETS": "consistency",
    "OBSTACLE_KEYS": "consistency",
    "REGION_MATERIAL_KEYS": "consistency",
    "check_consistency": "consistency",
    "check_render": "consistency",
    "SOLVER_MODES": "modes",
    "apply_solver_mode": "modes",
    "DEFAULTS": "schema",
    "SCHEMA": "schema",
    "Scene": "schema",
    "default_scene_text": "schema",
    "load_scene": "schema",
    "parse_override": "schema",
    "validate_render": "schema",
})
