"""`metaopt replay --video`: every engine renders headless, the camera follows the torso, and the
MP4 holds one frame per 1/25 s of the walk."""

from __future__ import annotations

import ctypes.util
import os
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest

from metaopt.assessment.replay import find_source, run_source
from metaopt.cli.report import write_replay_video
from metaopt.errors import ConfigError
from metaopt.physics import PhysicsSettings
from metaopt.plugins import registry
from metaopt.reporting.video import VIDEO_FPS, Mp4Writer, film_candidate
from metaopt.running import RunSpec, run
from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.robot import nao
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait
from metaopt_problems.nao_walk.video import CAMERA_TARGET_HEIGHT, film
from tests.engines import needs_ode
from tests.walk_runs import store_walk_run

#: MuJoCo renders offscreen through a system OpenGL library (.ci/run installs Mesa's EGL);
#: PyBullet's software renderer needs nothing.
HEADLESS_GL = any(ctypes.util.find_library(name) for name in ("EGL", "OSMesa"))
ENGINES = (
    pytest.param(
        "mujoco",
        marks=pytest.mark.skipif(
            not HEADLESS_GL,
            reason="MuJoCo offscreen rendering needs libEGL or libOSMesa "
            "(apt-get install libegl1 libgl1-mesa-dri)",
        ),
    ),
    "pybullet",
    # ODE cannot draw: its poses are drawn through MuJoCo's renderer.
    pytest.param(
        "ode",
        marks=[
            needs_ode,
            pytest.mark.skipif(not HEADLESS_GL, reason="ODE's video draws with MuJoCo"),
        ],
    ),
)


@pytest.fixture(scope="module")
def walk_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("walk") / "runs.db"
    store_walk_run(db)
    return db


@pytest.mark.parametrize("engine", ENGINES)
def test_render_draws_the_robot_where_the_camera_looks(engine):
    backend = registry().physics_backend(engine).factory(nao(), PhysicsSettings())
    try:
        at_robot = backend.render(160, 120, (0.0, 0.0, 0.3))
        elsewhere = backend.render(160, 120, (20.0, 20.0, 0.3))
    finally:
        backend.close()
    assert at_robot.shape == (120, 160, 3) and at_robot.dtype == np.uint8
    centre = (slice(40, 80), slice(60, 100))  # the robot stands in the middle of the picture
    difference = np.abs(at_robot[centre].astype(int) - elsewhere[centre].astype(int)).mean()
    assert difference > 20


@pytest.mark.parametrize("engine", ENGINES)
def test_replay_video_is_a_valid_mp4_with_one_frame_per_25th_of_a_second(
    walk_db, tmp_path, engine, capsys
):
    path = tmp_path / f"walk-{engine}.mp4"
    source = find_source("1", registry(), str(walk_db))
    write_replay_video(source, {"backend": engine}, str(path))
    assert capsys.readouterr().out == f"wrote {path}: 50 frames, 480x360, 25 fps (2.0 s)\n"
    assert imageio_ffmpeg.count_frames_and_secs(str(path)) == (50, 2.0)
    frames = imageio_ffmpeg.read_frames(str(path))
    meta = next(frames)
    assert meta["size"] == (480, 360) and meta["fps"] == VIDEO_FPS
    first = np.frombuffer(next(frames), np.uint8).reshape(360, 480, 3)
    assert first.std() > 10  # a picture, not a blank frame


def test_the_camera_follows_the_torso():
    problem = registry().problem("nao-walk").factory(duration=3.0, lock=1.0)
    gait = problem.gait(gait_vector(load_gait()))
    walk = problem.runner.run(gait, record=True).trajectory
    targets = []

    def render(width: int, height: int, target: tuple[float, float, float]) -> np.ndarray:
        targets.append(target)
        return np.zeros((height, width, 3), np.uint8)

    problem.runner.backend.render = render
    frames: list[np.ndarray] = []
    film(problem.runner, gait, None, frames.append, (32, 24), 25)
    problem.close()
    assert len(frames) == 50
    expected = np.column_stack([walk["x"][1::2], walk["y"][1::2]])
    np.testing.assert_array_equal(np.array(targets)[:, :2], expected)
    assert {target[2] for target in targets} == {CAMERA_TARGET_HEIGHT}
    assert walk["x"][-1] - walk["x"][0] > 0.02  # it moved (0.032 m), and the camera went with it


def test_a_frame_rate_that_does_not_divide_the_control_rate_is_refused(walk_db, tmp_path):
    source = find_source("1", registry(), str(walk_db))
    with pytest.raises(ConfigError, match="50, 25, 10, 5, 2, 1"):
        film_candidate(source, registry(), {}, tmp_path / "walk.mp4", fps=30)
    assert not (tmp_path / "walk.mp4").exists()


def test_a_problem_without_video_says_so_in_one_line(tmp_path):
    plugins = registry()
    with RunStore(tmp_path / "runs.db") as store:
        spec = RunSpec("random", "sphere", 10, 1)
        run(spec, plugins.optimizer("random"), plugins.problem("sphere"), store)
        source = run_source(store, 1)
    with pytest.raises(ConfigError, match=r"^problem 'sphere': cannot show a video$"):
        film_candidate(source, plugins, {}, tmp_path / "walk.mp4")
    assert not (tmp_path / "walk.mp4").exists()


def _frame(size: tuple[int, int], shade: int) -> np.ndarray:
    width, height = size
    return np.full((height, width, 3), shade, dtype=np.uint8)


@pytest.mark.parametrize("stop", [ValueError, KeyboardInterrupt])
def test_a_video_that_fails_midway_leaves_no_file_and_the_earlier_one_as_it_was(tmp_path, stop):
    """The real encoder takes a few frames, then a wrong-sized one (ValueError) or Ctrl-C:
    neither a half-written MP4 nor its temporary file is left, and a file at the path before
    is untouched; a video that ends well replaces it whole."""
    size = (32, 24)
    path = tmp_path / "walk.mp4"
    for before in (None, b"an earlier good video"):
        if before is not None:
            path.write_bytes(before)
        with pytest.raises(stop), Mp4Writer(path, size, VIDEO_FPS) as writer:
            for shade in range(5):
                writer(_frame(size, 40 * shade))
            if stop is KeyboardInterrupt:
                raise KeyboardInterrupt
            writer(_frame((16, 16), 0))
        assert writer.frames == 5
        assert [p.name for p in tmp_path.iterdir()] == ([] if before is None else ["walk.mp4"])
        assert before is None or path.read_bytes() == before
    with Mp4Writer(path, size, VIDEO_FPS) as writer:
        for shade in range(5):
            writer(_frame(size, 40 * shade))
    assert [p.name for p in tmp_path.iterdir()] == ["walk.mp4"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # as a file opened there, not 0600
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert tuple(meta["size"]) == size and sum(1 for _ in reader) == 5
