"""`metaopt replay --video`: film a run's best candidate, or another (``RUN:NUMBER``), with
Problem.video into an MP4 file.

Frames are encoded as they come (H.264, yuv420p: plays in browsers and common players) with the
ffmpeg that imageio-ffmpeg ships, so no system ffmpeg is needed and no video is held in memory.
"""

from __future__ import annotations

import os
from collections.abc import Generator
from pathlib import Path
from typing import Any

import imageio_ffmpeg
import numpy as np

from metaopt.assessment.replay import ReplaySource, replay_params
from metaopt.errors import ConfigError, MetaoptError
from metaopt.plugins import Registry
from metaopt.storage.whole_file import check_regular, temporary_beside

#: Video size (width, height), pixels, and frames per second of simulated time.
VIDEO_SIZE = (480, 360)
VIDEO_FPS = 25


class Mp4Writer:
    """Frames (height, width, 3) uint8 RGB in, an H.264 MP4 at path out, written whole or not
    at all: encoded into a hidden temporary file beside path (opened with the first frame, so
    nothing is written when none comes), renamed over path when the block ends well and
    removed when it ends with an error or Ctrl-C, so an earlier file at path stays as it was.

    ``with Mp4Writer(path, size, fps) as writer: writer(frame) ...``
    """

    def __init__(self, path: Path, size: tuple[int, int], fps: int) -> None:
        check_regular(path)  # a FIFO or device is refused, as for every whole-file write
        self.path, self.size, self.fps = path, size, fps
        self.frames = 0
        self._encoder: Generator[Any, bytes, None] | None = None
        self._temporary: Path | None = None

    def __enter__(self) -> Mp4Writer:
        return self

    def __exit__(self, error_type: type[BaseException] | None, *rest: object) -> None:
        """Finish and move the file into place when the block succeeded; else discard it."""
        if error_type is None:
            self.close()
        else:
            self.discard()

    def __call__(self, frame: np.ndarray) -> None:
        """Encode one frame; ValueError for one of another size or type."""
        width, height = self.size
        if frame.shape != (height, width, 3) or frame.dtype != np.uint8:
            raise ValueError(f"frame {frame.shape} {frame.dtype}: expected ({height}, {width}, 3)")
        if self._encoder is None:
            target = Path(os.path.realpath(self.path))  # a symlink is written through
            descriptor, self._temporary = temporary_beside(target, ".mp4")
            os.close(descriptor)
            self._encoder = imageio_ffmpeg.write_frames(
                str(self._temporary), self.size, fps=self.fps, codec="libx264",
                pix_fmt_out="yuv420p", macro_block_size=2, output_params=["-preset", "veryfast"],
            )  # fmt: skip
            self._encoder.send(None)
        self._encoder.send(np.ascontiguousarray(frame).tobytes())
        self.frames += 1

    def close(self) -> None:
        """Finish the file (flush the encoder) and rename it over path; on an error in doing
        so, remove it."""
        try:
            if self._encoder is not None:
                self._encoder.close()
                self._encoder = None
            if self._temporary is not None:
                os.replace(self._temporary, os.path.realpath(self.path))
                self._temporary = None
        except BaseException:
            self.discard()
            raise

    def discard(self) -> None:
        """Stop the encoder and remove the temporary file: path stays as it was."""
        try:
            if self._encoder is not None:
                encoder, self._encoder = self._encoder, None
                encoder.close()
        finally:
            if self._temporary is not None:
                self._temporary.unlink(missing_ok=True)
                self._temporary = None


def film_candidate(
    source: ReplaySource,
    plugins: Registry,
    overrides: dict[str, Any],
    path: Path,
    size: tuple[int, int] = VIDEO_SIZE,
    fps: int = VIDEO_FPS,
) -> int:
    """Film ``source``'s candidate with its (first) seed, problem parameters as stored but for
    ``overrides``, into path; returns the number of frames. An error (or Ctrl-C) writes no
    file: one at path before stays as it was (Mp4Writer)."""
    info, params = replay_params(source, plugins, overrides)
    problem = info.factory(**params)
    try:
        with Mp4Writer(path, size, fps) as writer:
            try:
                problem.video(source.x, source.seed, writer, size, fps)
            except NotImplementedError as missing:
                raise ConfigError(f"problem {source.problem!r}: {missing}") from None
            if writer.frames == 0:
                raise MetaoptError(f"{source.label} gave no frame to film")
    finally:
        problem.close()
    return writer.frames
