"""Filming a walk: the backend renders the robot every few control steps, the camera following
the torso across the ground (at a fixed height, so the picture does not bob)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from metaopt.errors import ConfigError

from .episode import Disturbance, EpisodeRunner, Gait, Push

#: Height the camera looks at, m: about the middle of the standing robot.
CAMERA_TARGET_HEIGHT = 0.3


def film(
    runner: EpisodeRunner,
    gait: Gait,
    disturbance: Disturbance | None,
    frame: Callable[[np.ndarray], None],
    size: tuple[int, int],
    fps: int,
    push: Push | None = None,
) -> None:
    """Run one episode of gait (``push``: instead of the runner's, as EpisodeRunner.run),
    passing ``fps`` images per simulated second of the walking phase to ``frame`` (size =
    (width, height)); fps must divide the control rate."""
    period = runner.backend.settings.control_period
    every = round(1.0 / (fps * period))
    if every < 1 or abs(every * fps * period - 1.0) > 1e-9:
        rate = round(1.0 / period)
        divisors = ", ".join(str(n) for n in range(rate, 0, -1) if rate % n == 0)
        raise ConfigError(f"video fps must divide the {rate} Hz control rate: {divisors}")
    backend = runner.backend
    width, height = size

    def shoot(steps: int) -> None:
        if steps % every == 0:
            x, y, _ = backend.root_position()
            frame(backend.render(width, height, (float(x), float(y), CAMERA_TARGET_HEIGHT)))

    runner.run(gait, disturbance=disturbance, on_step=shoot, push=push)
