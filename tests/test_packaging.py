"""A plain (non-editable) install of the wheel into a fresh virtual environment makes every
environment: the MJCF assets travel inside the wheel."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import gymnasium as gym, numpy as np, wip_gym, wip_gym.assets as a
assert "site-packages" in a.__file__, a.__file__
assert "_assets" in str(a.mjcf_dir()), a.mjcf_dir()
for env_id in wip_gym.ENV_IDS:
    env = gym.make(env_id)
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape))
print("ok", len(wip_gym.ENV_IDS))
"""


def test_wheel_installs_into_a_fresh_venv_and_makes_every_env(tmp_path: Path) -> None:
    dist = tmp_path / "dist"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(dist),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
    )
    wheels = list(dist.glob("wip_gym-*.whl"))
    assert len(wheels) == 1
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=False)
    python = env_dir / "bin" / "python"
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    )
    # the fresh venv sees the dependencies of the test venv (already installed and pinned) but
    # not its editable wip-gym: a plain path entry does not run the editable finder's .pth
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "--no-deps",
            "--no-index",
            str(wheels[0]),
        ],
        check=True,
        capture_output=True,
    )
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    result = subprocess.run(
        [str(python), "-c", SCRIPT],
        cwd=tmp_path,
        env=environment,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("ok 5")
