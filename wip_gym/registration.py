"""Gymnasium registration of the wip-gym environments (docs/DESIGN.md §6) and their native
vector envs (``gymnasium.make_vec``, docs/vector.md).

The time limit is the env's own (its ``time_limit`` argument, in simulated seconds), not a
registered ``max_episode_steps``: a step count would mean another duration at every
``frame_skip`` (25 000 steps are 25 s at 1 ms and 250 s at 10 ms). So the specs register no
``max_episode_steps`` and ``gym.make`` adds no ``TimeLimit``; ``gym.make(id,
max_episode_steps=N)`` still adds one (N steps or the env's own limit, whichever comes first)
and ``max_episode_steps=-1`` adds none (docs/learning.md §4). The vector env's sub-envs are
the single env (``wip_gym.vector.env.make_sub_env``), so they truncate at the same time.
"""

from __future__ import annotations

import gymnasium

#: the episode's time limit (s of simulated time): the plan horizon (20 s) plus 5 s to settle
EPISODE_SECONDS = 25.0

ENV_IDS: dict[str, str] = {
    "wip_gym/WIP-v0": "wip_gym.envs.tasks:WIPDriveEnv",
    "wip_gym/Planar-v0": "wip_gym.envs.tasks:PlanarEnv",
    "wip_gym/PlanarTray-v0": "wip_gym.envs.tasks:PlanarTrayEnv",
    "wip_gym/Krang-v0": "wip_gym.envs.tasks:KrangEnv",
    "wip_gym/KrangTray-v0": "wip_gym.envs.tasks:KrangTrayEnv",
}


def vector_entry_point(env_id: str) -> str:
    """The vector env class of ``env_id``: ``wip_gym.vector.env:<task class>``, the task
    class's name with ``Env`` made ``VectorEnv`` (``WIPDriveEnv`` -> ``WIPDriveVectorEnv``)."""
    task_class = ENV_IDS[env_id].split(":")[1]
    return "wip_gym.vector.env:" + task_class.removesuffix("Env") + "VectorEnv"


def register_envs() -> None:
    """Register every environment (idempotent)."""
    for env_id, entry_point in ENV_IDS.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id, entry_point=entry_point, vector_entry_point=vector_entry_point(env_id)
        )
