"""Demonstrations: every controller's episodes as a Minari dataset (docs/controllers.md §7).

``wip-bench compare --record-transitions`` keeps each episode's stream of observations,
actions, rewards, terminations and truncations (:class:`TransitionRecorder`, a hook of the
rollout: ``benchmarks.rollout``), saves it beside the run while the episodes run (each in its
own worker process with ``--jobs``), and at the end writes one Minari dataset per controller
(:func:`write_datasets`): ``<out>/datasets/wip_gym/<env name>/<controller>-v0``, a standard
offline-learning dataset (Minari 0.5, HDF5: one group per episode with ``observations`` (the
reset's and every step's, ``T + 1`` rows, a group per observation key), ``actions`` (``T``
rows, float64 as the controller gave them), ``rewards``, ``terminations``, ``truncations``;
the episode's seed as an attribute; the env's spec, with its arguments, in the metadata), read
with ``minari.load_dataset`` under ``MINARI_DATASETS_PATH=<out>/datasets`` or
``minari.MinariDataset(<dataset dir>/data)``.

An episode that reaches compare's ``--duration`` without ending is truncated there: its last
step's truncation is True (the env itself did not end it; every episode of a dataset ends in a
termination or a truncation). Infos are not kept.
"""

from __future__ import annotations

import json
import os
import shutil
import warnings
from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

#: the namespace of the datasets' ids (``wip_gym/<env name>/<controller>-v0``)
NAMESPACE = "wip_gym"
DATASETS_DIR = "datasets"
EPISODES_DIR = "transitions"  # the episodes' streams while the run goes on (removed after)
FORMAT_VERSION = 1


def require_minari() -> None:
    """``ValueError`` (a usage error: nothing has run) when Minari is not installed."""
    try:
        import minari  # noqa: F401
    except ImportError:
        raise ValueError(
            "--record-transitions writes Minari datasets: pip install 'wip-gym[data]' "
            "(minari[hdf5])"
        ) from None


class TransitionRecorder:
    """An episode's stream: :meth:`on_reset` with the reset's observation, then
    :meth:`on_step` after every ``env.step``; :meth:`save` writes it (``.npz``)."""

    def __init__(self) -> None:
        self._observations: dict[str, list[NDArray[Any]]] = {}
        self._actions: list[NDArray[np.float64]] = []
        self._rewards: list[float] = []
        self._terminations: list[bool] = []
        self._truncations: list[bool] = []

    def on_reset(self, observation: Mapping[str, Any]) -> None:
        """Start the episode at the reset's observation (a dict of arrays)."""
        self._observations = {key: [np.array(value)] for key, value in observation.items()}
        self._actions, self._rewards = [], []
        self._terminations, self._truncations = [], []

    def on_step(
        self,
        action: NDArray[Any],
        observation: Mapping[str, Any],
        reward: SupportsFloat,
        terminated: bool,
        truncated: bool,
    ) -> None:
        """One step: the action given and what the env returned."""
        if not self._observations:
            raise RuntimeError("TransitionRecorder.on_step before on_reset")
        self._actions.append(np.array(action, dtype=np.float64))
        for key, rows in self._observations.items():
            rows.append(np.array(observation[key]))
        self._rewards.append(float(reward))
        self._terminations.append(bool(terminated))
        self._truncations.append(bool(truncated))

    def arrays(self) -> dict[str, NDArray[Any]]:
        """The episode as arrays: ``observations/<key>`` (``T + 1`` rows), ``actions``,
        ``rewards``, ``terminations``, ``truncations`` (``T`` rows); the last step truncated
        when neither the env ended the episode (the rollout's duration did)."""
        if not self._observations:
            raise RuntimeError("nothing recorded: call on_reset first")
        truncations = np.array(self._truncations, dtype=np.bool_)
        terminations = np.array(self._terminations, dtype=np.bool_)
        if len(truncations) and not (terminations[-1] or truncations[-1]):
            truncations[-1] = True
        arrays = {f"observations/{k}": np.array(v) for k, v in self._observations.items()}
        steps = len(self._actions)
        arrays.update(
            actions=np.array(self._actions).reshape(steps, -1),
            rewards=np.array(self._rewards, dtype=np.float64),
            terminations=terminations,
            truncations=truncations,
        )
        return arrays

    def save(self, path: str | Path, seed: int) -> Path:
        """Write the episode (``.npz``) with its ``seed``."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        header = json.dumps({"version": FORMAT_VERSION, "seed": int(seed)})
        arrays = cast(dict[str, Any], {"header": np.array(header), **self.arrays()})
        np.savez(path, **arrays)
        return path


def episode_file(out: Path, controller: str, index: int) -> Path:
    """Where compare keeps episode ``index`` of ``controller`` until the datasets are made."""
    return out / EPISODES_DIR / controller / f"episode_{index:05d}.npz"


def dataset_id(env_id: str, controller: str) -> str:
    """``wip_gym/<env name>/<controller>-v0`` (``wip_gym/PlanarTray/unified-v0``)."""
    return f"{NAMESPACE}/{gym.spec(env_id).name}/{controller}-v0"


def _episode_buffer(path: Path, index: int) -> Any:
    from minari.data_collector import EpisodeBuffer

    with np.load(path, allow_pickle=False) as data:
        header = json.loads(str(data["header"]))
        if header.get("version") != FORMAT_VERSION:
            raise ValueError(f"{path}: transitions version {header.get('version')!r}")
        prefix = "observations/"
        return EpisodeBuffer(
            id=index,
            seed=header["seed"],
            observations={k[len(prefix) :]: data[k] for k in data.files if k.startswith(prefix)},
            actions=data["actions"],
            rewards=data["rewards"].tolist(),
            terminations=data["terminations"].tolist(),
            truncations=data["truncations"].tolist(),
        )


@contextmanager
def datasets_root(root: Path) -> Any:
    """Minari's datasets directory (``MINARI_DATASETS_PATH``) set to ``root`` for a while."""
    before = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    try:
        yield root
    finally:
        if before is None:
            del os.environ["MINARI_DATASETS_PATH"]
        else:
            os.environ["MINARI_DATASETS_PATH"] = before


def write_datasets(
    out: Path,
    env_id: str,
    env_kwargs: Mapping[str, Any],
    episodes: Mapping[str, Sequence[int]],
    description: str = "",
) -> dict[str, str]:
    """One Minari dataset per controller of ``episodes`` (controller -> the indices of its
    saved episodes, in order) under ``out/datasets`` (a dataset of the same id there is
    replaced); the saved episodes are removed. Returns controller -> dataset id."""
    import minari

    root = out / DATASETS_DIR
    env = gym.make(env_id, **env_kwargs)
    written = {}
    try:
        with datasets_root(root):
            for controller, indices in episodes.items():
                name = dataset_id(env_id, controller)
                shutil.rmtree(root / name, ignore_errors=True)
                buffers = [
                    _episode_buffer(episode_file(out, controller, i), k)
                    for k, i in enumerate(indices)
                ]
                with warnings.catch_warnings():  # its advice to name an author and a URL
                    warnings.filterwarnings("ignore", message=r".* is set to None", module="minari")
                    minari.create_dataset_from_buffers(
                        name,
                        buffers,
                        env=env,
                        eval_env=env.spec,
                        algorithm_name=controller,
                        author="wip-bench compare",
                        description=description
                        or f"{controller} on {env_id}: wip-bench compare --record-transitions",
                    )
                written[controller] = name
    finally:
        env.close()
    shutil.rmtree(out / EPISODES_DIR, ignore_errors=True)
    return written
