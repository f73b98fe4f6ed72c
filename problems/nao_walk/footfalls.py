"""How a gait uses its feet: contact, flight and slip, measured from the ground-contact forces
and the feet's positions over one episode (is it a walk, a run, a shuffle or a slide?)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .episode import CONTACT_FORCE_N, SETTLE_S, EpisodeRunner, Gait


@dataclass(frozen=True)
class Footfalls:
    """Foot use over the walking phase after SETTLE_S (until the end or a fall)."""

    contact: tuple[float, float]  #: share of the time each foot (left, right) touches the ground
    flight: float  #: share of the time neither foot does
    double_support: float  #: share of the time both do
    stride_frequency: float  #: gait cycles per second (the load moving from foot to foot), Hz
    stride_length: float  #: forward travel per gait cycle (two steps), m
    slip_speed: float  #: median horizontal speed of a foot while it touches the ground, m/s


def footfalls(runner: EpisodeRunner, gait: Gait) -> Footfalls:
    """Run one noise-free episode of gait on runner's backend and measure its foot use.

    The stride frequency is the strongest frequency of the load moving from foot to foot (the
    left foot's contact force less the right's; counting touchdowns would also count the
    bounces of a vibrating foot); the stride length is the torso's forward speed over it."""
    backend = runner.backend
    period = backend.settings.control_period
    feet = backend.robot.contact_bodies  # the bodies contact_forces() reports, in its order
    if len(feet) != 2:
        raise ValueError(f"footfalls needs a robot with two feet, not contact bodies {feet}")
    rows: list[list[float]] = []

    def sample(steps: int) -> None:
        if steps * period > SETTLE_S:
            left, right = (backend.body_position(foot)[:2] for foot in feet)
            forces = backend.contact_forces()
            torso_x = float(backend.root_position()[0])
            rows.append([*left, *right, float(forces[0]), float(forces[1]), torso_x])

    runner.run(gait, on_step=sample)
    if len(rows) < 2:
        raise ValueError(f"the episode ended within {SETTLE_S} s of walking: nothing to measure")
    table = np.array(rows)
    touching = table[:, 4:6] > CONTACT_FORCE_N
    slips = []
    for foot in (0, 1):
        still = touching[1:, foot] & touching[:-1, foot]
        travel = np.diff(table[:, 2 * foot : 2 * foot + 2], axis=0)
        slips.extend(np.linalg.norm(travel, axis=1)[still] / period)
    torso_x = table[:, 6]
    load = table[:, 4] - table[:, 5]
    spectrum = np.abs(np.fft.rfft(load - load.mean()))
    spectrum[0] = 0.0
    frequency = float(np.fft.rfftfreq(len(load), period)[int(np.argmax(spectrum))])
    speed = (torso_x[-1] - torso_x[0]) / ((len(table) - 1) * period)
    return Footfalls(
        contact=(float(touching[:, 0].mean()), float(touching[:, 1].mean())),
        flight=float((~touching.any(axis=1)).mean()),
        double_support=float(touching.all(axis=1).mean()),
        stride_frequency=frequency,
        stride_length=speed / frequency if frequency > 0 else 0.0,
        slip_speed=float(np.median(slips)) if slips else 0.0,
    )
