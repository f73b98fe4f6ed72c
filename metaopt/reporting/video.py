"""`metaopt replay --video`: film a run's best candidate, or another (``RUN:NUMBER``), with
Problem.video into an MP4 file.

Frames are encoded as they come (H.264, yuv420p: plays in browsers and common players) with the
ffmpeg that imageio-ffmpeg ships, so no system ffmpeg is needed and no video is held in memory.
"""

from __future__ import annotations

from collections.abc import Generator
from pathlib import Path
from typing import Any

import imageio_ffmpeg
import numpy as np

from metaopt.assessment.replay import ReplaySource, replay_params
from metaopt.errors import ConfigError, MetaoptError
from metaopt.plugins import Registry

#: Video size (width, height), pixels, and frames per second of simulated time.
VIDEO_SIZE = (480, 360)
VIDEO_FPS = 25


class Mp4Writer:
    """Frames (height, width, 3) uint8 RGB in, an H.264 MP4 at path out; the file is opened
    with the first frame, so nothing is written when none comes."""

    def __init__(self, path: Path, size: tuple[int, int], fps: int) -> None:
        self.path, self.size, self.fps = path, size, fps
        self.frames = 0
        self._encoder: Generator[Any, bytes, None] | None = None

    def __call__(self, frame: np.ndarray) -> None:
        width, height = self.size
        if frame.shape != (height, width, 3) or frame.dtype != np.uint8:
            raise ValueError(f"frame {frame.shape} {frame.dtype}: expected ({height}, {width}, 3)")
        if self._encoder is None:
            self._encoder = imageio_ffmpeg.write_frames(
                str(self.path), self.size, fps=self.fps, codec="libx264", pix_fmt_out="yuv420p",
                macro_block_size=2, output_params=["-preset", "veryfast"],
            )  # fmt: skip
            self._encoder.send(None)
        self._encoder.send(np.ascontiguousarray(frame).tobytes())
        self.frames += 1

    def close(self) -> None:
        """Finish the file (flush the encoder)."""
        if self._encoder is not None:
            self._encoder.close()
            self._encoder = None


def film_candidate(
    source: ReplaySource,
    plugins: Registry,
    overrides: dict[str, Any],
    path: Path,
    size: tuple[int, int] = VIDEO_SIZE,
    fps: int = VIDEO_FPS,
) -> int:
    """Film ``source``'s candidate with its (first) seed, problem parameters as stored but for
    ``overrides``, into path; returns the number of frames (an error keeps those so far)."""
    info, params = replay_params(source, plugins, overrides)
    problem = info.factory(**params)
    writer = Mp4Writer(path, size, fps)
    try:
        problem.video(source.x, source.seed, writer, size, fps)
    except NotImplementedError as missing:
        raise ConfigError(f"problem {source.problem!r}: {missing}") from None
    finally:
        writer.close()
        problem.close()
    if writer.frames == 0:
        raise MetaoptError(f"{source.label} gave no frame to film")
    return writer.frames
