"""The ``realistic`` preset and composed presets (docs/realism.md §7), in compare's resolver, its
command line and sweep specs; the shipped sweep specs validate."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks import presets
from benchmarks.cli import main
from benchmarks.overrides import resolve_run
from benchmarks.sweep.spec import SpecError, load_spec, parse_spec
from controllers.baselines.decoupled import DecoupledConfig

PLANAR_TRAY = "wip_gym/PlanarTray-v0"
SPECS = sorted((Path(__file__).parents[1] / "benchmarks" / "sweeps").glob("*.toml"))


def test_realistic_sets_env_arguments_only() -> None:
    spec = resolve_run(PLANAR_TRAY, ["decoupled"], "realistic")
    assert spec.env_kwargs == presets.REALISTIC
    assert spec.configs["decoupled"] == DecoupledConfig()
    assert spec.preset == "realistic"


@pytest.mark.parametrize(
    "composed", ["paper,realistic", " paper , realistic", ("paper", "realistic")]
)
def test_presets_compose_in_order(composed: str | tuple[str, ...]) -> None:
    spec = resolve_run(PLANAR_TRAY, ["decoupled"], composed)  # type: ignore[arg-type]
    paper = resolve_run(PLANAR_TRAY, ["decoupled"], "paper")
    assert spec.preset == "paper,realistic"
    assert spec.env_kwargs == {**paper.env_kwargs, **presets.REALISTIC}
    assert spec.configs["decoupled"] == DecoupledConfig.paper()  # the controllers' side: paper


def test_the_later_preset_wins_and_set_wins_over_both(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(presets.REALISTIC, "goal", 1.5)
    assert resolve_run(PLANAR_TRAY, ["decoupled"], "paper,realistic").env_kwargs["goal"] == 1.5
    assert resolve_run(PLANAR_TRAY, ["decoupled"], "realistic,paper").env_kwargs["goal"] == 5.0
    spec = resolve_run(
        PLANAR_TRAY, ["decoupled"], "paper,realistic", overrides={"env.sensor_noise": 3.0}
    )
    assert spec.env_kwargs["sensor_noise"] == 3.0


def test_single_presets_are_as_they_were() -> None:
    spec = resolve_run(PLANAR_TRAY, ["decoupled"], "paper")
    assert spec.preset == "paper"
    assert spec.env_kwargs == {"goal": 5.0, **presets.PAPER_TRAY}
    assert presets.canonical(None) is None and presets.controller_preset("realistic") is None


@pytest.mark.parametrize("bad", ["realism", "paper,paper", "paper,", ["paper", 3]])
def test_unknown_or_repeated_presets_are_refused(bad: object) -> None:
    with pytest.raises(ValueError, match="preset"):
        presets.preset_names(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("env_id", sorted(i for i in gym.registry if i.startswith("wip_gym/")))
def test_realistic_applies_to_every_env(env_id: str) -> None:
    spec = resolve_run(env_id, ["decoupled"], "realistic")
    env = gym.make(env_id, **spec.env_kwargs)
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step(np.zeros(env.action_space.shape))
    assert np.all(np.isfinite(obs["qpos"]))
    base = env.unwrapped
    assert base.perturbations.sensor_noise == 1.0 and base.model.na == base.model.nu


def test_compare_takes_composed_presets_and_refuses_unknown_ones(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = ["compare", "--env", PLANAR_TRAY, "--controllers", "decoupled", "--list-keys"]
    assert main([*args, "--preset", "paper,realistic"]) in (0, None)
    listed = capsys.readouterr().out
    line = next(row for row in listed.splitlines() if row.startswith("env.sensor_noise "))
    assert "0.0" in line  # the env's defaults (the preset's values apply at run time)
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--preset", "paper,realism"])
    assert exit_info.value.code == 2


SWEEP = """
env = "wip_gym/PlanarTray-v0"
controllers = ["decoupled"]
duration = 1.0
seeds = 1
preset = {preset}
[grid]
"env.sensor_noise" = [0.0, 1.0]
"""


def test_sweep_specs_take_a_composed_preset_as_a_string_or_a_list() -> None:
    text = parse_spec(SWEEP.format(preset='"paper,realistic"'), validate_env=False)
    listed = parse_spec(SWEEP.format(preset='["paper", "realistic"]'), validate_env=False)
    assert text.preset == listed.preset == "paper,realistic"
    assert [e.seed for e in text.episodes()] == [e.seed for e in listed.episodes()]
    single = parse_spec(SWEEP.format(preset='"paper"'), validate_env=False)
    assert single.preset == "paper"
    with pytest.raises(SpecError, match="preset"):
        parse_spec(SWEEP.format(preset='["paper", "nope"]'), validate_env=False)


@pytest.mark.parametrize("path", SPECS, ids=[p.name for p in SPECS])
def test_every_shipped_sweep_spec_validates(path: Path) -> None:
    spec = load_spec(path)
    assert spec.episodes()
