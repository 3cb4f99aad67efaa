"""``wip-bench figures``: the paper's Figure 3 as PNGs, one set per controller.

For each controller, one seeded closed-loop episode of the scenario, then:

* ``<controller>_wipm.png`` (the paper's Fig. 3a, "simple-result"): the WIPM reference from the
  offline DDP plan (dashed) against the WIPM state of the full robot under control (solid) for
  ``theta``, ``thetad``, ``x``, ``xd``; the control ``thdd`` (the MPC's, solid, against the
  plan's, dashed); and every actuator's torque over time.
* ``<controller>_snapshots.png`` (Fig. 3b, "movie"): the full body rendered offscreen at six
  instants from the start to the time the goal is reached (or the end), the body CoM projected
  into each image as a blue dot (with the axle-to-CoM line, whose angle is ``theta``, and the
  CoM's path over the last half second), the tray's plate as a red line, and, as in the paper,
  the body's pose at five earlier instants (0.1 s apart) as grey stick figures, which show the
  motion the tracking camera hides.
* ``comparison.png``: every controller side by side: ``theta`` and ``x`` against time, and the
  tray's tilt and the cup's friction use in tray tasks.

In tray tasks the episode goes on after the cup leaves the tray (``terminate_on_cup_loss`` is
off, so a reader sees what happens to the cup); the moment it left is marked. A fall ends it.

    wip-bench figures --env wip_gym/PlanarTray-v0 --out docs/figures
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from benchmarks.overrides import resolve_run
from benchmarks.rollout import rollout
from benchmarks.scenario import Scenario, check_task_flags, parse_controllers, resolve_env_id
from controllers.high_level.planning import Plan
from controllers.registry import controller_names
from controllers.simplified.wipm_problem import PLANAR_STATE, SPATIAL_STATE
from wip_gym.scene import TRAY_HALF_SIZE

Array = NDArray[np.float64]

DEFAULT_ENV = "wip_gym/PlanarTray-v0"
DEFAULT_CONTROLLERS = "unified,decoupled"
DEFAULT_DURATION_S = 10.0
SNAPSHOTS = 6
TRAIL_S = 0.5  # the CoM's path drawn behind each snapshot
GHOSTS = 5  # earlier poses drawn as stick figures behind each snapshot (the paper's)
GHOST_INTERVAL_S = 0.1
DPI = 120

# the WIPM panels: state name, axis label
WIPM_PANELS = (
    ("theta", r"$\theta$ (rad)"),
    ("thetad", r"$\dot\theta$ (rad/s)"),
    ("x", r"$x$ (m)"),
    ("xd", r"$\dot x$ (m/s)"),
)
# the comparison panels, in order of preference: info key, axis label
COMPARISON_PANELS = (
    ("theta", r"$\theta$ (rad)"),
    ("x", r"$x$ (m)"),
    ("tray_tilt_deg", "tray tilt (deg)"),
    ("cup_friction_use", "cup friction use (1 = slip)"),
    ("ee_error", "end-effector error (m)"),
    ("goal_distance", "distance to goal (m)"),
    ("xd", r"$\dot x$ (m/s)"),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", default=DEFAULT_ENV, help="env id (wip_gym/NAME or NAME)")
    parser.add_argument(
        "--controllers",
        default=DEFAULT_CONTROLLERS,
        help=f"comma-separated, from {controller_names()}",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION_S, metavar="SECONDS")
    parser.add_argument("--goal", type=float, nargs="+", metavar=("X", "Y"))
    parser.add_argument("--cup-friction", type=float, metavar="MU")
    parser.add_argument("--model", default="nominal", choices=["nominal", "oracle"])
    parser.add_argument("--width", type=int, default=640, help="render width (px)")
    parser.add_argument("--height", type=int, default=480, help="render height (px)")
    parser.add_argument("--out", default="out/figures", metavar="DIR")


def scenario_from_args(args: argparse.Namespace) -> tuple[Scenario, list[str]]:
    """Validate the flags; raise ValueError naming the valid choices."""
    env_id = resolve_env_id(args.env)
    names = parse_controllers(args.controllers)
    if not (np.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be positive, got {args.duration}")
    check_task_flags(env_id, args.goal, args.cup_friction)
    for flag, value in (("--width", args.width), ("--height", args.height)):
        if not 16 <= value <= 4096:
            raise ValueError(f"{flag} must be in [16, 4096] px, got {value}")
    scenario = Scenario(
        env_id=env_id,
        goal=tuple(args.goal) if args.goal is not None else None,
        cup_friction=args.cup_friction,
        duration=args.duration,
        model=args.model,
    )
    scenario.make_env().close()  # the env validates the task values (goal shape, ...)
    return scenario, names


# ---------------------------------------------------------------------------- the episode
@dataclass
class Snapshot:
    """One rendered instant and what is drawn over it (pixel coordinates ``(u, v)``).

    Attributes:
        time: s. image: (H, W, 3) uint8. com, axle: the body CoM and the axle midpoint.
        trail: the CoM over the last ``TRAIL_S`` (k, 2). tray: the plate's two ends (2, 2),
        None without a tray. ghosts: the body's stick figure (segments (s, 2, 2)) at up to
        ``GHOSTS`` earlier instants ``GHOST_INTERVAL_S`` apart, oldest first, seen from this
        instant's camera. crop: ``(u0, v0, u1, v1)`` of the robot in the image.
        theta, x, tilt_deg: from the env's info at that instant (tilt None without a tray).
    """

    time: float
    image: NDArray[np.uint8]
    com: Array
    axle: Array
    trail: Array
    tray: Array | None
    ghosts: list[Array]
    crop: tuple[int, int, int, int]
    theta: float
    x: float
    tilt_deg: float | None


@dataclass
class Run:
    """One controller's episode: what the figures need.

    Attributes:
        controller, env_id: names. goal: ``(X, Y)``. dt: control step (s). planar: robot kind.
        times: (n,) s, the instant of each ``info`` row (0 = reset).
        info: per-step scalars of the env's ``info`` (``theta``, ``x``, ``tray_tilt_deg``, ...).
        diagnostics: the policy's per-step signals (``diagnostics[...][k]`` computed from the
            observation at ``times[k]``).
        plan: the offline plan the controller follows, if it has one.
        actuators: actuator names, in action order.
        fell, cup_lost_at, reached_at: outcome (``reached_at``: ``metrics.time_to_goal``).
        snapshots: the rendered instants.
    """

    controller: str
    env_id: str
    goal: Array
    dt: float
    planar: bool
    times: Array
    info: dict[str, Array]
    diagnostics: dict[str, Array]
    plan: Plan | None
    actuators: list[str]
    fell: bool
    cup_lost_at: float | None
    reached_at: float | None
    snapshots: list[Snapshot] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def peak(self, key: str) -> float | None:
        """``max |info[key]|`` over the episode, None if the env does not report it."""
        return float(np.max(np.abs(self.info[key]))) if key in self.info else None


def project(
    points: Array,
    camera_position: Array,
    camera_matrix: Array,
    fovy_deg: float,
    width: int,
    height: int,
) -> Array:
    """World points (k, 3) to pixel coordinates (k, 2) ``(u right, v down)`` of a MuJoCo
    camera (it looks along its -z, x to the right, y up; ``fovy`` is the vertical field of
    view); points behind the camera come out as NaN."""
    local = (np.atleast_2d(points) - camera_position) @ camera_matrix  # rows: R^T (p - c)
    depth = -local[:, 2]
    focal = 0.5 * height / np.tan(np.radians(fovy_deg) / 2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = 0.5 * width + focal * local[:, 0] / depth
        v = 0.5 * height - focal * local[:, 1] / depth
    pixels = np.stack([u, v], axis=1)
    pixels[depth <= 1e-9] = np.nan
    return pixels


def snapshot_times(duration: float, reached_at: float | None, count: int = SNAPSHOTS) -> Array:
    """``count`` instants evenly from 0 to the time the goal is reached (the end if never)."""
    end = duration if reached_at is None else min(max(reached_at, 0.0), duration)
    if end <= 0.0:
        end = duration
    return np.linspace(0.0, end, count)


def _robot_extent_points(base: Any) -> Array:
    """World points bounding the robot, its tray and cup: each geom's centre plus and minus
    its bounding radius along the world axes."""
    m, d = base.model, base.data
    root = m.body_rootid[base.robot.layout.base_body]
    roots = {root}
    for name in ("tray", "cup"):
        body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if body >= 0:
            roots.add(m.body_rootid[body])
    geoms = [
        g
        for g in range(m.ngeom)
        if m.body_rootid[m.geom_bodyid[g]] in roots and m.geom_bodyid[g] != 0
    ]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    points = [d.geom_xpos[g] + m.geom_rbound[g] * corners for g in geoms]
    return np.concatenate(points) if points else np.zeros((0, 3))


def _skeleton(base: Any) -> Array:
    """The robot's stick figure in world, segments (s, 2, 3): each body's origin (its joint)
    to its parent's, wheels left out, plus the hand to its ``ee`` site."""
    m, d = base.model, base.data
    lay = base.robot.layout
    root = m.body_rootid[lay.base_body]
    wheels = set(lay.wheel_bodies)
    bodies = {b for b in range(1, m.nbody) if m.body_rootid[b] == root and b not in wheels}
    segments = [
        (d.xpos[m.body_parentid[b]], d.xpos[b])
        for b in sorted(bodies)
        if m.body_parentid[b] in bodies
    ]
    for name in ("ee", "ee_right"):
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
        if site >= 0:
            segments.append((d.xpos[m.site_bodyid[site]], d.site_xpos[site]))
    return np.array(segments, dtype=float).reshape(-1, 2, 3)


