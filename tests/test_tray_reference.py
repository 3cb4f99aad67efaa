"""The upright controller's tray targets (controllers/high_level/tray_reference.py)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.high_level.planning import Plan
from controllers.high_level.tray_reference import (
    GRAVITY,
    TrayGains,
    TrayReference,
    plan_acceleration,
    tilt_toward,
)


def _plan(
    states: np.ndarray, planar: bool, dt: float = 0.01, settle: np.ndarray | None = None
) -> Plan:
    n = len(states)
    settle = np.zeros((0, states.shape[1])) if settle is None else settle
    return Plan(
        times=np.arange(n) * dt,
        states=states,
        controls=np.zeros((n - 1, 1 if planar else 2)),
        goal_state=states[-1],
        planar=planar,
        cost=0.0,
        iterations=0,
        converged=True,
        peak_acceleration=0.0,
        peak_theta=0.0,
        arrival_time=None,
        a_max=np.inf,
        theta_max=np.inf,
        violations=(),
        settle_states=settle,
        settle_controls=np.zeros((len(settle), 1 if planar else 2)),
        rest_state=np.zeros(states.shape[1]),
    )


def test_the_plans_acceleration_is_its_speed_difference_and_the_turns_lateral_part():
    rng = np.random.default_rng(0)
    planar = rng.normal(size=(50, 4))
    plan = _plan(planar, True)
    t = 0.237  # inside step 23
    assert plan_acceleration(plan, t) == pytest.approx(
        ((planar[24, 3] - planar[23, 3]) / 0.01, 0.0)
    )
    spatial = rng.normal(size=(50, 8))
    plan = _plan(spatial, False)
    forward, lateral = plan_acceleration(plan, t)
    assert forward == pytest.approx((spatial[24, 3] - spatial[23, 3]) / 0.01)
    assert lateral == pytest.approx(spatial[23, 3] * spatial[23, 4])  # xd psid
    assert plan_acceleration(plan, 10.0) == (0.0, 0.0)  # past the end: at rest
    assert plan_acceleration(plan, -0.5) == (0.0, 0.0)
    # past t_f the continuation's speeds, then the rest state's
    settle = rng.normal(size=(5, 4))
    plan = _plan(planar, True, settle=settle)
    assert plan_acceleration(plan, 0.515)[0] == pytest.approx((settle[2, 3] - settle[1, 3]) / 0.01)
    assert plan_acceleration(plan, 0.545)[0] == pytest.approx((0.0 - settle[4, 3]) / 0.01)


def _reference(gains: TrayGains | None = None) -> TrayReference:
    rng = np.random.default_rng(1)
    pivot = np.array([0.4, 0.0, 1.0])
    positions = [pivot + np.array([-0.05, 0.1, -0.02]), pivot + np.array([-0.05, -0.1, -0.02])]
    rotations = []
    for _ in positions:
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        rotations.append(q * np.sign(np.linalg.det(q)))
    return TrayReference(pivot, positions, rotations, gains or TrayGains())


def test_at_rest_the_targets_are_the_reset_poses():
    ref = _reference()
    for (p, R), p0, R0 in zip(
        ref.targets((0.0, 0.0), np.zeros(3), np.zeros(3)),
        [ref.pivot + a for a in ref._arms],
        ref._rotations,
        strict=True,
    ):
        np.testing.assert_allclose(p, p0, atol=1e-15)
        np.testing.assert_allclose(R, R0, atol=1e-15)


def test_the_tray_turns_rigidly_into_the_specific_force():
    ref = _reference(TrayGains(kp=0.0, kv=0.0))
    a = (2.0, -1.0)
    targets = ref.targets(a, np.zeros(3), np.zeros(3))
    normal = ref.tilt @ np.array([0.0, 0.0, 1.0])
    specific = np.array([a[0], a[1], GRAVITY])
    np.testing.assert_allclose(normal, specific / np.linalg.norm(specific), atol=1e-12)
    # rigid: the hands keep their distances to each other and to the pivot, and their relative
    # rotation
    (p1, R1), (p2, R2) = targets
    arms = ref._arms
    assert np.linalg.norm(p1 - p2) == pytest.approx(np.linalg.norm(arms[0] - arms[1]))
    assert np.linalg.norm(p1 - ref.pivot) == pytest.approx(np.linalg.norm(arms[0]))
    np.testing.assert_allclose(R1.T @ R2, ref._rotations[0].T @ ref._rotations[1], atol=1e-12)


def test_a_tray_left_behind_tilts_further_forward():
    """The outer loop: a tray behind its place (drift < 0 forward) asks more acceleration."""
    ref = _reference(TrayGains(kp=4.0, kv=4.0))
    ahead = ref.desired_acceleration((1.0, 0.0), np.array([0.02, 0.0, 0.0]), np.zeros(3))
    behind = ref.desired_acceleration((1.0, 0.0), np.array([-0.02, 0.0, 0.0]), np.zeros(3))
    assert ahead[0] == pytest.approx(1.0 - 0.08) and behind[0] == pytest.approx(1.0 + 0.08)
    slowing = ref.desired_acceleration((1.0, 0.0), np.zeros(3), np.array([0.0, 0.1, 0.0]))
    assert slowing[1] == pytest.approx(-0.4)


def test_a_tray_resting_tilted_is_levelled_first():
    rng = np.random.default_rng(4)
    normal = np.array([0.03, -0.04, 1.0])
    normal /= np.linalg.norm(normal)
    base = _reference()
    ref = TrayReference(
        base.pivot, [base.pivot + a for a in base._arms], base._rotations, TrayGains(), normal
    )
    np.testing.assert_allclose(ref.level @ normal, [0.0, 0.0, 1.0], atol=1e-12)
    # the smallest such rotation: its axis is horizontal and its angle the normal's tilt
    angle = np.degrees(np.arccos(np.clip((np.trace(ref.level) - 1) / 2, -1, 1)))
    assert angle == pytest.approx(np.degrees(np.arccos(normal[2])), abs=1e-9)
    a = tuple(rng.normal(size=2))
    targets = ref.targets(a, np.zeros(3), np.zeros(3))
    # the plate's normal, turned with the hands, is the specific force's direction
    (_, R1), R10 = targets[0], base._rotations[0]
    turned = (R1 @ R10.T) @ normal
    specific = np.array([a[0], a[1], GRAVITY])
    np.testing.assert_allclose(turned, specific / np.linalg.norm(specific), atol=1e-12)


def test_the_tilt_is_bounded_and_bad_gains_are_refused():
    R = tilt_toward(np.array([100.0, 0.0]), 10.0)
    assert np.degrees(np.arccos(R[2, 2])) == pytest.approx(10.0)
    with pytest.raises(ValueError, match="max_tilt_deg"):
        TrayGains(max_tilt_deg=95.0)
    with pytest.raises(ValueError, match="kp"):
        TrayGains(kp=-1.0)
    with pytest.raises(ValueError, match="one reset position"):
        TrayReference(np.zeros(3), [], [], TrayGains())
