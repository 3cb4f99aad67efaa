"""Named scenario presets of ``wip-bench compare --preset`` and of sweep specs: the env side
(the controllers' side is each config's constructor of the same name,
``default_config(name, preset=...)``).

``paper``: the comparison as the authors ran it (docs/AUTHORS_CONFIG.md §5.3): a 5 m drive
straight ahead; in tray tasks the tray a free body resting on the hand(s) with a 5 mm rim,
friction 0.3 tray-cup and tray-hand. The plan and controller settings (the authors' DDP weights,
no acceleration cap, the unified controller's task weights) come from ``Config.paper()``.

``realistic``: the robot as hardware sees it, every env: sensor noise, bus delays, the torque
loop's lag and model error at values from datasheets, the authors' code and the peers'
configurations (:data:`REALISTIC`; docs/realism.md §7 gives each value's source). It sets env
arguments only.

Presets compose: ``"paper,realistic"`` (or a list in a sweep spec) applies each in order, the
later one winning where two set the same env argument; the controllers take the constructor of
the last preset that has one (:func:`controller_preset`).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from typing import Any

PRESET_NAMES = ("paper", "realistic")
#: the presets with a controller side (a ``Config.<name>()`` constructor)
CONTROLLER_PRESETS = ("paper",)


def preset_names(preset: str | Sequence[str] | None) -> tuple[str, ...]:
    """The preset names in ``preset``: ``None``, one name, names joined by commas
    (``"paper,realistic"``) or a sequence of names. ``ValueError`` for an unknown or repeated
    name, naming the valid ones."""
    if preset is None:
        return ()
    if isinstance(preset, str):
        names = [name.strip() for name in preset.split(",")]
    elif isinstance(preset, Sequence) and all(isinstance(name, str) for name in preset):
        names = [name.strip() for name in preset]
    else:
        raise ValueError(f"a preset is a name or a list of names, got {preset!r}")
    unknown = [name for name in names if name not in PRESET_NAMES]
    if unknown or not names:
        raise ValueError(f"unknown preset {preset!r}; valid: {list(PRESET_NAMES)}")
    if len(set(names)) != len(names):
        raise ValueError(f"preset {preset!r} names a preset twice")
    return tuple(names)


def canonical(preset: str | Sequence[str] | None) -> str | None:
    """``preset`` as one string, its names joined by commas in order (None for none): how a
    run records it and how a sweep's seeds hash it (a single name is itself)."""
    names = preset_names(preset)
    return ",".join(names) if names else None


def controller_preset(preset: str | Sequence[str] | None) -> str | None:
    """The preset whose constructors the controllers' configs take: the last one of
    ``preset`` with a controller side (:data:`CONTROLLER_PRESETS`), None if none has."""
    chosen = [name for name in preset_names(preset) if name in CONTROLLER_PRESETS]
    return chosen[-1] if chosen else None


def _preset_argument(text: str) -> str:
    try:
        return canonical(text) or ""
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_configuration_arguments(parser: argparse.ArgumentParser, set_help: str) -> None:
    """``--preset`` and the repeatable ``--set KEY=VALUE`` (into ``args.overrides``), the
    configuration arguments of ``wip-bench compare`` and of every tool that takes its keys
    (``wip-bench profile``, ``tools/lurch_trace.py``); ``set_help`` says which keys."""
    parser.add_argument(
        "--preset",
        type=_preset_argument,
        metavar="NAME[,NAME...]",
        help="named configurations, applied in order (the later wins): paper = the authors' "
        "(5 m straight, free tray with rim, the configs' .paper()); realistic = sensor noise, "
        "delays, actuator lag and model error from datasheets (docs/realism.md)",
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", dest="overrides", help=set_help
    )


PAPER_GOAL_M = 5.0  # docs/AUTHORS_CONFIG.md §5.3: 5 m straight ahead
PAPER_TRAY = {  # docs/AUTHORS_CONFIG.md §5.3: the authors' tray and cup
    "tray_attachment": "free",
    "tray_rim": 0.005,
    "cup_friction": 0.3,
    "tray_friction": 0.3,
}


#: docs/realism.md §7: each value's source. Delays are in control steps of the default 1 ms.
REALISTIC: dict[str, Any] = {
    "sensor_noise": 1.0,  # wip_gym.envs.sensors.SensorModel: IMU and encoder datasheet figures
    "obs_delay_steps": 1,  # a 1 Mbit/s CAN request-reply per device, 0.2 to 0.3 ms, several
    "obs_delay_jitter_steps": 1,  # devices on a bus: the state 1 to 2 ms old
    "action_delay_steps": 1,  # the 0.4 to 2 ms motor-response delay injected to validate a
    "action_delay_jitter_steps": 1,  # CAN-based legged deployment: 1 to 2 ms
    "actuator_lag_s": 0.001,  # a 1000 rad/s current-loop bandwidth (ODrive's default)
    "com_offset": 0.01,  # cm-level residual of an identified CoM (Isaac Lab's z range)
    "inertia_randomization": 0.02,  # robosuite's mass and inertia +-2 %
    "mass_randomization": 0.02,
    "joint_damping": 0.5,  # the authors' simulation added 0.5 N m s/rad on the arm joints
    "joint_friction": 0.05,  # robosuite's frictionloss +0.05
    "floor_friction": (0.4, 1.0),  # MuJoCo Playground's floor friction range
}


def _paper_arguments(env_id: str, settings: Mapping[str, Any]) -> dict[str, Any]:
    from benchmarks.overrides import is_planar

    wanted: dict[str, Any] = {"goal": PAPER_GOAL_M if is_planar(env_id) else (PAPER_GOAL_M, 0.0)}
    if "env.cup_friction" in settings and "Tray" in env_id:
        wanted.update(PAPER_TRAY)
    return wanted


def env_arguments(
    preset: str | Sequence[str] | None, env_id: str, settings: Mapping[str, Any]
) -> tuple[dict[str, Any], list[str]]:
    """The env arguments of ``preset`` (one name, or several composed in order: the later wins
    where two set the same argument) for ``env_id`` (``settings``: its ``env.<argument>``
    keys), and an empty list (kept for callers; every preset argument must exist)."""
    wanted: dict[str, Any] = {}
    for name in preset_names(preset):
        if name == "paper":
            wanted.update(_paper_arguments(env_id, settings))
        elif name == "realistic":
            wanted.update(REALISTIC)
    unknown = [k for k in wanted if f"env.{k}" not in settings]
    if unknown:
        raise ValueError(f"--preset {canonical(preset)}: {env_id} has no arguments {unknown}")
    return wanted, []
