"""A learned policy as a controller (registry ``ppo``; docs/learning.md §8).

    policy = make_policy("ppo", env)                       # the shipped checkpoint of env's id
    policy = make_policy("ppo", env, LearnedConfig(checkpoint="out/ppo/checkpoint.npz"))

The checkpoint (written by ``examples/train_ppo.py`` with :func:`save_checkpoint`) holds the
policy's mean network (a tanh MLP), the running mean and standard deviation of the
observations it was trained on, and what it was trained with: the env, the control step
(``frame_skip``) and the observation's layout (``wip_gym.wrappers.ObservationNormalizer``).
Inference is NumPy: no JAX, no optax.

The action is the Gaussian policy's mean, clipped to ``[-1, 1]`` (counted as
``policy_clip_steps``) and mapped onto the torque limits as ``wip_gym.wrappers.ScaledAction``
does. A policy trained at a control step of ``k`` ms acts every ``k`` ms: on an env with a
shorter step it computes a new action every ``k / dt`` env steps and holds it in between (a
zero-order hold, what ``frame_skip`` does inside the env: on the 1 ms env the policy trained at
``frame_skip=10`` drives the same MuJoCo steps with the same torques). An env step that does
not divide the policy's, or is longer, is a ``ValueError``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self, cast

import numpy as np
from numpy.typing import NDArray

from controllers.policy import ModelChoice, PolicyBase, make_robot, task_info
from wip_gym.envs.base import wip_env
from wip_gym.wrappers import ObservationNormalizer

Array = NDArray[np.float64]
#: the checkpoints shipped with the package, one per env id: ``ppo_<name>.npz`` for
#: ``wip_gym/<name>``
CHECKPOINT_DIR = Path(__file__).resolve().parent / "checkpoints"
CHECKPOINT_FORMAT = 1


@dataclass(frozen=True)
class LearnedConfig:
    """Attributes:
    checkpoint: path of a checkpoint; "" (the default): the one shipped for the env's id
        (``controllers/checkpoints/ppo_<name>.npz``).
    model: unused (the policy has no model); kept for the registry's ``--model`` flag.
    """

    checkpoint: str = ""
    model: ModelChoice = "nominal"


@dataclass(frozen=True)
class Checkpoint:
    """A trained policy's mean network and what it was trained with.

    Attributes:
        weights, biases: the MLP's layers (``tanh`` between them, none after the last).
        obs_mean, obs_std: the running statistics that standardise its input.
        meta: ``env_id``, ``frame_skip``, ``control_dt``, ``wheel_angles``, ``tray``,
            ``observation_names``, ``training`` (the run's settings and budget), ``format``.
    """

    weights: tuple[Array, ...]
    biases: tuple[Array, ...]
    obs_mean: Array
    obs_std: Array
    meta: dict[str, Any]

    def mean_action(self, observation: NDArray[Any]) -> Array:
        """The policy's mean for flat observations (``(d,)`` or ``(n, d)``), unclipped."""
        h = (np.asarray(observation, dtype=np.float64) - self.obs_mean) / self.obs_std
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = h @ w + b
            if i < last:
                h = np.tanh(h)
        return h


def save_checkpoint(
    path: str | Path,
    weights: list[NDArray[Any]],
    biases: list[NDArray[Any]],
    obs_mean: NDArray[Any],
    obs_std: NDArray[Any],
    meta: dict[str, Any],
) -> None:
    """Write a checkpoint (``.npz``; weights as float32, the statistics as float64)."""
    for key in ("env_id", "frame_skip", "control_dt", "wheel_angles", "tray", "observation_names"):
        if key not in meta:
            raise ValueError(f"checkpoint meta needs {key!r}")
    arrays: dict[str, NDArray[Any]] = {
        "meta": np.array(json.dumps({**meta, "format": CHECKPOINT_FORMAT})),
        "obs_mean": np.asarray(obs_mean, dtype=np.float64),
        "obs_std": np.asarray(obs_std, dtype=np.float64),
    }
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        arrays[f"w{i}"] = np.asarray(w, dtype=np.float32)
        arrays[f"b{i}"] = np.asarray(b, dtype=np.float32)
    with open(path, "wb") as f:
        cast(Any, np.savez)(f, **arrays)  # numpy's stub takes **arrays for allow_pickle


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read a checkpoint; ``ValueError`` for a missing file, another format or bad shapes."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no checkpoint at {path}")
    with np.load(path, allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
        if meta.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"{path}: checkpoint format {meta.get('format')}, expected 1")
        layers = sum(1 for k in data.files if k.startswith("w"))
        weights = tuple(data[f"w{i}"].astype(np.float64) for i in range(layers))
        biases = tuple(data[f"b{i}"].astype(np.float64) for i in range(layers))
        mean, std = data["obs_mean"].copy(), data["obs_std"].copy()
    size = len(meta["observation_names"])
    if layers == 0 or weights[0].shape[0] != size or mean.shape != (size,) or std.shape != (size,):
        raise ValueError(f"{path}: the network's input does not match its {size} observations")
    if not (np.all(std > 0) and all(np.isfinite(w).all() for w in weights)):
        raise ValueError(f"{path}: non-finite weights or a non-positive observation scale")
    return Checkpoint(weights, biases, mean, std, meta)