def _tray_ends(base: Any) -> Array | None:
    m, d = base.model, base.data
    body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tray")
    if body < 0:
        return None
    R = d.xmat[body].reshape(3, 3)
    top = 2 * TRAY_HALF_SIZE[2]
    return np.array(
        [d.xpos[body] + R @ np.array([s * TRAY_HALF_SIZE[0], 0.0, top]) for s in (-1.0, 1.0)]
    )


def render_snapshots(
    env: Any, qpos: Array, qvel: Array, com_world: Array, axle_world: Array, run: Run
) -> list[Snapshot]:
    """Restore each chosen instant's state into the env, render it and project the marks."""
    base = env.unwrapped
    m, d = base.model, base.data
    camera = base.mujoco_renderer.camera_id
    if camera < 0:
        raise RuntimeError("the env renders from a free camera: no camera matrices to project")
    width, height = base.width, base.height
    trail_steps = max(1, int(round(TRAIL_S / run.dt)))
    ghost_steps = max(1, int(round(GHOST_INTERVAL_S / run.dt)))
    snapshots = []
    extents = []
    for t in snapshot_times(run.duration, run.reached_at):
        k = int(np.clip(round(t / run.dt), 0, len(run.times) - 1))
        base.set_state(qpos[k], qvel[k])  # mj_forward: bodies, camera pose
        image = np.asarray(env.render()).copy()
        camera_position = d.cam_xpos[camera].copy()
        camera_matrix = d.cam_xmat[camera].reshape(3, 3).copy()

        def to_pixels(points: Array, c: Array = camera_position, R: Array = camera_matrix) -> Array:
            return project(points, c, R, float(m.cam_fovy[camera]), width, height)

        extent = to_pixels(_robot_extent_points(base))
        extents.append(extent[np.all(np.isfinite(extent), axis=1)])
        tray = _tray_ends(base)
        snapshot = Snapshot(
            time=float(run.times[k]),
            image=image,
            com=to_pixels(com_world[k])[0],
            axle=to_pixels(axle_world[k])[0],
            trail=to_pixels(com_world[max(0, k - trail_steps) : k + 1]),
            tray=None if tray is None else to_pixels(tray),
            ghosts=[],
            crop=(0, 0, width, height),
            theta=float(run.info["theta"][k]),
            x=float(run.info["x"][k]),
            tilt_deg=(float(run.info["tray_tilt_deg"][k]) if "tray_tilt_deg" in run.info else None),
        )
        for j in range(GHOSTS, 0, -1):
            if k - j * ghost_steps < 0:
                continue
            base.set_state(qpos[k - j * ghost_steps], qvel[k - j * ghost_steps])
            segments = _skeleton(base)
            snapshot.ghosts.append(to_pixels(segments.reshape(-1, 3)).reshape(-1, 2, 2))
        snapshots.append(snapshot)
    # one crop size for every panel (the largest robot, a margin around it), a little wider
    # than tall: the earlier poses trail behind
    boxes = [(e.min(axis=0), e.max(axis=0)) for e in extents if len(e)]
    if boxes:
        size = max(max(hi[0] - lo[0], hi[1] - lo[1]) for lo, hi in boxes)
        h_crop = min(height, int(np.ceil(1.1 * size)) + 4)
        w_crop = min(width, int(np.ceil(1.2 * h_crop)))
        for snap, (lo, hi) in zip(snapshots, boxes, strict=True):
            cu, cv = 0.5 * (lo + hi)
            u0 = int(np.clip(round(cu - w_crop / 2), 0, width - w_crop))
            v0 = int(np.clip(round(cv - h_crop / 2), 0, height - h_crop))
            snap.crop = (u0, v0, u0 + w_crop, v0 + h_crop)
    return snapshots


