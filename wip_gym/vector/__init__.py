"""The native vector env of every wip-gym env (docs/vector.md): ``gymnasium.make_vec(id,
num_envs=N)`` makes a :class:`WIPVectorEnv`."""

from wip_gym.vector.env import (
    KrangTrayVectorEnv,
    KrangVectorEnv,
    PlanarTrayVectorEnv,
    PlanarVectorEnv,
    WIPDriveVectorEnv,
    WIPVectorEnv,
)

__all__ = [
    "KrangTrayVectorEnv",
    "KrangVectorEnv",
    "PlanarTrayVectorEnv",
    "PlanarVectorEnv",
    "WIPDriveVectorEnv",
    "WIPVectorEnv",
]
