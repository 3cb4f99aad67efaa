"""``wip_gym.mujoco_c``: the installed MuJoCo declares every C function as the fast path does,
and each gives, called from numba, exactly what the Python bindings give, on a random state of
Krang (the robot with the most joints, a free base and sites); the fast path's gate and switch.
``tools/verify_mujoco_releases.py`` runs this file on every MuJoCo release of pyproject's
range."""

from __future__ import annotations

import ctypes
import os
import re
import warnings

import gymnasium
import mujoco
import numpy as np
import pytest
from dynamics_reference import random_minimal_state
from numba import carray, njit

import wip_gym  # noqa: F401  (registers the envs)
from wip_gym import mujoco_c as mjc
from wip_gym.array_table import float64_view, int32_pointer
from wip_gym.assets import mjcf_path
from wip_gym.robot_model import RobotModel


def _normalised(declaration: str) -> str:
    return re.sub(r"\s+", " ", declaration).replace("( ", "(").strip()


def test_the_installed_header_declares_every_function_as_the_fast_path_does() -> None:
    """``mujoco/include/mujoco/mujoco.h`` of the installed release declares each C function
    the compiled code calls as ``DECLARATIONS`` has it, whitespace aside: a changed signature
    would corrupt memory instead of raising."""
    header = os.path.join(os.path.dirname(mujoco.__file__), "include", "mujoco", "mujoco.h")
    with open(header) as file:
        text = file.read()
    for name, (declaration, arguments) in mjc.DECLARATIONS.items():
        found = re.findall(rf"MJAPI\s+(void\s+{name}\s*\([^;]*\));", text)
        assert len(found) == 1, (name, found)
        assert _normalised(found[0]) == _normalised(declaration), name
        assert declaration.count(",") + 1 == len(arguments), name


@njit
def _compiled(model, data, jacs, point, body, site, dst, result) -> None:
    mjc.mj_kinematics(model, data)
    mjc.mj_comPos(model, data)
    mjc.mj_crb(model, data)
    mjc.mj_comVel(model, data)
    mjc.mj_passive(model, data)
    mjc.mj_subtreeVel(model, data)
    mjc.mj_fullM(model, data, dst.ctypes.data)
    mjc.mj_rne(model, data, 0, result.ctypes.data)
    mjc.mj_jac(model, data, jacs[0].ctypes.data, jacs[1].ctypes.data, point.ctypes.data, body)
    mjc.mj_jacDot(model, data, jacs[2].ctypes.data, jacs[3].ctypes.data, point.ctypes.data, body)
    mjc.mj_jacSite(model, data, jacs[4].ctypes.data, jacs[5].ctypes.data, site)
    mjc.mj_jacSubtreeCom(model, data, jacs[6].ctypes.data, body)
    mjc.mj_jac(model, data, jacs[7].ctypes.data, 0, point.ctypes.data, body)  # null jacr
    mjc.mj_rnePostConstraint(model, data)


def _bindings(m, d, jacs, point, body, site, dst, result) -> None:
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    mujoco.mj_crb(m, d)
    mujoco.mj_comVel(m, d)
    mujoco.mj_passive(m, d)
    mujoco.mj_subtreeVel(m, d)
    mujoco.mj_fullM(m, d, dst)
    mujoco.mj_rne(m, d, 0, result)
    mujoco.mj_jac(m, d, jacs[0], jacs[1], point, body)
    mujoco.mj_jacDot(m, d, jacs[2], jacs[3], point, body)
    mujoco.mj_jacSite(m, d, jacs[4], jacs[5], site)
    mujoco.mj_jacSubtreeCom(m, d, jacs[6], body)
    mujoco.mj_jac(m, d, jacs[7], None, point, body)
    mujoco.mj_rnePostConstraint(m, d)


def test_compiled_calls_equal_the_bindings() -> None:
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("scene_krang.xml")))
    robot = RobotModel(model)
    qpos, qvel = robot.full_state(*random_minimal_state(robot, np.random.default_rng(2)))
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "base")
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "ee")
    assert body >= 0 and site >= 0
    results = []
    for run in (_compiled, _bindings):
        data = mujoco.MjData(model)
        data.qpos[: len(qpos)], data.qvel[: len(qvel)] = qpos, qvel
        data.qacc[:] = np.linspace(-1.0, 1.0, model.nv)
        jacs = np.full((8, 3, model.nv), np.nan)
        point = np.array([0.1, -0.2, 0.7])
        dst, result = np.zeros((model.nv, model.nv)), np.zeros(model.nv)
        if run is _compiled:
            run(*mjc.addresses(model, data), jacs, point, body, site, dst, result)
        else:
            run(model, data, jacs, point, body, site, dst, result)
        results.append(
            (
                data.xpos.copy(),
                data.cdof.copy(),
                data.cvel.copy(),
                data.qfrc_passive.copy(),
                data.subtree_linvel.copy(),
                data.cfrc_int.copy(),
                dst,
                result,
                jacs,
            )
        )
    for ours, theirs in zip(*results, strict=True):
        np.testing.assert_array_equal(ours, theirs)
    assert np.isfinite(results[0][-1]).all() and np.abs(results[0][-1]).max() > 0


