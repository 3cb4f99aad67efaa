"""The five registered environments. Each fixes a robot and whether it carries a tray and cup.

Their docstrings follow Gymnasium's MuJoCo envs: description, spaces, rewards, starting state,
episode end, arguments.
"""

from __future__ import annotations

from typing import Any

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
    With `sensor_noise` or an observation delay they are what the robot's IMU and encoders
    report, late (docs/realism.md); `info` always holds the true state.

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
    ahead; from MuJoCo's subtree CoM and velocity of the state after the step, so `thetad`
    reads MuJoCo's velocities, wheel slip included), `axle_position`, `goal_distance`, `fallen`, `ee_error` (end-effector displacement
    from its reset position in the axle frame, m), and in tray tasks:

    | key | type | meaning |
    |---|---|---|
    | `tray_tilt_deg` | float | angle between the tray's normal and world z (deg) |
    | `cup_offset` | (3,) | cup centre in the tray frame (m; origin on the plate's underside); the sum of its per-step changes is the cup's slip path over the tray |
    | `cup_tilt_deg` | float | angle between the cup's axis and the tray's normal (deg) |
    | `cup_upright` | bool | `cup_tilt_deg <= 30` |
    | `cup_on_plate` | bool | the cup's centre is over the plate (within its 0.30 x 0.20 m outline) and above it, and its lowest point at most 5 mm above the plate's top (resting, or within a few mm) |
    | `cup_on_tray` | bool | `cup_on_plate and cup_upright`: the cup is kept at this step |
    | `cup_friction_use` | float | norm of the net tangential force over `cup_friction` times the net normal force, over the contacts of the cup with the **plate** (vectors summed, then the ratio): 1 = slipping, `tan(alpha) / mu` on a still plate tilted by alpha, 0 with no contact. Rim contacts are not counted (their push is a normal force of the rim, not friction of the plate) |
    | `tray_offset` | (3,) | the tray's origin relative to its rest place on the hand (the `tray_rest` site), in that place's frame (m); zeros when welded. The sum of its per-step changes is the tray's slip path |
    | `tray_on_hand` | bool | free tray: within 1 cm of its rest place along the normal and within the plate's half-size across it; always True when welded |

    The soft contact's creep floor (robot held still, `tests/test_cup_metrics.py`): a cup on a
    still level tray moves about 0.001 mm in 5 s (path of `cup_offset`); under a tangential
    load soft friction creeps about 0.08 to 0.09 mm/s per unit of `cup_friction_use` (0.065 mm
    in 5 s at 0.17, 0.47 mm at 0.89), and the free Krang tray on its 2.9 deg rest 0.14 mm in
    5 s. So a slip path under about 0.1 mm per second of episode is creep, not a slip.

    ## Starting State

    The `home` pose at the origin (on a sloped floor, the axle raised to put the wheels on
    it), heading along +x, the base pitched about the axle so the
    body's CoM is exactly above it (a welded tray is level there); then uniform noise of
    `reset_noise_scale` (rad, rad/s) on the base pitch, body joints and their rates, applied in
    minimal coordinates so the wheels stay rolling on the floor. Without control it falls.
    A free tray starts at rest on its supports: from its rest place on the hand (found when
    the model is built) it is let settle for 0.5 s on the supports of the noisy pose, held
    still in a small separate model (the reset noise moves Krang's grippers relative to each
    other by a few mm; about 10 ms per reset), and it and the cup get the hand's velocity.
    The cup starts upright at the plate's centre, exactly touching it (1 micron in).
    The free tray is not in `theta` (it is not part of the robot).
    `reset(options={"goal": x or (X, Y)})` sets the goal of that episode (observation, reward,
    info and marker); a reset without it goes back to the `goal` the env was made with.

    ## Episode End

    Terminated when the robot has fallen (a body link touches the floor or |theta| exceeds
    `fall_angle`) and, in tray tasks with `terminate_on_cup_loss`, when the cup is lost: not
    `cup_on_tray` (off the plate, or tilted beyond 30 deg) or, with a free tray, not
    `tray_on_hand` (`reward_cup_loss` is paid on that step). Truncated by the env itself at
    `time_limit` (25 s) of simulated time, whatever `frame_skip` is: after 25,000 steps at the
    1 ms step, 2,500 at `frame_skip=10` (the first step whose end reaches the limit). The specs
    register no `max_episode_steps`; `gym.make(id, max_episode_steps=N)` adds Gymnasium's
    `TimeLimit` of N steps on top (the first of the two ends the episode) and
    `time_limit=None` removes the env's own (docs/learning.md §4). Without `terminate_on_cup_loss`, the
    episode goes on with MuJoCo's constraint islands switched on from the loss to the next
    reset (the models have them off: one island while the cup rides the tray; the cup on the
    floor is an island of its own, which they solve to its own convergence).

    ## Arguments (`gymnasium.make(id, **kwargs)`)

    | argument | default | meaning |
    |---|---|---|
    | `goal` | 2.0 | goal x, or `(X, Y)` in 3-D |
    | `cup_friction` | 0.3 | tray-cup friction (explicit contact pairs, plate and rim;
        docs/DESIGN.md §5) |
    | `tray_attachment` | `"welded"` | tray tasks: `"welded"` to the hand, or `"free"`: a free body resting on the hand (see the task's description) |
    | `tray_rim` | 0.0 | tray tasks: rim height in m on the plate's edge (5 mm thick walls), 0 for none; the authors' tray: 0.005 (docs/AUTHORS_CONFIG.md §5.3) |
    | `tray_friction` | 0.3 | tray tasks: friction of the free tray's contact pairs with its supports (the authors' 0.3) |
    | `payload_mass` | 0.0 | kg welded to the hand (`ee` site) |
    | `payload_time` | 0.0 | s at which the payload appears (0: from the start) |
    | `push_force` | 0.0 | N along the heading at the torso's CoM (sign = direction); with a push the env owns that body's `data.xfrc_applied` (zeroed outside the push), without one it never writes it |
    | `push_time` | 1.0 | s at which the push starts (simulated time: the push acts on the steps that start in `[push_time, push_time + push_duration)`) |
    | `push_duration` | 0.1 | s the push lasts |
    | `reset_noise_scale` | 0.01 | half-width of the uniform reset noise on the base pitch, body joints and their rates (rad, rad/s) |
    | `mass_randomization` | 0.0 | each link's mass and inertia scaled by `1 + U(-f, f)` per reset |
    | `wheel_torque_limit` | 150.0 | N m per wheel (authors' simulation); 63.6 for Krang's hardware |
    | `terminate_on_cup_loss` | True | end the episode when the cup leaves the tray |
    | `fall_angle` | 0.8 | rad of `theta` counted as a fall |
    | `progress_weight`, `ctrl_cost_weight` | 1.0, 0.1 | reward weights |
    | `fall_penalty`, `cup_loss_penalty` | 10.0, 10.0 | reward penalties |
    | `frame_skip` | 1 | MuJoCo steps (1 ms) per env step: the control step `dt` = `frame_skip` ms; the arguments in s do not depend on it (the `*_delay_steps` count control steps) |
    | `time_limit` | 25.0 | s of simulated time after which the episode is truncated; None: never (the plan's 20 s horizon plus 5 s to settle) |
    | `sensor_noise` | 0.0 | scale on the documented noise, biases and steps of the IMU and the encoders, 0 for the exact state (docs/realism.md §2) |
    | `obs_delay_steps` | 0 | control steps by which the observation arrives late (until the first arrives, the reset's) |
    | `obs_delay_jitter_steps` | 0 | each step's observation delay is `obs_delay_steps` plus a uniform integer in `[0, j]` |
    | `action_delay_steps` | 0 | control steps by which the action is applied late (zero torque before the first arrives) |
    | `action_delay_jitter_steps` | 0 | each step's action delay is `action_delay_steps` plus a uniform integer in `[0, j]` |
    | `actuator_lag_s` | 0.0 | s, time constant of a first-order lag on every actuator's torque (MuJoCo's activation dynamics; docs/realism.md §4) |
    | `joint_lag_s` | None | s, the body joints' own lag time constant (None: `actuator_lag_s`) |
    | `torque_noise` | 0.0 | standard deviation of white torque noise per step, as a fraction of each actuator's torque limit |
    | `com_offset` | 0.0 | m, each link's CoM moved by `U(-c, c)` per axis per reset (wheels excepted) |
    | `inertia_randomization` | 0.0 | each link's inertia scaled by `1 + U(-f, f)` per reset |
    | `joint_damping` | 0.0 | N m s/rad, viscous damping `U(0, d)` added to every actuated joint per reset |
    | `joint_friction` | 0.0 | N m, dry friction (`frictionloss`) `U(0, f)` added to every actuated joint per reset |
    | `floor_friction` | 1.0 | wheel-floor friction coefficient, or a range `(low, high)` drawn per reset |
    | `floor_slope_deg` | 0.0 | deg, the floor's slope, rising toward +x when positive; the robot starts on it (docs/realism.md §5) |
    | `bump_height` | 0.0 | m, height of bumps across the path (flat-topped boxes the wheels roll over), 0 for none |
    | `bump_spacing` | 1.0 | m, distance between bumps along the floor (none at the start) |
    | `bump_width` | 0.1 | m, length of each bump's top along the path |
    | `render_mode`, `width`, `height` | None, 480, 320 | `human`, `rgb_array`, `depth_array` |
"""


class WIPDriveEnv(WIPEnv):
    """## Description

    `wip`: one rigid body (150 kg, CoM 0.30 m above the axle) on two independently driven
    wheels, free in 3-D. The simplified model (WIPM) made physical: drive to a goal `(X, Y)`.
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("goal", (2.0, 0.0))
        super().__init__(robot="wip", tray=False, **kwargs)


class PlanarEnv(WIPEnv):
    """## Description

    `planar7`: the paper's 7-DOF planar WIP humanoid (x, base pitch and five body joints:
    spine, torso, shoulder, elbow, wrist), at Krang's scale. Drive to a goal x.
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(robot="planar7", tray=False, **kwargs)


class PlanarTrayEnv(WIPEnv):
    """## Description

    `planar7` carrying a tray with a free cup on it: drive to a goal x without spilling (the
    paper's Fig. 3 task). The tray is welded to the hand, level at reset, or free
    (`tray_attachment="free"`): resting level on the tip face of the hand's box (0.08 x 0.12 m).

    Controllers' nominal model (`controllers.policy.controller_model`): a free tray is welded
    there at its nominal place (the designer knows its mass, not its contact).
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(robot="planar7", tray=True, **kwargs)


class KrangEnv(WIPEnv):
    """## Description

    Golem Krang (KrangOld's masses and geometry, kinect dropped): 19 minimal DOF (x, psi,
    base pitch, waist, torso, two 7-joint arms), 18 motors. Drive to a goal `(X, Y)`.
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("goal", (2.0, 0.0))
        super().__init__(robot="krang", tray=False, **kwargs)


class KrangTrayEnv(WIPEnv):
    """## Description

    Golem Krang carrying a tray midway between the grippers as in the authors' demo
    (docs/AUTHORS_CONFIG.md §5.3) with a free cup on it: drive to `(X, Y)` without spilling.
    The tray is welded to the left gripper, level at reset, or free (`tray_attachment="free"`).

    The free tray's support: the authors' tray is a free body on the grippers at their initial
    arm pose (docs/AUTHORS_CONFIG.md §1.6, which is our `home` keyframe), and what reaches under
    it there are the gripper **finger plates** of their URDF (`l/rgPlate1,2`), not the gripper
    boxes (0.08 x 0.112 x 0.2025 m, which end 6 to 11 cm short of the plate's side edges). We
    add the four finger plates to the free-tray model as massless 21 x 74 x 90 mm boxes (their
    mesh bounds, at the URDF's places): their tips reach 3 cm under each side edge of the
    plate. The arm pose is unchanged (so the welded default is unchanged). On them the tray
    rests **2.9 deg from level** (the grippers are pitched there; the welded tray is made level
    instead), so a cup at rest on a free tray already uses about `tan(2.9 deg) / mu` = 0.17 of
    its friction (mu 0.3): the authors' setup has that tilt too, by the same geometry.

    Controllers' nominal model (`controllers.policy.controller_model`): a free tray is welded
    there at its nominal place, level on the left gripper (the designer knows its mass, not its
    contact).
    """

    __doc__ = (__doc__ or "") + _COMMON

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("goal", (2.0, 0.0))
        super().__init__(robot="krang", tray=True, **kwargs)