def run_controller(scenario: Scenario, controller: str, seed: int, width: int, height: int) -> Run:
    """One seeded episode of ``controller`` on ``scenario`` (the one rollout, its metrics),
    recorded for the figures."""
    env_kwargs: dict[str, Any] = {
        **scenario.env_kwargs(),
        "render_mode": "rgb_array",
        "width": width,
        "height": height,
        "camera_name": "track",  # a fixed MJCF camera: its matrices project the marks
    }
    if "Tray" in scenario.env_id:
        env_kwargs["terminate_on_cup_loss"] = False  # show what happens to the cup
    spec = resolve_run(scenario.env_id, [controller], controller_flags={"model": scenario.model})
    rows: dict[str, list[float]] = {}
    qpos, qvel, com_world, axle_world = [], [], [], []

    def record(env: Any, info: dict[str, Any], step_index: int) -> None:
        base = env.unwrapped
        if step_index == 0:
            for key, value in info.items():
                if np.ndim(value) == 0 and not key.startswith("reward"):
                    rows[key] = []
        for key, values in rows.items():
            values.append(float(info[key]))
        qpos.append(base.data.qpos.copy())
        qvel.append(base.data.qvel.copy())
        robot, lay = base.robot, base.robot.layout
        # the env's step no longer updates its RobotModel (it reads MuJoCo's own kinematics)
        robot.update(base.data.qpos[: lay.nq], base.data.qvel[: lay.nv], dynamics=False)
        axle = robot.axle_position
        axle_world.append(axle)
        com_world.append(axle + base.robot.heading_rotation @ base.robot.com)

    episode = rollout(
        scenario.env_id,
        env_kwargs,
        controller,
        spec.configs[controller],
        seed,
        scenario.duration,
        on_step=record,
        keep_env=True,
    )
    env = episode.env
    assert env is not None  # keep_env
    try:
        base = env.unwrapped
        dt = float(base.dt)
        times = np.arange(len(qpos)) * dt
        metrics = episode.metrics
        run = Run(
            controller=controller,
            env_id=scenario.env_id,
            goal=base.goal,
            dt=dt,
            planar=base.robot.layout.planar,
            times=times,
            info={k: np.asarray(v) for k, v in rows.items()},
            diagnostics=dict(episode.policy.diagnostics),
            plan=getattr(episode.policy, "plan", None),
            actuators=[base.model.actuator(i).name for i in range(base.model.nu)],
            fell=bool(metrics["fell"]),
            cup_lost_at=metrics["cup_lost_at_s"],
            reached_at=metrics["time_to_goal_s"],
        )
        run.snapshots = render_snapshots(
            env, np.array(qpos), np.array(qvel), np.array(com_world), np.array(axle_world), run
        )
        return run
    finally:
        env.close()