def test_the_fast_path_runs_on_verified_releases_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Another release is refused with its reason, and what the readable path costs is said
    once, whatever the number of objects that ask; the switch turns the fast path off, and on
    only where it can run."""
    assert mjc.release() in mjc.VERIFIED_RELEASES and mjc.available()
    monkeypatch.setattr(mujoco, "__version__", "3.99.0")
    assert "3.99.0 is not one of the releases" in str(mjc._unavailable())
    monkeypatch.setattr(mjc, "_available", None)
    monkeypatch.setattr(mjc, "_chosen", None)
    with pytest.warns(RuntimeWarning, match=r"3\.99\.0 .* about \d+ times slower") as caught:
        assert not mjc.fast_path()
        assert not mjc.fast_path() and not mjc.available()
    assert len(caught) == 1
    with pytest.raises(ValueError, match="cannot run here"):
        mjc.set_fast_path(True)
    with pytest.raises(RuntimeError, match="not available"):
        mjc.addresses(mujoco.MjModel.from_xml_string("<mujoco/>"), None)  # type: ignore[arg-type]
    monkeypatch.setattr(mujoco, "__version__", "3.17.2")  # a patch release of a verified one
    monkeypatch.setattr(mjc, "_available", None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert mjc.fast_path()
    for value, expected in (("0", False), ("1", True), (" 0 ", False)):
        monkeypatch.setenv(mjc.FAST_PATH_ENV, value)
        mjc.set_fast_path(None)  # the environment, read again
        assert mjc.fast_path() is expected
    mjc.set_fast_path(False)
    assert not mjc.fast_path()
    mjc.set_fast_path(True)
    assert mjc.fast_path()
    mjc.set_fast_path(None)


@njit
def _through_pointer(address, rows, cols, out) -> None:
    view = float64_view(address, (rows, cols))
    for i in range(rows):
        for j in range(cols):
            out[i, j] = view[i, j]
            view[i, j] = -view[i, j]


def test_float64_view_is_the_array_at_an_address() -> None:
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("scene_krang.xml")))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    xpos = data.xpos.copy()
    seen = np.zeros_like(xpos)
    _through_pointer(data.xpos.ctypes.data, model.nbody, 3, seen)
    np.testing.assert_array_equal(seen, xpos)  # read where the data's array is
    np.testing.assert_array_equal(data.xpos, -xpos)  # and written there


@njit
def _contacts(
    model: int,
    data: int,
    ncon: int,
    geom_address: int,
    stride: int,
    geoms: np.ndarray,
    forces: np.ndarray,
) -> None:
    result = np.empty(6)
    for i in range(ncon):
        pair = carray(int32_pointer(np.uint64(geom_address + i * stride)), 2)
        geoms[i, 0], geoms[i, 1] = pair[0], pair[1]
        mjc.mj_contactForce(model, data, i, result.ctypes.data)
        forces[i] = result


@pytest.mark.parametrize("cone", [mujoco.mjtCone.mjCONE_ELLIPTIC, mujoco.mjtCone.mjCONE_PYRAMIDAL])
def test_compiled_contact_reads_equal_the_bindings(cone: mujoco.mjtCone) -> None:
    """``int32_pointer`` reads the contacts' geom pairs where the bindings' view is, and
    ``mj_contactForce`` gives the bindings' forces, for either friction cone."""
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("scene_krang.xml")))
    model.opt.cone = cone
    data = mujoco.MjData(model)
    for _ in range(20):  # settle onto the wheels: contacts with forces
        mujoco.mj_step(model, data)
    n = data.ncon
    assert n >= 2
    geoms, forces = np.full((n, 2), -1, np.int32), np.full((n, 6), np.nan)
    geom = data.contact.geom
    _contacts(*mjc.addresses(model, data), n, geom.ctypes.data, geom.strides[0], geoms, forces)
    expected = np.zeros((n, 6))
    for i in range(n):
        mujoco.mj_contactForce(model, data, i, expected[i])
    np.testing.assert_array_equal(geoms, geom)
    np.testing.assert_array_equal(forces, expected)
    assert (expected[:, 0] > 0).all()  # real forces, not zeros on both sides


def test_size_addresses_read_the_datas_ncon_and_time() -> None:
    """The addresses compiled code reads ``mjData.ncon`` and ``mjData.time`` at (the native
    vector env's compiled steps) hold the bindings' values along an episode of the tray env
    (its contacts come and go)."""
    env = gymnasium.make("wip_gym/KrangTray-v0", fall_angle=0.3)
    env.reset(seed=1)
    env.action_space.seed(1)
    data = env.unwrapped.data
    ncon, time = mjc.size_addresses(data)
    rng = np.random.default_rng(0)
    counts = set()
    for _ in range(300):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample() * rng.uniform())
        assert ctypes.c_int.from_address(ncon).value == data.ncon
        assert ctypes.c_double.from_address(time).value == data.time
        counts.add(data.ncon)
        if terminated or truncated:
            env.reset()
    assert len(counts) > 3
    env.close()
