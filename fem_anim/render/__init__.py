"""Render: the pictures of a run, made in a separate process that never imports DOLFINx.

:mod:`~fem_anim.render.process` starts that process; :mod:`~fem_anim.render.animation` reads a
run directory back and writes the PNG frames, the GIF and MP4 animations and ``final.png``
with the off-screen pyvista renderer of :mod:`~fem_anim.render.frames`;
:mod:`~fem_anim.render.plots` draws ``stats.csv`` (energies, Newton and linear iterations).
Public names load lazily, so importing this package loads neither pyvista nor DOLFINx.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "MAX_GIF_FPS": "animation",
    "REQUIRED_FILES": "animation",
    "RunFrames": "animation",
    "check_run_directory": "animation",
    "frame_values": "animation",
    "gif_stride": "animation",
    "read_run": "animation",
    "render_directory": "animation",
    "DEFAULT_SETTINGS": "frames",
    "FIELD_LABELS": "frames",
    "FrameRenderer": "frames",
    "VIEWS": "frames",
    "body_labels": "frames",
    "render_frame": "frames",
    "render_vtu": "frames",
    "PLOT_COLUMNS": "plots",
    "read_stats": "plots",
    "write_plots": "plots",
    "render_file": "process",
    "render_run": "process",
})
