"""Fixtures shared by the test modules: the robots' scene models and their ``home`` state."""

from __future__ import annotations

from collections.abc import Callable

import jax
import mujoco
import pytest

from controllers.optimizer import jax_setup
from wip_gym.assets import mjcf_path

# The solvers need no setting (they scope float64, docs/DESIGN.md §4; tests/test_jax_setup.py
# runs them without any). The suite's own: JAX's compilation cache, and float64 for the whole
# process, since tests call the WIPM's JAX functions and the solvers' raw jitted ones directly.
jax_setup.use_compilation_cache()
jax.config.update("jax_enable_x64", True)


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
