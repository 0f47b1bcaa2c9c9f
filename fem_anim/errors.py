"""Typed errors of fem_anim (STYLE rule 8).

Library code raises these; only the command line turns them into a message and
exit code 2. Every message names the offending key, file or value.
"""

__all__ = ["FemAnimError", "SceneError", "MeshError", "ConvergenceError", "show_value"]


class FemAnimError(Exception):
    """Base class of every error fem_anim reports to a user."""


class SceneError(FemAnimError):
    """A scene file or override is malformed, of the wrong type or nonphysical."""


class MeshError(FemAnimError):
    """A mesh cannot be built or read, or is unusable (inverted, empty, ...)."""


class ConvergenceError(FemAnimError):
    """A time step's minimisation did not converge."""


def show_value(value: object, limit: int = 200) -> str:
    """``repr`` of a value for a message, cut short (a scene value may be megabytes)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"