# ---------------------------------------------------------------------------- the WIPM figure
def wipm_signals(run: Run) -> dict[str, tuple[Array, Array]]:
    """The WIPM state under control, by name: ``(t, values)``. From the diagnostics'
    ``wipm_state`` (the hierarchical and MPC controllers), else from the decoupled
    baselines' ``theta``, ``thetad``, ``x``, ``xd``, else from the env's info."""
    diag = run.diagnostics
    names = PLANAR_STATE if run.planar else SPATIAL_STATE
    if "wipm_state" in diag and "t" in diag:
        state = np.atleast_2d(diag["wipm_state"])
        return {name: (diag["t"], state[:, i]) for i, name in enumerate(names)}
    if all(k in diag for k in ("t", "theta", "thetad", "x", "xd")):
        return {name: (diag["t"], diag[name]) for name, _ in WIPM_PANELS}
    n = len(run.times) - 1  # the info row after the last step is no policy input
    return {name: (run.times[:n], run.info[name][:n]) for name, _ in WIPM_PANELS}


def wipm_references(run: Run) -> dict[str, tuple[Array, Array]]:
    """The reference, by name: the controller's own ``*_ref`` diagnostics where it records
    them (the decoupled baselines: ``decoupled`` balances about ``theta_ref = 0`` while it
    follows the plan's ``x``; ``decoupled-lqr`` tracks the plan's lean), else the offline
    plan's states up to the run's end (the MPC controllers' reference)."""
    names = PLANAR_STATE if run.planar else SPATIAL_STATE
    diag = run.diagnostics
    own = {
        name: (diag["t"], diag[f"{name}_ref"])
        for name, _ in WIPM_PANELS
        if "t" in diag and f"{name}_ref" in diag
    }
    if own or run.plan is None:
        return own
    keep = run.plan.times <= run.duration + 1e-9
    return {name: (run.plan.times[keep], run.plan.states[keep, i]) for i, name in enumerate(names)}


