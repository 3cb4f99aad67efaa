"""The five registered environments. Each fixes a robot and whether it carries a tray and cup.

Their docstrings follow Gymnasium's MuJoCo envs: description, spaces, rewards, starting state,
episode end, arguments.
"""

from __future__ import annotations

from typing import Any

from gymnasium import utils

from wip_gym.envs.base import WIPEnv

_COMMON = """
    ## Observation Space

    A `Dict` of float64 arrays with fixed shapes (works with `FlattenObservation`):

    | key | shape | meaning |
    |---|---|---|
    | `qpos` | (nq,) | the robot's own MuJoCo positions (3-D: free base position + quaternion, wheels, body joints; planar: slide x, slide z, pitch, wheels, body joints) |
    | `qvel` | (nv,) | the robot's own MuJoCo velocities (free joint: world linear, body angular) |
    | `goal` | (2,) | goal `(X, Y)` of the axle midpoint in world (planar: `(x, 0)`) |
    | `cup_pose` | (7,) | tray tasks: cup position (m) and quaternion in the tray's frame |

    `qpos`/`qvel` are all a model-based controller needs: `wip_gym.RobotModel` rebuilds the
    minimal coordinates `[x, psi, q1..qn]`, `theta`, `lambda(q)` and the dynamics from them.

    ## Action Space

    `Box` of the actuators' torques (N m), bounds = the MJCF `ctrlrange` (the robot's torque
    limits): wheels `wheel_left`, `wheel_right` first, then the body joints in tree order.
    A NaN, a wrong shape or a torque beyond its limit raises `ValueError` (nothing is clipped).

    ## Rewards (for learning agents; `info["reward_*"]` sum to the reward)

    | term | value per step |
    |---|---|
    | `reward_progress` | `progress_weight * (previous goal distance - goal distance)` (m) |
    | `reward_ctrl` | `-ctrl_cost_weight * sum((action / limit)^2) * dt` |
    | `reward_fall` | `-fall_penalty` on the step the robot is found fallen |
    | `reward_cup_loss` | `-cup_loss_penalty` on the step the cup leaves the tray |

    ## Info

    `x` (distance rolled along the heading: 3-D wheel odometry, planar the base slide), `xd`,
    `psi`, `psid` (3-D), `theta`, `thetad` (CoM pitch about the axle from vertical, positive
    ahead), `axle_position`, `goal_distance`, `fallen`, `ee_error` (end-effector displacement
    from its reset position in the axle frame, m), and in tray tasks `tray_tilt_deg` (angle
    between the tray's normal and world z), `cup_offset` (cup position in the tray frame),
    `cup_on_tray`, `cup_friction_use` (tangential / (mu normal) tray-cup force: 1 = slipping).

    ## Starting State

    The `home` pose at the origin, heading along +x, the base pitched about the axle so the
    body's CoM is exactly above it (the tray is level there); then uniform noise of
    `reset_noise_scale` (rad, rad/s) on the base pitch, body joints and their rates, applied in
    minimal coordinates so the wheels stay rolling on the floor. Without control it falls.

    ## Episode End

    Terminated when the robot has fallen (a body link touches the floor or |theta| exceeds
    `fall_angle`) and, in tray tasks with `terminate_on_cup_loss`, when the cup leaves the
    tray. Truncated after 25 s (`max_episode_steps` = 25000 at the 1 ms step).

    ## Arguments (`gymnasium.make(id, **kwargs)`)

    | argument | default | meaning |
    |---|---|---|
    | `goal` | 2.0 | goal x, or `(X, Y)` in 3-D |
    | `cup_friction` | 0.3 | tray-cup friction (explicit contact pair; DESIGN 5) |
    | `payload_mass` | 0.0 | kg welded to the hand (`ee` site) |
    | `payload_time` | 0.0 | s at which the payload appears (0: from the start) |
    | `push_force` | 0.0 | N along the heading at the torso's CoM (sign = direction) |
    | `push_time`, `push_duration` | 1.0, 0.1 | s |
    | `reset_noise_scale` | 0.01 | rad and rad/s |
    | `mass_randomization` | 0.0 | each link's mass and inertia scaled by `1 + U(-f, f)` per reset |
    | `wheel_torque_limit` | 150.0 | N m per wheel (authors' simulation); 63.6 for Krang's hardware |
    | `terminate_on_cup_loss` | True | end the episode when the cup leaves the tray |
    | `fall_angle` | 0.8 | rad of `theta` counted as a fall |
    | `progress_weight`, `ctrl_cost_weight` | 1.0, 0.1 | reward weights |
    | `fall_penalty`, `cup_loss_penalty` | 10.0, 10.0 | reward penalties |
    | `frame_skip` | 1 | MuJoCo steps (1 ms) per env step |
    | `render_mode`, `width`, `height` | None, 480, 320 | `human`, `rgb_array`, `depth_array` |
"""


class WIPDriveEnv(WIPEnv):
    """## Description

    `wip`: one rigid body (150 kg, CoM 0.30 m above the axle) on two independently driven
    wheels, free in 3-D. The simplified model (WIPM) made physical: drive to a goal `(X, Y)`.
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        utils.EzPickle.__init__(self, **kwargs)
        kwargs.setdefault("goal", (2.0, 0.0))
        super().__init__(robot="wip", tray=False, **kwargs)


class PlanarEnv(WIPEnv):
    """## Description

    `planar7`: the paper's 7-DOF planar WIP humanoid (x, base pitch and five body joints:
    spine, torso, shoulder, elbow, wrist), at Krang's scale. Drive to a goal x.
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        utils.EzPickle.__init__(self, **kwargs)
        super().__init__(robot="planar7", tray=False, **kwargs)


class PlanarTrayEnv(WIPEnv):
    """## Description

    `planar7` carrying a tray (fixed to the hand, level at reset) with a free cup on it:
    drive to a goal x without spilling (the paper's Fig. 3 task).
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        utils.EzPickle.__init__(self, **kwargs)
        super().__init__(robot="planar7", tray=True, **kwargs)


class KrangEnv(WIPEnv):
    """## Description

    Golem Krang (KrangOld's masses and geometry, kinect dropped): 19 minimal DOF (x, psi,
    base pitch, waist, torso, two 7-joint arms), 18 motors. Drive to a goal `(X, Y)`.
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        utils.EzPickle.__init__(self, **kwargs)
        kwargs.setdefault("goal", (2.0, 0.0))
        super().__init__(robot="krang", tray=False, **kwargs)


class KrangTrayEnv(WIPEnv):
    """## Description

    Golem Krang carrying a tray (fixed to the left gripper, midway between the grippers as in
    the authors' demo, level at reset) with a free cup on it: drive to `(X, Y)` without spilling.
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        utils.EzPickle.__init__(self, **kwargs)
        kwargs.setdefault("goal", (2.0, 0.0))
        super().__init__(robot="krang", tray=True, **kwargs)
