"""``wip-bench figures``: the PNGs of a short run, flag validation, the camera projection."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest
from matplotlib import image as mpimg

from benchmarks import figures
from benchmarks.cli import main
from controllers.registry import controller_names

CONTROLLERS = ("unified", "decoupled")


@pytest.fixture(scope="module")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """One short run of both controllers (the unified one's reset compiles JAX: ~10 s)."""
    out = tmp_path_factory.mktemp("figures")
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        status = main(
            [
                "figures",
                "--env",
                "PlanarTray-v0",
                "--controllers",
                ",".join(CONTROLLERS),
                "--duration",
                "1.0",
                "--width",
                "160",
                "--height",
                "112",
                "--out",
                str(out),
            ]
        )
    assert status == 0
    return out, stdout.getvalue()


def expected_files() -> list[str]:
    names = [f"{c}_{kind}.png" for c in CONTROLLERS for kind in ("wipm", "snapshots")]
    return [*names, "comparison.png"]


@pytest.mark.parametrize("name", expected_files())
def test_each_png_is_valid_and_not_blank(short_run: tuple[Path, str], name: str) -> None:
    out, _ = short_run
    path = out / name
    assert path.is_file() and path.stat().st_size > 20_000
    pixels = mpimg.imread(path)  # raises on a broken PNG
    height, width = pixels.shape[:2]
    assert pixels.ndim == 3 and height >= 300 and width >= 600
    rgb = pixels[..., :3]
    assert rgb.std() > 0.05  # drawn axes and lines, not one flat colour
    if name == "comparison.png":  # line plots: each controller's colour is drawn
        for colour in ((31, 119, 180), (214, 39, 40)):  # matplotlib's tab:blue, tab:red
            near = np.abs(rgb * 255.0 - np.array(colour)).max(axis=2) < 30
            assert near.sum() > 2000, colour
    else:  # renders: a good share of coloured pixels
        assert (rgb.std(axis=2) > 0.05).mean() > 0.01


def test_paths_are_printed(short_run: tuple[Path, str]) -> None:
    out, stdout = short_run
    for name in expected_files():
        assert f"wrote {out / name}" in stdout
    for controller in CONTROLLERS:
        assert f"{controller}" in stdout and "peak |theta|" in stdout


def test_snapshots_show_the_robot_in_colour(short_run: tuple[Path, str]) -> None:
    out, _ = short_run
    pixels = mpimg.imread(out / "unified_snapshots.png")[..., :3]
    # the robot's orange links, the red tray and the blue marks: not a white page with text
    saturated = pixels.max(axis=2) - pixels.min(axis=2)
    assert (saturated > 0.3).mean() > 0.01
    orange = (pixels[..., 0] > 0.6) & (pixels[..., 2] < 0.4) & (pixels[..., 1] > 0.3)
    assert orange.mean() > 0.01


@pytest.mark.parametrize(
    ("flags", "valid"),
    [
        (["--env", "Nope-v0"], "wip_gym/PlanarTray-v0"),
        (["--controllers", "decoupled,nope"], "unified"),
        (["--controllers", ","], "decoupled"),
        (["--duration", "0"], "duration"),
        (["--goal", "1", "2", "3"], "goal"),
        (["--env", "Planar-v0", "--cup-friction", "0.5"], "tray"),
        (["--width", "0"], "width"),
    ],
)
def test_bad_flags_exit_2_with_the_valid_choices(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str], valid: str
) -> None:
    with pytest.raises(SystemExit) as error:
        main(["figures", "--out", str(tmp_path), *flags])
    assert error.value.code == 2
    message = capsys.readouterr().err
    assert valid in message
    assert not list(tmp_path.iterdir())  # nothing written


def test_unknown_controller_message_lists_every_controller(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["figures", "--controllers", "nope"])
    message = capsys.readouterr().err
    for name in controller_names():
        assert name in message


def test_projection_of_a_mujoco_camera() -> None:
    position = np.array([0.5, -4.0, 1.0])
    # a camera looking along +y (its -z), x to the right, y up
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    ahead = position + np.array([0.0, 3.0, 0.0])
    pixels = figures.project(
        np.array([ahead, ahead + [0.1, 0, 0], ahead + [0, 0, 0.1], position - [0, 1, 0]]),
        position,
        R,
        45.0,
        200,
        100,
    )
    np.testing.assert_allclose(pixels[0], [100.0, 50.0])
    focal = 50.0 / np.tan(np.radians(22.5))
    np.testing.assert_allclose(pixels[1], [100.0 + focal * 0.1 / 3.0, 50.0])  # right
    np.testing.assert_allclose(pixels[2], [100.0, 50.0 - focal * 0.1 / 3.0])  # up: v smaller
    assert np.all(np.isnan(pixels[3]))  # behind the camera


def test_snapshot_times_end_at_the_goal_or_the_run() -> None:
    np.testing.assert_allclose(figures.snapshot_times(10.0, 5.0), np.linspace(0, 5, 6))
    np.testing.assert_allclose(figures.snapshot_times(10.0, None), np.linspace(0, 10, 6))
    np.testing.assert_allclose(figures.snapshot_times(10.0, 0.0), np.linspace(0, 10, 6))


def test_the_reference_drawn_is_the_one_each_controller_tracks() -> None:
    """Krang 2014's ``decoupled`` balances about theta = 0 while it follows the plan's x; the
    figure draws that, not the plan's lean (which ``decoupled-lqr`` does track)."""
    from benchmarks.scenario import Scenario

    scenario = Scenario(env_id="wip_gym/Planar-v0", duration=1.5)
    krang = figures.run_controller(scenario, "decoupled", 0, 96, 64)
    lqr = figures.run_controller(scenario, "decoupled-lqr", 0, 96, 64)
    assert krang.plan is not None and np.abs(krang.plan.states[:150, 0]).max() > 0.01
    t, theta_ref = figures.wipm_references(krang)["theta"]
    assert len(t) > 1000 and np.all(theta_ref == 0.0)
    t, theta_ref = figures.wipm_references(lqr)["theta"]
    assert np.abs(theta_ref).max() > 0.01  # the plan's lean
    t, x_ref = figures.wipm_references(krang)["x"]
    np.testing.assert_allclose(x_ref, [krang.plan.sample(ti)["x"] for ti in t], atol=1e-9)