def _mark_events(ax: Axes, run: Run) -> None:
    if run.cup_lost_at is not None:
        ax.axvline(run.cup_lost_at, color="tab:red", lw=0.8, ls=":")
    if run.reached_at is not None:
        ax.axvline(run.reached_at, color="tab:green", lw=0.8, ls=":")


def _outcome(run: Run) -> str:
    parts = []
    if run.fell:
        parts.append(f"fell at {run.duration:.2f} s")
    if run.cup_lost_at is not None:
        parts.append(f"cup lost at {run.cup_lost_at:.2f} s")
    elif "cup_on_tray" in run.info:
        parts.append("cup kept")
    parts.append(
        f"goal reached at {run.reached_at:.2f} s"
        if run.reached_at is not None
        else "goal not reached"
    )
    return ", ".join(parts)


def wipm_figure(run: Run, path: Path) -> Path:
    """The paper's Fig. 3a for one run (see the module docstring)."""
    fig = Figure(figsize=(15, 7.5), layout="constrained")
    axes = fig.subplots(2, 3)
    signals, references = wipm_signals(run), wipm_references(run)
    own = "theta_ref" in run.diagnostics  # the decoupled baselines record their own
    source = "the controller's reference" if own else "reference (DDP plan)"
    for ax, (name, label) in zip(axes.flat[:4], WIPM_PANELS, strict=True):
        if name in references:
            t_ref, ref = references[name]
            ax.plot(t_ref, ref, "--", color="tab:orange", lw=1.5, label=source)
        t, value = signals[name]
        ax.plot(t, value, "-", color="tab:blue", lw=1.2, label="state under control")
        ax.set_ylabel(label)
    if "x" in references and run.planar:
        axes.flat[2].axhline(run.goal[0], color="0.5", lw=0.6, ls="-.", label="goal")
    ax = axes.flat[4]
    ax.set_ylabel(r"control $\ddot\theta$ (rad/s$^2$)")
    if run.plan is not None:
        keep = run.plan.times[:-1] <= run.duration + 1e-9
        ax.plot(
            run.plan.times[:-1][keep],
            run.plan.controls[keep, 0],
            "--",
            color="tab:orange",
            lw=1.5,
            label="plan (DDP)",
        )
    if "thdd_ref" in run.diagnostics:
        ax.plot(
            run.diagnostics["t"],
            run.diagnostics["thdd_ref"],
            "-",
            color="tab:blue",
            lw=1.0,
            label=r"MPC $\ddot\theta^{ref}$",
        )
    else:
        ax.text(
            0.5,
            0.92,
            "no MPC: state feedback on the wheel torques",
            transform=ax.transAxes,
            ha="center",
            va="top",
            fontsize=9,
            color="0.3",
        )
    ax = axes.flat[5]
    torque = run.diagnostics.get("torque")
    if torque is not None:
        torque = np.atleast_2d(torque)
        palette = colormaps["tab10" if torque.shape[1] <= 10 else "tab20"].colors
        columns = torque.shape[1]
        same = np.array(
            [
                [np.allclose(torque[:, i], torque[:, j]) for j in range(columns)]
                for i in range(columns)
            ]
        )
        for i, name in enumerate(run.actuators[:columns]):
            # an actuator with the torque of an earlier one (a planar robot's two wheels) is
            # dashed over the earlier one's wider line, so both stay visible
            copy = same[i, :i].any()
            width = 2.2 if same[i, i + 1 :].any() else 0.9
            ax.plot(
                run.diagnostics["t"],
                torque[:, i],
                "--" if copy else "-",
                lw=width,
                color=palette[i % len(palette)],
                label=name,
            )
        ax.legend(fontsize=7, ncol=2, loc="best")
    ax.set_ylabel("joint torques (N m)")
    ax.set_title("every actuator", fontsize=9)
    for ax in axes.flat:
        ax.set_xlabel("t (s)")
        ax.set_xlim(0.0, run.duration)
        ax.grid(alpha=0.3)
        _mark_events(ax, run)
    for ax in axes.flat[:5]:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="best")
    peaks = f"peak |theta| {run.peak('theta'):.3f} rad"
    if "tray_tilt_deg" in run.info:
        peaks += f", peak tray tilt {run.peak('tray_tilt_deg'):.2f} deg"
    fig.suptitle(
        f"{run.controller} on {run.env_id}: WIPM reference (dashed) vs state under control "
        f"(solid); dotted: goal reached (green), cup lost (red)\n{_outcome(run)}; {peaks}"
    )
    fig.savefig(path, dpi=DPI)
    return path


