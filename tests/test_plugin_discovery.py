"""An outside package's plugins show up through its entry point, with no change to metaopt."""

from tests.conftest import metaopt_cli

ALL = {"METAOPT_LOAD_PLUGINS": None}


def test_outside_plugin_is_listed_and_runs(tmp_path, outside_plugin_path):
    listing = metaopt_cli("list", cwd=tmp_path, extra_path=outside_plugin_path, env=ALL)
    assert listing.returncode == 0, listing.stderr
    assert "hill-climb" in listing.stdout and "bowl" in listing.stdout
    assert "metaopt-example-plugin" in listing.stdout  # where it comes from

    done = metaopt_cli(
        "run", "-o", "hill-climb", "-p", "bowl", "--seed", "3", "--set", "step=0.1",
        "--set", "nan_above=2.5", "--set", "raise_above=2.5",
        cwd=tmp_path, extra_path=outside_plugin_path, env=ALL,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "200 (" in done.stdout  # the problem's default budget
    assert "distance" in done.stdout  # its key metric

    # A built-in optimizer on the outside problem, and failures are reported, not fatal.
    mixed = metaopt_cli(
        "run", "-o", "random", "-p", "bowl", "--budget", "300", "--set", "nan_above=0",
        cwd=tmp_path, extra_path=outside_plugin_path, env=ALL,
    )  # fmt: skip
    assert mixed.returncode == 0, mixed.stderr
    assert "failed; their errors are stored" in mixed.stdout


def test_environment_variable_restricts_loaded_plugins(tmp_path, outside_plugin_path):
    only = metaopt_cli(
        "list", cwd=tmp_path, extra_path=outside_plugin_path,
        env={"METAOPT_LOAD_PLUGINS": "example,functions"},
    )  # fmt: skip
    assert only.returncode == 0, only.stderr
    assert "hill-climb" in only.stdout and "sphere" in only.stdout
    assert "hs " not in only.stdout and "harmony" not in only.stdout.lower()
    none = metaopt_cli("list", cwd=tmp_path, env={"METAOPT_LOAD_PLUGINS": ""})
    assert none.returncode == 0 and "sphere" not in none.stdout


def test_available_physics_backends_leave_out_an_engine_that_cannot_run_here():
    """MuJoCo and PyBullet come with their wheels; ODE needs libode8, which CI installs."""
    from metaopt.plugins import registry
    from tests.engines import ODE_MISSING

    available = registry().available_physics_backends()
    assert {"mujoco", "pybullet"} <= set(available) <= set(registry().physics_backends)
    assert ("ode" in available) == (not ODE_MISSING)
    assert available == [name for name in registry().physics_backends if name in available]
