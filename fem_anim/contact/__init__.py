"""Contact: static obstacles as a smooth barrier in the step objective, contact between
surfaces by the IPC Toolkit (barrier, CCD, friction), and an independent check that no frame
has an intersection.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "boundary_triangles": "intersection",
    "crossed_frames": "intersection",
    "IPCContact": "ipc",
    "KEEP_FRACTION": "obstacles",
    "ObstacleContact": "obstacles",
    "contact_quadrature": "obstacles",
})
