"""The ``[render]`` keys whose default depends on the scene: a shot or an engineering plot.

Two kinds of scene are told apart by what they hold:

* **held** (a ``[[pin]]`` anywhere, or no scene to look at): a body deflecting from its
  rest shape. The rest-shape ghost (``render.ghost``) is the reference the deflection is
  seen against, and the cell edges (``render.show_edges``) show the mesh.
* **free** (no pins: thrown, dropped, piled bodies): the rest shape is where a body
  started, an outline left hanging in the air once it has moved, and edges are noise on a
  shaded surface. Both are off.

``render.color_by`` is ``body`` (one colour per body) when the mesh has several connected
parts (a ``[[body]]`` scene), else ``displacement``. ``render.camera`` is resolved by
:func:`fem_anim.render.camera.camera_mode`.
"""

from __future__ import annotations

import numpy as np

from fem_anim.mesh.connectivity import cell_components

__all__ = ["is_held", "resolve_settings", "DEFAULT_SETTINGS"]

#: The ``[render]`` table's defaults (see fem_anim/scene/schema.py); ``None``: derived here.
DEFAULT_SETTINGS = {"color_by": None, "colormap": "viridis", "view": "auto", "camera": None,
                    "camera_position": None, "focal_point": None, "view_up": None,
                    "fov": 30.0, "background": "white", "window_size": [800, 600],
                    "show_edges": None, "ghost": None, "obstacles": True, "shadows": False,
                    "workers": None, "outputs": ["frames", "gif", "mp4"], "fps": None}


def is_held(scene: dict | None) -> bool:
    """Whether a scene holds a body by pins (``True`` without a scene).

    Args:
        scene: The run's scene table (``scene.json``'s ``scene``), or ``None``.

    Returns:
        True if the scene or one of its bodies has a ``[[pin]]``, or it is unknown.
    """
    if scene is None:
        return True
    return bool(scene.get("pin")) or any(body.get("pin") for body in scene.get("body") or [])


def resolve_settings(settings: dict, cells: np.ndarray, scene: dict | None) -> dict:
    """The ``[render]`` table with every scene-dependent default filled in.

    Args:
        settings: The ``[render]`` table (keys absent or ``None``: default).
        cells: The mesh's cells (several connected parts: several bodies).
        scene: The run's scene table, or ``None`` (a lone ``.vtu``).

    Returns:
        A new table: :data:`DEFAULT_SETTINGS` overlaid with the given keys, ``color_by``,
        ``ghost`` and ``show_edges`` decided as the module says.
    """
    given = {k: v for k, v in settings.items() if v is not None}
    resolved = DEFAULT_SETTINGS | given
    held = is_held(scene)
    if resolved["color_by"] is None:
        parts = cell_components(cells, int(cells.max()) + 1)
        resolved["color_by"] = "body" if parts.max() > 0 else "displacement"
    for key in ("ghost", "show_edges"):
        if resolved[key] is None:
            resolved[key] = held
    return resolved
