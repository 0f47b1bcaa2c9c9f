"""A run's frames rendered side by side in worker processes, handed back in order.

Each worker is a fork of the rendering process made before any render window exists, so
it inherits the trajectory and the imported modules without pickling or importing them
again, and opens its own off-screen plotter (:class:`~fem_anim.render.frames.FrameRenderer`)
once. Frames go to the workers in order; each worker renders its frame, writes its PNG
(:func:`~fem_anim.render.png_writer.write_png`) and sends the image back, and
:func:`frame_images` yields the images in frame order, so the caller writes the GIF and the
MP4 as if it had rendered them itself. Mesa's software rasteriser (llvmpipe) threads each
frame itself; a worker is given its share of the CPUs (``LP_NUM_THREADS``) unless the user
set it.

Workers ignore SIGINT (the parent decides what an interrupt does: it stops the pool and
removes the staged files) and die on SIGTERM, which the pool sends them when it stops.
"""

from __future__ import annotations

import os
import signal
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from fem_anim.render.png_writer import write_png

__all__ = ["FrameJob", "frame_images", "worker_count", "worker_signals"]


@dataclass
class FrameJob:
    """Everything a worker needs to render any frame of a run."""

    points: np.ndarray  # (n, d) rest positions
    cells: np.ndarray  # (m, d + 1)
    settings: dict  # the resolved [render] table
    clim: tuple[float, float]
    stage: tuple[np.ndarray, float]  # the bodies' centre and size over the run
    obstacles: list  # [[obstacle]] tables
    displacement: np.ndarray  # (k, n, d)
    values: np.ndarray  # (k, n) or (k, m)
    titles: list[str]
    shots: list  # one camera.Shot per frame
    frame_paths: list[Path | None]  # where each frame's PNG goes (None: nowhere)


def worker_count(settings: dict, frames: int) -> int:
    """``render.workers`` (no more than the frames), else 1: the calling process alone.

    Several workers are opt-in: on Python 3.13 (Debian 13) a render process interrupted while
    its forked workers rendered was seen to hang with them instead of exiting.

    Args:
        settings: The ``[render]`` table.
        frames: How many frames will be rendered.

    Returns:
        The number of processes rendering (1: the calling process alone).
    """
    if settings.get("workers"):
        return max(1, min(int(settings["workers"]), frames))
    return 1


_job: FrameJob | None = None
_renderer = None


def _open(job: FrameJob):
    from fem_anim.render.frames import FrameRenderer

    return FrameRenderer(job.points, job.cells, job.settings, job.clim, job.stage,
                         job.obstacles)


def _render(renderer, job: FrameJob, k: int) -> np.ndarray:
    image = renderer.render(job.displacement[k], job.values[k], job.titles[k], job.shots[k])
    if job.frame_paths[k] is not None:
        write_png(job.frame_paths[k], image)
    return image


def worker_signals() -> None:
    """In a forked worker: ignore SIGINT (the parent handles it), die on SIGTERM and SIGHUP."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def _start_worker(threads: int) -> None:
    global _renderer
    worker_signals()
    os.environ.setdefault("LP_NUM_THREADS", str(threads))
    _renderer = _open(_job)


def _work(k: int) -> np.ndarray:
    return _render(_renderer, _job, k)


def frame_images(job: FrameJob, order: list[int], workers: int) -> Iterator[np.ndarray]:
    """Render the frames ``order`` of ``job`` and yield their images in that order.

    Args:
        job: The run's frames and how to draw them.
        order: Frame indices to render.
        workers: Processes to render in (1: this process).

    Yields:
        Each frame's image, (height, width, 3) uint8, its PNG already written.
    """
    global _job
    if workers <= 1:
        renderer = _open(job)
        try:
            for k in order:
                yield _render(renderer, job, k)
        finally:
            renderer.close()
        return
    import multiprocessing

    from fem_anim.render.frames import _pyvista

    _pyvista()  # imported once, here: the workers inherit it (no render window exists yet)
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
    _job = job  # inherited by the forked workers
    try:
        context = multiprocessing.get_context("fork")
        pool = context.Pool(workers, initializer=_start_worker,
                            initargs=(max(1, cpus // workers),))
        try:
            yield from pool.imap(_work, order)
        except BaseException:
            pool.terminate()  # an interrupt or an error: stop the workers now
            raise
        pool.close()  # done: let the workers exit on their own
        pool.join()
    finally:
        _job = None
