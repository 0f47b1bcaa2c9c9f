"""Pictures of a run, made in a separate process that never imports DOLFINx: off-screen frames
(pyvista), the GIF/MP4 animation, ``final.png`` and the plots of ``stats.csv``.
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
