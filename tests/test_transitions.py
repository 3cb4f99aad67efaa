"""Demonstrations (benchmarks/transitions.py, docs/controllers.md §7): ``wip-bench compare
--record-transitions`` writes each controller's episodes as a Minari dataset whose arrays are
what the rollout saw, and whose actions replay its observations."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import minari
import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout
from benchmarks.transitions import datasets_root

ENV = "wip_gym/PlanarTray-v0"
CONTROLLERS = ("decoupled", "decoupled-lqr")
SEED, EPISODES, DURATION = 3, 2, 0.2


class Spy:
    """Keeps what the rollout hands its transition hook, as it is."""

    def __init__(self) -> None:
        self.reset: dict[str, Any] = {}
        self.steps: list[tuple[Any, ...]] = []

    def on_reset(self, observation: dict[str, Any]) -> None:
        self.reset = {k: np.array(v) for k, v in observation.items()}

    def on_step(self, action: Any, observation: Any, reward: Any, *ends: Any) -> None:
        self.steps.append(
            (np.array(action), {k: np.array(v) for k, v in observation.items()}, reward, *ends)
        )


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("compare")
    main(
        [
            "compare",
            "--env",
            ENV,
            "--controllers",
            ",".join(CONTROLLERS),
            "--episodes",
            str(EPISODES),
            "--seed",
            str(SEED),
            "--duration",
            str(DURATION),
            "--record-transitions",
            "--out",
            str(out),
        ]
    )
    return out


def test_one_dataset_per_controller_with_every_episode(run: Path) -> None:
    summary = json.loads((run / "summary.json").read_text())
    ids = summary["datasets"]["ids"]
    assert ids == {c: f"wip_gym/PlanarTray/{c}-v0" for c in CONTROLLERS}
    assert not (run / "transitions").exists()  # the episodes' files are gone
    lines = [json.loads(line) for line in (run / "episodes.jsonl").read_text().splitlines()]
    with datasets_root(run / "datasets"):
        assert sorted(minari.list_local_datasets()) == sorted(ids.values())
        for controller, dataset_id in ids.items():
            dataset = minari.load_dataset(dataset_id)
            assert dataset.total_episodes == EPISODES
            assert dataset.spec.env_spec is not None and dataset.spec.env_spec.id == ENV
            assert dataset.storage.metadata["algorithm_name"] == controller
            steps = [r["steps"] for r in lines if r["controller"] == controller]
            assert [len(e.rewards) for e in dataset.iterate_episodes()] == steps


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_the_arrays_are_what_the_rollout_saw(run: Path, controller: str) -> None:
    """Each episode against a rollout of the same seed that keeps what it hands the hook
    (the same episode: a seed's episode is the same to the bit on one machine)."""
    dataset = minari.MinariDataset(
        run / "datasets" / f"wip_gym/PlanarTray/{controller}-v0" / "data"
    )
    spec = resolve_run(ENV, [controller])
    for i, episode in enumerate(dataset.iterate_episodes()):
        spy = Spy()
        rollout(
            ENV,
            spec.env_kwargs,
            controller,
            spec.configs[controller],
            SEED + i,
            DURATION,
            on_transition=spy,
        )
        steps = len(spy.steps)
        assert len(episode.actions) == steps and steps == round(DURATION / 0.001)
        actions = np.array([s[0] for s in spy.steps])
        assert episode.actions.dtype == np.float64
        np.testing.assert_array_equal(episode.actions, actions, strict=True)
        for key, rows in episode.observations.items():
            seen = np.array([spy.reset[key]] + [s[1][key] for s in spy.steps])
            np.testing.assert_array_equal(rows, seen, strict=True)
        np.testing.assert_array_equal(episode.rewards, [s[2] for s in spy.steps], strict=True)
        np.testing.assert_array_equal(episode.terminations, [s[3] for s in spy.steps])
        # the duration cut it: its last step is a truncation, the others are what the env said
        np.testing.assert_array_equal(episode.truncations[:-1], [s[4] for s in spy.steps[:-1]])
        assert episode.truncations[-1] and not spy.steps[-1][4]


def test_the_actions_replay_the_observations(run: Path) -> None:
    """A user's check: the env the dataset names, reset with an episode's seed and stepped
    with its actions, gives its observations, rewards and terminations."""
    dataset = minari.MinariDataset(run / "datasets" / "wip_gym/PlanarTray/decoupled-v0" / "data")
    env = dataset.recover_environment()
    for i, episode in enumerate(dataset.iterate_episodes()):
        observation, _ = env.reset(seed=SEED + i)
        for key, rows in episode.observations.items():
            np.testing.assert_array_equal(rows[0], observation[key])
        for t, action in enumerate(episode.actions):
            observation, reward, terminated, _, _ = env.step(action)
            for key, rows in episode.observations.items():
                np.testing.assert_array_equal(rows[t + 1], observation[key])
            assert reward == episode.rewards[t] and terminated == episode.terminations[t]
    env.close()


def test_a_terminated_episode_ends_in_its_termination(tmp_path: Path) -> None:
    main(
        [
            "compare",
            "--env",
            "WIP-v0",
            "--controllers",
            "decoupled",
            "--duration",
            "0.5",
            "--set",
            "env.fall_angle=0.001",  # below the reset's lean: it falls at once
            "--record-transitions",
            "--out",
            str(tmp_path),
        ]
    )
    dataset = minari.MinariDataset(tmp_path / "datasets" / "wip_gym/WIP/decoupled-v0" / "data")
    episode = dataset[0]
    assert episode.terminations[-1] and not episode.terminations[:-1].any()
    assert not episode.truncations.any()
    assert len(episode.observations["qpos"]) == len(episode.actions) + 1 < 500


def test_without_minari_the_flag_is_a_usage_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "minari", None)  # import minari raises ImportError
    with pytest.raises(SystemExit) as exit_info:
        main(["compare", "--record-transitions", "--out", str(tmp_path / "run")])
    assert exit_info.value.code == 2
    assert "wip-gym[data]" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_a_second_run_replaces_its_datasets(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "again"
    for seed in ("0", "1"):
        main(
            [
                "compare",
                "--env",
                "Planar-v0",
                "--controllers",
                "decoupled",
                "--duration",
                "0.05",
                "--seed",
                seed,
                "--record-transitions",
                "--out",
                str(out),
            ]
        )
    dataset = minari.MinariDataset(out / "datasets" / "wip_gym/Planar/decoupled-v0" / "data")
    assert dataset.total_episodes == 1
    episode = dataset[0]
    env = gym.make("wip_gym/Planar-v0")
    first, _ = env.reset(seed=1)
    np.testing.assert_array_equal(episode.observations["qpos"][0], first["qpos"])