def shipped_checkpoint(env_id: str) -> Path:
    """The shipped checkpoint of ``env_id``; ``ValueError`` naming those there are."""
    name = env_id.split("/")[-1]
    path = CHECKPOINT_DIR / f"ppo_{name}.npz"
    if not path.is_file():
        shipped = sorted(p.stem.removeprefix("ppo_") for p in CHECKPOINT_DIR.glob("ppo_*.npz"))
        raise ValueError(
            f"no shipped ppo checkpoint for {env_id} (shipped: {shipped}); train one with "
            f"examples/train_ppo.py and pass it as ppo.checkpoint=PATH"
        )
    return path


class LearnedController(PolicyBase):
    """A checkpoint's policy acting every ``frame_skip`` ms of its training (see the module)."""

    config_class = LearnedConfig
    registry_name = "ppo"

    def __init__(self, robot: Any, task: Any, config: LearnedConfig, env: Any) -> None:
        super().__init__(robot, task, config)
        base = wip_env(env)
        env_id = base.spec.id if base.spec is not None else ""
        path = Path(config.checkpoint) if config.checkpoint else shipped_checkpoint(env_id)
        self.checkpoint = load_checkpoint(path)
        self.checkpoint_path = str(path)
        meta = self.checkpoint.meta
        normalizer = ObservationNormalizer.for_env(env, meta["wheel_angles"], np.float64)
        if meta["tray"] and not normalizer.tray:
            raise ValueError(f"{path} was trained with a cup on a tray; {env_id} has none")
        # a policy trained without a cup may drive a tray task, blind to the cup
        self.normalizer = ObservationNormalizer(
            normalizer.layout,
            bool(meta["tray"]),
            normalizer.joint_low,
            normalizer.joint_high,
            meta["wheel_angles"],
            np.float64,
        )
        if self.normalizer.names != meta["observation_names"]:
            raise ValueError(
                f"{path} observes {meta['observation_names']}; {env_id} gives "
                f"{self.normalizer.names}"
            )
        ratio = float(meta["control_dt"]) / task.control_dt
        self.hold_steps = int(round(ratio))
        if self.hold_steps < 1 or not math.isclose(ratio, self.hold_steps, rel_tol=1e-9):
            raise ValueError(
                f"{path} acts every {meta['control_dt']} s; the env's step ({task.control_dt} s) "
                f"must divide it"
            )
        self._mid = (task.torque_high + task.torque_low) / 2.0
        self._half = (task.torque_high - task.torque_low) / 2.0
        self._held: Array = np.zeros_like(self._mid)
        self._policy_clips = 0

    @classmethod
    def for_env(cls, env: Any, config: Any = None) -> Self:
        config = LearnedConfig() if config is None else config
        if not isinstance(config, LearnedConfig):
            raise ValueError(
                f"LearnedController needs a LearnedConfig, got {type(config).__name__}"
            )
        return cls(make_robot(env, config.model), task_info(env, config.model), config, env)

    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        self.begin_episode()
        self._policy_clips = 0

    def action(self, observation: dict[str, Array]) -> Array:
        """The policy's torques for one ``Dict`` observation (no hold, no counting)."""
        mean = self.checkpoint.mean_action(self.normalizer(observation))
        return self._mid + self._half * np.clip(mean, -1.0, 1.0)

    def __call__(self, observation: dict[str, Array]) -> Array:
        if self._step % self.hold_steps == 0:
            mean = self.checkpoint.mean_action(self.normalizer(observation))
            if np.any(np.abs(mean) > 1.0):
                self._policy_clips += 1
            self._held = self._mid + self._half * np.clip(mean, -1.0, 1.0)
        self._step += 1
        return self.finish(self._held)

    def controller_counters(self) -> dict[str, float]:
        """``policy_clip_steps``: policy steps whose mean left ``[-1, 1]`` (clipped to it)."""
        return {"policy_clip_steps": float(self._policy_clips)}
