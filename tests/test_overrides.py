"""``--set KEY=VALUE``: parsing, type checks, where plan keys land, precedence (no episode runs)."""

from __future__ import annotations

import warnings

import pytest

from benchmarks.overrides import (
    OverrideError,
    coerce,
    env_settings,
    parse_assignment,
    parse_value,
    plan_configs,
    resolve_run,
    valid_settings,
)

PLANAR = "wip_gym/PlanarTray-v0"
KRANG = "wip_gym/KrangTray-v0"
ALL = ["decoupled", "decoupled-mpc", "unified", "unified-waiter"]


def plans(config: object) -> list[object]:
    found = []
    for path in plan_configs(config):
        node = config
        for part in path.split(".") if path else []:
            node = getattr(node, part)
        found.append(node)
    return found


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("2.5", 2.5),
        ("3", 3),
        ("[2, 1]", [2, 1]),
        ("true", True),
        ("null", None),
        ("none", "none"),  # not JSON: a string
        ("cup_safe", "cup_safe"),
        ('"7"', "7"),
    ],
)
def test_values_parse_as_json_else_as_strings(text: str, value: object) -> None:
    assert parse_value(text) == value and type(parse_value(text)) is type(value)


def test_assignment_needs_a_key_and_an_equals_sign() -> None:
    assert parse_assignment("env.goal=[2, 1]") == ("env.goal", [2, 1])
    for bad in ("env.goal", "=3"):
        with pytest.raises(OverrideError, match="KEY=VALUE"):
            parse_assignment(bad)


def test_values_are_checked_against_the_annotated_types() -> None:
    assert coerce(3, float, "k") == 3.0 and type(coerce(3, float, "k")) is float
    assert coerce([2, 1], float | tuple[float, float], "env.goal") == (2.0, 1.0)
    assert coerce(None, float | None, "k") is None
    for value, hint in (
        (True, float),
        ("abc", float),
        (2.5, int),
        ([1, 2, 3], tuple[float, float]),
        (1, bool),
        (float("nan"), float),
    ):
        with pytest.raises(OverrideError, match="the.key"):
            coerce(value, hint, "the.key")


def test_env_keys_come_from_the_constructor_signatures() -> None:
    keys = env_settings(KRANG)
    assert keys["env.cup_friction"].default == 0.3
    assert keys["env.goal"].default == [2.0, 0.0]  # the task class's default, read back
    assert env_settings(PLANAR)["env.goal"].default == 2.0
    assert "env.robot" not in keys and "env.render_mode" not in keys


def test_a_plan_key_reaches_every_plan_of_every_controller() -> None:
    spec = resolve_run(PLANAR, ALL, overrides={"plan.q_position": 33, "plan.ddp.max_iterations": 7})
    for name, config in spec.configs.items():
        found = plans(config)
        assert found, name
        assert all(p.q_position == 33.0 and p.ddp.max_iterations == 7 for p in found), name


def test_a_controller_key_changes_only_that_controller() -> None:
    spec = resolve_run(
        PLANAR, ["unified", "unified-waiter"], overrides={"unified.high_level.mpc.horizon_s": 0.5}
    )
    assert spec.configs["unified"].high_level.mpc.horizon_s == 0.5
    assert spec.configs["unified-waiter"].high_level.mpc.horizon_s != 0.5


def test_precedence_defaults_preset_named_flags_then_set() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # configs or env arguments the preset cannot set yet
        preset_only = resolve_run(PLANAR, ["decoupled"], "paper")
        flagged = resolve_run(PLANAR, ["decoupled"], "paper", {"goal": 3.0}, {"model": "oracle"})
        overridden = resolve_run(
            PLANAR,
            ["decoupled"],
            "paper",
            {"goal": 3.0},
            {"model": "oracle"},
            {"env.goal": 4.0, "decoupled.model": "nominal"},
        )
    assert "goal" not in resolve_run(PLANAR, ["decoupled"]).env_kwargs  # the env's default
    assert preset_only.env_kwargs["goal"] == 5.0
    assert flagged.env_kwargs["goal"] == 3.0 and flagged.configs["decoupled"].model == "oracle"
    assert overridden.env_kwargs["goal"] == 4.0
    assert overridden.configs["decoupled"].model == "nominal"
    assert overridden.env_arguments()["goal"] == 4.0
    assert overridden.overrides == {"env.goal": 4.0, "decoupled.model": "nominal"}


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("env.nope", 1, "env.nope"),
        ("env.cup_friction", "abc", "env.cup_friction"),
        ("plan.nope", 1, "plan.nope"),
        ("unified.theta_kp", 1, "unified.theta_kp"),  # unified is not in this run
        ("decoupled.nope.deeper", 1, "decoupled.nope.deeper"),
        ("decoupled.plan", 1, "decoupled.plan"),  # a whole sub-config
        ("decoupled.plan.dt.x", 1, "decoupled.plan.dt.x"),
        ("nothing", 1, "nothing"),
    ],
)
def test_bad_keys_and_values_name_the_key(key: str, value: object, message: str) -> None:
    with pytest.raises(OverrideError, match=message.replace(".", r"\.")):
        resolve_run(PLANAR, ["decoupled"], overrides={key: value})


def test_sweeps_may_share_keys_of_controllers_not_in_the_run() -> None:
    spec = resolve_run(
        PLANAR, ["decoupled"], overrides={"unified.theta_kp": 1.0}, ignore_other_controllers=True
    )
    assert list(spec.configs) == ["decoupled"]


def test_valid_settings_list_env_plan_and_controller_keys() -> None:
    spec = resolve_run(KRANG, ["decoupled", "unified"])
    keys = valid_settings(KRANG, spec.configs)
    assert {
        "env.goal",
        "plan.a_max",
        "plan.ddp.max_iterations",
        "decoupled.posture_frequency_hz",
        "unified.ee_position_weight",
        "unified.high_level.plan.a_max",
    } <= set(keys)
    assert keys["unified.ee_position_weight"].default == spec.configs["unified"].ee_position_weight