# ---------------------------------------------------------------------------- the snapshots
def snapshots_figure(run: Run, path: Path) -> Path:
    """The paper's Fig. 3b for one run (see the module docstring)."""
    count = len(run.snapshots)
    first = run.snapshots[0]
    u0, v0, u1, v1 = first.crop
    aspect = (v1 - v0) / max(u1 - u0, 1)
    fig = Figure(figsize=(2.6 * count, 2.6 * aspect + 1.3), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, count))
    for ax, snap in zip(axes, run.snapshots, strict=True):
        u0, v0, u1, v1 = snap.crop
        ax.imshow(snap.image[v0:v1, u0:u1], extent=(u0, u1, v1, v0), interpolation="lanczos")
        for j, segments in enumerate(snap.ghosts):
            alpha = 0.25 + 0.5 * (j + 1) / (len(snap.ghosts) + 1)
            for segment in segments:
                ax.plot(*segment.T, "-", color="0.15", lw=1.2, alpha=alpha, solid_capstyle="round")
        ax.plot(*snap.trail.T, "-", color="tab:blue", lw=1.0, alpha=0.45)
        ax.plot(*np.stack([snap.axle, snap.com]).T, "-", color="tab:blue", lw=1.0)
        ax.plot(*snap.com, "o", ms=7, mfc="tab:blue", mec="white", mew=1.0)
        if snap.tray is not None:
            ax.plot(*snap.tray.T, "-", color="red", lw=2.0, solid_capstyle="butt")
        ax.set_xlim(u0, u1)
        ax.set_ylim(v1, v0)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"t = {snap.time:.2f} s", fontsize=10)
        x, theta = round(snap.x, 2) + 0.0, round(snap.theta, 3) + 0.0  # no "-0.00"
        text = rf"$x$ = {x:.2f} m, $\theta$ = {theta:+.3f} rad"
        if snap.tilt_deg is not None:
            text += f"\ntray tilt {snap.tilt_deg:.2f} deg"
        ax.set_xlabel(text, fontsize=8)
    legend = (
        "blue dot: body CoM (line from the axle: theta; faint: its path over the last "
        f"{TRAIL_S:g} s); grey sticks: the body {GHOST_INTERVAL_S:g} s apart before"
    )
    if first.tray is not None:
        legend += "; red: the tray's plate"
    fig.suptitle(
        f"{run.controller} on {run.env_id}: full body at {count} instants ({_outcome(run)})\n"
        + legend,
        fontsize=10,
    )
    fig.savefig(path, dpi=DPI)
    return path


