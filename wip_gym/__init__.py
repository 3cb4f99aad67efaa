"""wip-gym: a MuJoCo research gym for whole-body control of wheeled inverted pendulum humanoids.

``import wip_gym`` registers the environments (namespace ``wip_gym``):

| id | robot | task |
|---|---|---|
| ``wip_gym/WIP-v0`` | one body on two wheels (3-D) | drive to a goal (X, Y) |
| ``wip_gym/Planar-v0`` | 7-DOF planar humanoid | drive to a goal x |
| ``wip_gym/PlanarTray-v0`` | 7-DOF planar humanoid | drive to x carrying a cup on a tray |
| ``wip_gym/Krang-v0`` | Golem Krang, 19 DOF | drive to a goal (X, Y) |
| ``wip_gym/KrangTray-v0`` | Golem Krang, 19 DOF | drive to (X, Y) carrying a cup on a tray |

On every MuJoCo release from 3.10 to 3.17: the per-step computation calls MuJoCo's C functions
from compiled code where their declarations were verified (``wip_gym.mujoco_c``), and MuJoCo's
Python bindings elsewhere, or everywhere with ``WIP_GYM_FAST_PATH=0`` or
``wip_gym.set_fast_path(False)`` (docs/robot_model.md §3).
"""

from __future__ import annotations

import os

# Offscreen rendering when there is no display (docs/DESIGN.md §6); MuJoCo reads this when imported.
if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

# numba's cache in a directory keyed on the packages' compiled sources and the modules they
# import (a caller compiled with an edited callee of another file would load the old code):
# before any of their compiled functions is defined
from wip_gym.compiled_cache import configure as _configure_compiled_cache  # noqa: E402

_configure_compiled_cache()

from wip_gym.mujoco_c import set_fast_path  # noqa: E402
from wip_gym.registration import ENV_IDS, register_envs  # noqa: E402
from wip_gym.robot_model import RobotModel, WIPMParameters  # noqa: E402
from wip_gym.scene import SceneOptions, build_model  # noqa: E402

register_envs()

__all__ = [
    "ENV_IDS",
    "RobotModel",
    "SceneOptions",
    "WIPMParameters",
    "build_model",
    "register_envs",
    "set_fast_path",
]
