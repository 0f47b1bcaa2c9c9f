"""Render: the pictures of a run, made in a separate process that never imports DOLFINx.

:mod:`~fem_anim.render.process` starts that process; :mod:`~fem_anim.render.animation` reads a
run directory back and writes the PNG frames, the GIF and MP4 animations and ``final.png``
with the off-screen pyvista renderer of :mod:`~fem_anim.render.frames`, in worker processes
(:mod:`~fem_anim.render.parallel_frames`); :mod:`~fem_anim.render.camera` frames the bodies,
:mod:`~fem_anim.render.scenery` draws the obstacles and lights,
:mod:`~fem_anim.render.outer_surface` gives the surface drawn, and
:mod:`~fem_anim.render.render_defaults` the defaults that depend on the scene;
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
    "CAMERA_MODES": "camera",
    "Shot": "camera",
    "plan_shots": "camera",
    "VIEWS": "camera",
    "fit_distance": "camera",
    "view_axes": "camera",
    "DEFAULT_SETTINGS": "render_defaults",
    "resolve_settings": "render_defaults",
    "is_held": "render_defaults",
    "outer_faces": "outer_surface",
    "FrameJob": "parallel_frames",
    "frame_images": "parallel_frames",
    "worker_count": "parallel_frames",
    "obstacle_mesh": "scenery",
    "visible_obstacles": "scenery",
    "add_lights": "scenery",
    "plane_shade": "scenery",
    "tile_plane": "scenery",
    "FIELD_LABELS": "frames",
    "FrameRenderer": "frames",
    "body_labels": "frames",
    "render_frame": "frames",
    "stage_of": "frames",
    "render_vtu": "frames",
    "PLOT_COLUMNS": "plots",
    "read_stats": "plots",
    "write_plots": "plots",
    "render_file": "process",
    "render_run": "process",
})
