"""Fixtures shared by the test modules: the robots' scene models and their ``home`` state."""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import pytest

from controllers.optimizer import jax_setup
from wip_gym.assets import mjcf_path

# the suite is an entry point: the solvers' JAX settings, before any test starts JAX
jax_setup.configure()


def home_data(model: mujoco.MjModel) -> mujoco.MjData:
    """Data at the model's ``home`` keyframe, with its kinematics and dynamics computed."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    return data


@pytest.fixture(scope="session")
def scene_model() -> Callable[[str], mujoco.MjModel]:
    """``scene_model("krang")``: a fresh model of ``assets/mjcf/scene_<robot>.xml``."""

    def load(robot: str) -> mujoco.MjModel:
        return mujoco.MjModel.from_xml_path(str(mjcf_path(f"scene_{robot}.xml")))

    return load


@pytest.fixture(scope="session")
def home() -> Callable[[mujoco.MjModel], mujoco.MjData]:
    """``home(model)``: data at the model's ``home`` keyframe, forward computed."""
    return home_data
