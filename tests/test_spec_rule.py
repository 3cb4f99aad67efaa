"""``compare`` and the sweep read a spec by one rule: a ``plan.*`` key applies to every
controller of the run with an offline plan, leaves the others as they are (and says so), and is
refused before anything runs when no controller has a plan. A sweep's exit status says whether
every episode ran (docs/sweeps.md §2)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from benchmarks.overrides import OverrideError, config_dict, resolve_run
from benchmarks.sweep import cli as sweep_cli
from benchmarks.sweep import runner
from benchmarks.sweep.episode import run_episode_job
from benchmarks.sweep.keys import spec_keys_not_applied
from benchmarks.sweep.runner import make_job
from benchmarks.sweep.spec import SpecError, parse_spec
from controllers.policy import ModelChoice, PolicyBase
from controllers.registry import _REGISTRY, register

PLANAR = "wip_gym/PlanarTray-v0"


@dataclass(frozen=True)
class StillConfig:
    """Zero torques.

    Attributes:
        model: ``nominal`` or ``oracle``.
        gain: unused.
    """

    model: ModelChoice = "nominal"
    gain: float = 1.0


class StillController(PolicyBase):
    """Zero torques: a controller without an offline plan."""

    config_class = StillConfig

    def reset(self, observation: dict[str, NDArray[np.float64]], info: dict[str, Any]) -> None:
        self.begin_episode()

    def __call__(self, observation: dict[str, NDArray[np.float64]]) -> NDArray[np.float64]:
        self._step += 1
        joints = np.zeros(len(self.robot.layout.joint_actuators))
        return self.finish(self.assemble((0.0, 0.0), joints))


@pytest.fixture
def still():  # noqa: ANN201
    register("still", StillController, StillConfig)
    yield "still"
    _REGISTRY.pop("still")


def test_a_plan_key_leaves_a_controller_without_a_plan_alone_in_compare(still: str) -> None:
    spec = resolve_run(PLANAR, [still, "decoupled"], overrides={"plan.a_max": 0.5})
    assert spec.configs[still] == StillConfig()
    assert spec.configs["decoupled"].plan.a_max == 0.5
    assert spec.not_applied == {"plan.a_max": (still,)}
    assert resolve_run(PLANAR, ["decoupled"], overrides={"plan.a_max": 0.5}).not_applied == {}


def test_the_sweep_runs_such_an_episode_with_the_config_compare_resolves(still: str) -> None:
    """Before the rule, each episode of ``still`` resolved the key alone and failed."""
    spec = parse_spec(
        f'env = "{PLANAR}"\ncontrollers = ["{still}", "decoupled"]\nduration = 0.05\n'
        'seeds = 1\n[set]\n"plan.a_max" = 0.5\n"still.gain" = 2.0\n'
    )
    assert spec_keys_not_applied(spec) == {"plan.a_max": (still,)}
    compared = resolve_run(
        PLANAR, [still, "decoupled"], overrides={"plan.a_max": 0.5, "still.gain": 2.0}
    )
    for episode in spec.episodes():
        row = run_episode_job(make_job(spec, episode))
        assert row["steps"] == 50
        assert row["config"] == config_dict(compared.configs[episode.controller])


def test_a_plan_key_without_any_plan_is_refused_by_both(still: str) -> None:
    with pytest.raises(OverrideError, match="no controller of this run has an offline plan"):
        resolve_run(PLANAR, [still], overrides={"plan.a_max": 0.5})
    with pytest.raises(SpecError, match="no controller of this run has an offline plan"):
        parse_spec(
            f'env = "{PLANAR}"\ncontrollers = ["{still}"]\nduration = 0.05\nseeds = 1\n'
            '[grid]\n"plan.a_max" = [0.5, 1.0]\n'
        )


@pytest.mark.parametrize(
    ("summary", "status"),
    [
        ({"interrupted": False, "episodes_failed": 0}, 0),
        ({"interrupted": False, "episodes_failed": 3}, 1),
        ({"interrupted": True, "episodes_failed": 3}, 130),
    ],
)
def test_the_sweeps_exit_status(
    summary: dict[str, Any], status: int, tmp_path: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_text(f'env = "{PLANAR}"\ncontrollers = ["decoupled"]\nduration = 0.1\nseeds = 1\n')
    monkeypatch.setattr(runner, "run_sweep", lambda *args, **kwargs: summary)
    parser = argparse.ArgumentParser()
    sweep_cli.add_arguments(parser)
    args = parser.parse_args([str(spec), "--out", str(tmp_path / "out")])
    assert sweep_cli.run(args) == status
