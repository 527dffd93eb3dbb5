"""Write rendered frames to an animated GIF or an MP4 file."""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from formation_env.core.errors import ControlDimension, FormationError

__all__ = ["VIDEO_SUFFIXES", "save_animation"]

VIDEO_SUFFIXES: tuple[str, ...] = (".gif", ".mp4")


def _check_frames(frames: Sequence[NDArray[np.uint8]]) -> tuple[int, int]:
    """Check that ``frames`` is a non-empty sequence of equal (H, W, 3) uint8 arrays; return (H, W)."""
    if len(frames) == 0:
        raise FormationError("save_animation needs at least one frame, got 0")
    first = frames[0]
    for i, frame in enumerate(frames):
        if not isinstance(frame, np.ndarray):
            raise TypeError(f"frames[{i}] must be a numpy array, got {type(frame).__name__}")
        if frame.dtype != np.uint8:
            raise FormationError(f"frames[{i}] must have dtype uint8, got {frame.dtype}")
        if frame.ndim != 3 or frame.shape[2] != 3:
            raise ControlDimension(f"frames[{i}] must have shape (H, W, 3), got {frame.shape}")
        if frame.shape != first.shape:
            raise ControlDimension(f"frames[{i}] has shape {frame.shape}, expected {first.shape} as frames[0]")
    return int(first.shape[0]), int(first.shape[1])


def save_animation(frames: Sequence[NDArray[np.uint8]], path: str | Path, fps: int = 20) -> Path:
    """Write ``frames`` to ``path`` as a looping GIF (``.gif``) or an H.264 MP4 (``.mp4``).

    Args:
        frames: sequence of (H, W, 3) uint8 RGB images, all the same shape (e.g. the
            output of ``Renderer.draw`` in ``rgb_array`` mode).
        path: output file; the suffix picks the format. Parent folders are created.
        fps: frames per second (GIF frame duration is 1000 / fps ms, rounded by the
            format to 10 ms; identical consecutive GIF frames are merged by Pillow).

    Returns:
        The path written, as a ``Path``.

    Raises:
        FormationError / ControlDimension (ValueError): no frames, wrong dtype or shape,
            mismatched shapes, fps <= 0 or an unsupported suffix.
        ImportError: ``.mp4`` asked for but ``imageio-ffmpeg`` is not installed.
    """
    out = Path(path)
    suffix = out.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise FormationError(f"save_animation path suffix must be one of {list(VIDEO_SUFFIXES)}, got {out.suffix!r}")
    if not (isinstance(fps, int | float) and fps > 0):
        raise FormationError(f"save_animation fps must be positive, got {fps!r}")
    _check_frames(frames)
    if suffix == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is None:
        raise ImportError(
            "writing .mp4 needs the imageio-ffmpeg package: `pip install imageio-ffmpeg`, or save as .gif instead"
        )
    out.parent.mkdir(parents=True, exist_ok=True)

    if suffix == ".gif":
        import imageio.v3 as iio

        gif: Any
        with iio.imopen(out, "w", plugin="pillow", extension=".gif") as gif:
            for frame in frames:
                gif.write(frame, is_batch=False, duration=1000.0 / fps, loop=0)
    else:
        import imageio.v2 as iio2

        writer: Any = iio2.get_writer(out, format="FFMPEG", mode="I", fps=fps, codec="libx264", pixelformat="yuv420p")
        try:
            for frame in frames:
                writer.append_data(frame)
        finally:
            writer.close()
    return out