# ---------------------------------------------------------------------------- side by side
def comparison_figure(runs: list[Run], path: Path) -> Path:
    """Every controller's run on the same axes (see the module docstring)."""
    available = [(k, label) for k, label in COMPARISON_PANELS if all(k in r.info for r in runs)]
    panels = available[:4]
    fig = Figure(figsize=(12, 7), layout="constrained")
    axes = list(fig.subplots(2, 2).flat)
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple", "tab:brown", "tab:olive"]
    for ax, (key, label) in zip(axes, panels, strict=False):
        for i, run in enumerate(runs):
            color = colors[i % len(colors)]
            ax.plot(run.times, run.info[key], color=color, lw=1.1, label=run.controller)
            if run.cup_lost_at is not None:
                ax.axvline(run.cup_lost_at, color=color, lw=0.8, ls=":")
        if key == "x" and runs[0].planar:
            ax.axhline(runs[0].goal[0], color="0.5", lw=0.7, ls="-.", label="goal")
        if key == "cup_friction_use":
            ax.axhline(1.0, color="0.3", lw=0.7, ls="--", label="slip")
        ax.set_ylabel(label)
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    outcomes = "; ".join(f"{r.controller}: {_outcome(r)}" for r in runs)
    note = " (dotted: cup lost)" if "cup_on_tray" in runs[0].info else ""
    fig.suptitle(f"{runs[0].env_id}: controllers side by side{note}\n{outcomes}", fontsize=10)
    fig.savefig(path, dpi=DPI)
    return path


# ---------------------------------------------------------------------------- the command
def summary_line(run: Run) -> str:
    text = f"{run.controller:<16} peak |theta| {run.peak('theta'):.3f} rad"
    if "tray_tilt_deg" in run.info:
        text += f", peak tray tilt {run.peak('tray_tilt_deg'):.2f} deg"
        text += f", peak cup friction use {run.peak('cup_friction_use'):.2f}"
    return f"{text}; {_outcome(run)}"


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run every controller, write the figures, print their paths; return the runs and
    the paths."""
    scenario, names = scenario_from_args(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    runs = []
    paths: list[Path] = []
    for name in names:
        print(f"running {name} on {scenario.env_id} for {scenario.duration:g} s ...", flush=True)
        result = run_controller(scenario, name, args.seed, args.width, args.height)
        runs.append(result)
        paths.append(wipm_figure(result, out / f"{name}_wipm.png"))
        paths.append(snapshots_figure(result, out / f"{name}_snapshots.png"))
        print(summary_line(result), flush=True)
    paths.append(comparison_figure(runs, out / "comparison.png"))
    for path in paths:
        print(f"wrote {path}")
    return {"runs": runs, "paths": paths}
