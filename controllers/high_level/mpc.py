"""Model predictive control on the WIPM, tracking the offline plan (paper section "Receding
Horizon Control").

Every ``dt`` (10 ms) over ``horizon_s`` (the paper's 1 s; the authors' code used 0.1 s), from
the current WIPM state with ``lambda(q)`` updated at every step (as the paper says; the
authors' code froze it), the DDP tracks the plan's window by time index (past the plan's end,
its continuation until it rests at the goal, then its rest state: ``Plan.reference_states``,
``Plan.rest_state``; docs/controllers.md §3.1), warm-started from the previous solution
shifted by one step, with a fixed budget of iterations (real-time MPC does not wait for
convergence). Its result is used when it is finite and its cost did not rise above the warm
start's; otherwise (a NaN or a divergence) the previous controls, shifted, are kept and the
rejection is counted.

Two backends run the same step (``MPCConfig.backend``): ``"jax"``, the DDP of
``controllers.optimizer.ddp`` jitted by XLA, the reference; and ``"numba"``, the same algorithm
with every derivative from the same JAX functions, written out as scalar code and compiled by
numba (``controllers.optimizer.numba_ddp``), equal to it to round-off (tests/test_numba_ddp.py)
and 1.3 to 2.5 times as fast.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

from controllers.high_level.planning import Plan
from controllers.optimizer import jax_setup, numba_ddp
from controllers.optimizer.ddp import DDPConfig, rollout
from controllers.simplified.wipm import WIPMParams
from controllers.simplified.wipm_problem import Weights, WIPMProblem, ddp_solver_for
from wip_gym.minimal_kernels import WIPM_VECTOR_LENGTH, WIPM_VECTOR_SIZES
from wip_gym.robot_model import RobotModel


@dataclass(frozen=True)
class MPCConfig:
    """MPC settings; the authors' values (docs/AUTHORS_CONFIG.md §3.3) for comparison.

    Attributes:
        horizon_s, dt: 1 s at 10 ms (paper: 1 s; authors' code: 10 steps = 0.1 s at 10 ms).
        iterations: DDP iterations per MPC step (authors: 50; real-time budget here: 2).
        q_theta, q_thetad, q_position, q_speed, q_heading: tracking weights (authors' 3-D
            Q = diag[0, 10, 10, 0.1, 0.1, 0.1, 10, 10] over [x, psi, theta, xd, psid, thetad,
            X0, Y0]: higher on positions than speeds, as the paper says).
        r_control: weights on [thdd, tau_0] (authors 0.01, 0.01).
        q_terminal, q_terminal_speed: terminal weights on positions and theta (authors 1e5) and
            on speeds (authors 1e4).
        ddp: solver settings except the iteration budget (iLQR, no tolerance stop, no backward
            pass after the last line search: the MPC uses the controls, not the gains; no
            gradient norm: nothing reads it).
        backend: ``"numba"`` (default: the same solve to round-off, 1.3 to 2.5 times as fast)
            or ``"jax"`` (the reference; it also runs the settings
            the numba backend refuses: ``second_order``, ``gradient_norm``).
    """

    horizon_s: float = 1.0
    dt: float = 0.01
    iterations: int = 2
    q_theta: float = 10.0
    q_thetad: float = 0.1
    q_position: float = 10.0
    q_speed: float = 0.1
    q_heading: float = 10.0
    r_control: float = 0.01
    q_terminal: float = 1e5
    q_terminal_speed: float = 1e4
    ddp: DDPConfig = field(
        default_factory=lambda: DDPConfig(
            max_iterations=2,
            tolerance=0.0,
            second_order=False,
            final_backward=False,
            gradient_norm=False,
        )
    )
    backend: Literal["jax", "numba"] = "numba"

    def __post_init__(self) -> None:
        if self.backend not in ("jax", "numba"):
            raise ValueError(f"MPC backend must be 'jax' or 'numba', got {self.backend!r}")

    @property
    def steps(self) -> int:
        steps = self.horizon_s / self.dt
        if abs(steps - round(steps)) > 1e-9 or steps < 1:
            raise ValueError(f"MPC horizon {self.horizon_s} s is not a whole number of {self.dt} s")
        return int(round(steps))


def mpc_problem(planar: bool, config: MPCConfig, a_max: float, theta_max: float) -> WIPMProblem:
    c = config
    if planar:
        q = (c.q_theta, c.q_thetad, c.q_position, c.q_speed)
        q_terminal = (c.q_terminal, c.q_terminal_speed, c.q_terminal, c.q_terminal_speed)
        r = (c.r_control,)
    else:
        q = (
            0.0,
            c.q_heading,
            c.q_theta,
            c.q_speed,
            c.q_speed,
            c.q_thetad,
            c.q_position,
            c.q_position,
        )
        q_terminal = (
            0.0,
            c.q_terminal,
            c.q_terminal,
            c.q_terminal_speed,
            c.q_terminal_speed,
            c.q_terminal_speed,
            c.q_terminal,
            c.q_terminal,
        )
        r = (c.r_control, c.r_control)
    weights = Weights(q=q, r=r, r_rate=(), q_terminal=q_terminal, a_max=a_max, theta_max=theta_max)
    return WIPMProblem(planar=planar, dt=c.dt, weights=weights, rate_input=False)


@dataclass(frozen=True)
class MPCStep:
    """One MPC solution: the control to apply now, the predicted trajectory, and whether the
    new solution was accepted."""

    control: np.ndarray
    predicted_states: np.ndarray
    predicted_controls: np.ndarray
    cost: float
    accepted: bool


class _CompiledStep:
    """One jitted MPC step for a problem, solver settings and horizon (shared by every
    :class:`ModelPredictiveController` of that problem, so a new plan or a new controller does
    not retrace). Everything of a step happens inside it: the plan's window by index (the padded
    plan arrays are inputs), ``lambda(q)`` broadcast along the horizon, the warm start, the DDP,
    the acceptance test with its fallback rollout and the shifted warm start of the next step,
    which stays on the device. ``trace_count`` counts its traces (one per horizon and plan
    length is the design).

    The step runs inside a ``lax.while_loop`` that makes one trip (:meth:`_one_trip`), so that
    XLA:CPU compiles the whole step into one kernel (``controllers.optimizer.jax_setup``'s
    small-loop option) rather than dispatching each of its ~40 top-level operations (the
    parameters' broadcasts along the horizon, the window's slices, the acceptance test, the
    packing) through its runtime one by one. Measured: the 3-D step ~3-4 units faster, the
    same results bit for bit.

    The host's inputs (the plan index, the first-step flag, the state and ``lambda(q)``'s 11
    leaves) come packed in one vector (:func:`pack_inputs`): one argument to hand over instead
    of fourteen. The results are the same to the bit, the step slightly faster."""

    def __init__(self, problem: WIPMProblem, ddp: DDPConfig, horizon: int) -> None:
        self.problem, self.ddp = problem, ddp
        self.solver = ddp_solver_for(problem, ddp)
        self.dynamics = problem.dynamics()
        self.horizon = horizon
        self.trace_count = 0
        self.jitted = jax.jit(self._one_trip)

    def __call__(
        self, host: np.ndarray, warm: Any, plan_states: Any, plan_controls: Any
    ) -> tuple[Any, Any]:
        """``(packed, next_warm)`` of one step (:meth:`_step`), traced and run in float64
        (``jax_setup.float64``: in any thread, whatever the process's JAX settings)."""
        with jax_setup.float64():
            return self.jitted(host, warm, plan_states, plan_controls)

    def __reduce__(self) -> tuple[Any, tuple[WIPMProblem, DDPConfig, int]]:
        # a copy or an unpickled one is the shared step of its problem, settings and horizon
        return compiled_step, (self.problem, self.ddp, self.horizon)

    def _one_trip(
        self, host: jax.Array, warm: jax.Array, plan_states: jax.Array, plan_controls: jax.Array
    ) -> tuple[jax.Array, jax.Array]:
        """:meth:`_step` of the host's inputs packed in one vector (:func:`pack_inputs`,
        unpacked inside the loop) as the body of a ``while`` loop that stops after its first
        trip (a flag, not a counter: XLA cannot see the trip count and inline the loop away)."""
        self.trace_count += 1
        inputs = (host, warm, plan_states, plan_controls)

        def step(*values: jax.Array) -> tuple[jax.Array, jax.Array]:
            return self._step(*unpack_inputs(*values))

        # the loop's carry before its trip: zeros shaped as _step's outputs
        shapes = jax.eval_shape(step, *inputs)
        initial = (*(jnp.zeros(a.shape, a.dtype) for a in shapes), jnp.array(False))

        def body(carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
            return (*step(*inputs), jnp.array(True))

        packed, next_warm, _ = jax.lax.while_loop(lambda carry: ~carry[2], body, initial)
        return packed, next_warm

    def _step(
        self,
        index: jax.Array,
        first: jax.Array,
        state: jax.Array,
        params: WIPMParams,
        warm: jax.Array,
        plan_states: jax.Array,
        plan_controls: jax.Array,
    ) -> tuple[jax.Array, jax.Array]:
        """``(packed, next_warm)``: ``packed`` holds ``X`` (N+1, n), ``U`` (N, m), the cost, the
        warm start's cost and the acceptance flag, flattened in that order."""
        H = self.horizon
        window = jax.lax.dynamic_slice_in_dim(plan_states, index, H + 1)
        plan_warm = jax.lax.dynamic_slice_in_dim(plan_controls, index, H)
        warm = jnp.where(first, plan_warm, warm)
        per_step = jax.tree.map(
            lambda leaf: jnp.broadcast_to(leaf, (H + 1, *jnp.shape(leaf))), params
        )
        result = self.solver.jitted(state, warm, params, (window, per_step))
        X, U, cost = result.X, result.U, result.cost
        initial = result.cost_history[0]
        accepted = (
            jnp.all(jnp.isfinite(X))
            & jnp.all(jnp.isfinite(U))
            & jnp.isfinite(cost)
            & (cost <= initial * (1 + 1e-12) + 1e-12)
        )
        X, U, cost = jax.lax.cond(
            accepted,
            lambda: (X, U, cost),
            lambda: (rollout(self.dynamics, state, warm, params), warm, initial),
        )
        # warm start of the next step: shifted by one, the reference's control past the end
        tail = jax.lax.dynamic_slice_in_dim(plan_controls, index + H, 1)
        next_warm = jnp.concatenate([U[1:], tail], axis=0)
        packed = jnp.concatenate(
            [X.ravel(), U.ravel(), jnp.stack([cost, initial]), accepted.astype(X.dtype)[None]]
        )
        return packed, next_warm


#: the MPC's padded reference has a multiple of this many rows (``ModelPredictiveController``)
PADDED_ROWS = 1000
#: the host's inputs of a packed MPC step before the state: the plan index and the first flag
HOST_HEAD = 2
#: WIPMParams' leaves in one vector: its scalars, with ``inertia_body``'s 9 entries (row-major)
#: in its place (the layout ``RobotModel.wipm_inputs`` writes)
_PARAM_SIZES = WIPM_VECTOR_SIZES
_N_PARAMS = WIPM_VECTOR_LENGTH


def param_values(params: WIPMParams) -> list[float]:
    """``lambda(q)``'s leaves as ``_N_PARAMS`` floats in :data:`_PARAM_SIZES`' order
    (``inertia_body`` row-major); :func:`params_from_vector` is its inverse in traced code.
    ``ValueError`` for a leaf of another size."""
    values: list[float] = []
    for leaf, size in zip(params, _PARAM_SIZES, strict=True):
        # the leaves params_from_robot makes first (NumPy float64 scalars are floats; a float64
        # array's tolist is exact): np.ndim and np.asarray cost ~0.3 us a leaf
        if size == 1 and isinstance(leaf, float):
            values.append(float(leaf))
        elif type(leaf) is np.ndarray and leaf.dtype == np.float64 and leaf.size == size:
            values.extend(leaf.ravel().tolist())
        elif size == 1 and np.ndim(leaf) == 0:
            values.append(float(leaf))
        else:
            flat = np.asarray(leaf, dtype=np.float64).ravel()
            if flat.size != size:
                raise ValueError(f"a WIPM parameter of {flat.size} entries: expected {size}")
            values.extend(flat.tolist())
    return values


def params_from_vector(vector: jax.Array | np.ndarray) -> WIPMParams:
    """The :class:`WIPMParams` of :func:`param_values`' floats (a vector of ``_N_PARAMS``)."""
    leaves, at = [], 0
    for size in _PARAM_SIZES:
        leaves.append(vector[at] if size == 1 else vector[at : at + size].reshape(3, 3))
        at += size
    return WIPMParams(*leaves)


def pack_inputs(index: int, first: bool, state: np.ndarray, params: WIPMParams) -> np.ndarray:
    """The MPC step's host inputs as one float64 vector ``[index, first, state, params]``
    (:func:`unpack_inputs` is its inverse inside the compiled step; the index is exact in
    float64)."""
    values = [float(index), float(first), *np.asarray(state, dtype=np.float64).tolist()]
    # one array from Python floats: a slice assignment per leaf cost ~1.5 us each (16 us in
    # all in a tight loop, 60 us per MPC tick in the closed loop)
    return np.array(values + param_values(params))


def unpack_inputs(
    host: jax.Array, warm: jax.Array, plan_states: jax.Array, plan_controls: jax.Array
) -> tuple[Any, ...]:
    """The arguments of ``_CompiledStep._step`` from :func:`pack_inputs`' vector (its state
    as long as the plan's; another length is refused when the step is traced)."""
    n = plan_states.shape[1]
    if host.shape != (HOST_HEAD + n + _N_PARAMS,):
        raise ValueError(
            f"packed MPC inputs of shape {host.shape} for a plan of {n} states: expected "
            f"({HOST_HEAD + n + _N_PARAMS},)"
        )
    index = jnp.maximum(host[0].astype(jnp.int32), 0)  # dynamic_slice would wrap a negative one
    first = host[1] != 0.0
    return (
        index,
        first,
        host[HOST_HEAD : HOST_HEAD + n],
        params_from_vector(host[HOST_HEAD + n :]),
        warm,
        plan_states,
        plan_controls,
    )


@functools.lru_cache(maxsize=16)
def compiled_step(problem: WIPMProblem, ddp: DDPConfig, horizon: int) -> _CompiledStep:
    """The shared compiled MPC step of a problem, solver settings and horizon."""
    return _CompiledStep(problem, ddp, horizon)


class _NumbaStep:
    """The MPC step of ``controllers.optimizer.numba_ddp`` for a problem and solver settings:
    the same inputs and outputs as :class:`_CompiledStep` (any horizon; the warm start and the
    plan as NumPy arrays; inputs of other lengths refused). Its machine code serves every
    problem of the same structure (the problem's numbers are inputs); a copy or an unpickled
    one is the shared step of its problem and settings (:func:`numba_step`)."""

    def __init__(self, problem: WIPMProblem, ddp: DDPConfig) -> None:
        self.problem, self.ddp = problem, ddp
        self.settings, self.alphas = numba_ddp.settings_vector(ddp)
        self.constants = problem.constants()
        layout = params_from_vector(np.zeros(_N_PARAMS))  # lambda(q)'s leaves, as packed
        self.module = numba_ddp.generated_module(problem, layout)

    def __call__(
        self, host: np.ndarray, warm: np.ndarray, plan_states: np.ndarray, plan_controls: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return self.module.mpc_step(  # type: ignore[no-any-return]
            host, warm, plan_states, plan_controls, self.constants, self.settings, self.alphas
        )

    def __reduce__(self) -> tuple[Any, tuple[WIPMProblem, DDPConfig]]:
        return numba_step, (self.problem, self.ddp)


@functools.lru_cache(maxsize=16)
def numba_step(problem: WIPMProblem, ddp: DDPConfig) -> _NumbaStep:
    """The shared numba MPC step of a problem and solver settings."""
    return _NumbaStep(problem, ddp)


class ModelPredictiveController:
    """Receding-horizon DDP tracking a :class:`Plan` (see the module docstring).

    The plan's reference (its states and controls, then its continuation's; padded past that
    with its rest state and zero controls) is put on the device once
    (the JAX backend); each :meth:`step` is one call of the shared compiled step
    (:func:`compiled_step`, or :func:`numba_step`) with its host inputs packed in one vector
    (:func:`pack_inputs`) and one transfer of its packed result. ``solver`` is the JAX solver
    of the same problem and settings, whichever the backend (the reference).
    ``step`` is :meth:`solve` of :meth:`inputs`, and :meth:`solve` is :meth:`take` of
    :meth:`run`. The high level makes its inputs with :meth:`inputs_from` (the robot's
    ``RobotModel.wipm_inputs`` written into them); beside the control loop, :meth:`run` runs
    in the MPC's thread and :meth:`take` on the control thread, one solve after the other.
    """

    def __init__(self, plan: Plan, config: MPCConfig | None = None) -> None:
        self.config = config or MPCConfig()
        if abs(self.config.dt - plan.dt) > 1e-12:
            raise ValueError(f"MPC dt {self.config.dt} differs from the plan's {plan.dt}")
        self.plan = plan
        self.problem = mpc_problem(plan.planar, self.config, plan.a_max, plan.theta_max)
        ddp = DDPConfig(**{**self.config.ddp.__dict__, "max_iterations": self.config.iterations})
        self.horizon = self.config.steps
        self._ddp = ddp
        self.solver = ddp_solver_for(self.problem, ddp)
        self.compiled: _CompiledStep | _NumbaStep
        self.rejected = 0
        self.solves = 0
        H = self.horizon
        reference, m = len(plan.reference_states), plan.controls.shape[1]
        # the rest state at least a horizon on; the rows rounded up to a multiple of
        # PADDED_ROWS, so that the JAX step, traced per length, is traced a few times per plan
        # horizon, not once per continuation's length
        rows = -(-(reference + H + 1) // PADDED_ROWS) * PADDED_ROWS
        states = np.vstack([plan.reference_states, np.tile(plan.rest_state, (rows - reference, 1))])
        controls = np.vstack([plan.reference_controls, np.zeros((rows - reference, m))])
        warm = np.zeros((H, m))
        if self.config.backend == "numba":
            self.compiled = numba_step(self.problem, ddp)
            self._plan_states, self._plan_controls, self._warm = states, controls, warm
        else:
            self.compiled = compiled_step(self.problem, ddp, self.horizon)
            with jax_setup.float64():  # float64 on the device too
                self._plan_states = jax.device_put(states)
                self._plan_controls = jax.device_put(controls)
                self._warm = jax.device_put(warm)
        self._first = True  # the first step warm-starts from the plan's controls
        n = states.shape[1]
        self._sizes = ((H + 1) * n, H * m)
        self._shapes = ((H + 1, n), (H, m))
        # dynamic_slice clamps: past it, all rest state
        self._last_index = len(plan.reference_states)
        self._host_size = HOST_HEAD + n + _N_PARAMS

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["solver"] = None  # closures do not pickle: the shared solver, found again
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.solver = ddp_solver_for(self.problem, self._ddp)

    def step(self, index: int, state: np.ndarray, params: WIPMParams) -> MPCStep:
        """Solve at plan time index ``index`` from WIPM ``state`` with parameters ``params``."""
        return self.solve(self.inputs(index, state, params))

    def inputs(self, index: int, state: np.ndarray, params: WIPMParams) -> np.ndarray:
        """The next :meth:`solve`'s host inputs (checked, packed: :func:`pack_inputs`): the
        reference of :meth:`inputs_of` and :meth:`inputs_from` (the high level's path)."""
        state = np.asarray(state, dtype=np.float64)
        if state.shape != (self._shapes[0][1],):
            raise ValueError(
                f"MPC state must have shape ({self._shapes[0][1]},) (the plan's), got {state.shape}"
            )
        if not np.isfinite(state).all():
            raise ValueError(f"MPC state is not finite: {state}")
        index = min(max(int(index), 0), self._last_index)
        return pack_inputs(index, self._first, state, params)

    def inputs_of(self, index: int, wipm_inputs: np.ndarray) -> np.ndarray:
        """:meth:`inputs` from a vector of the WIPM state and ``lambda(q)``
        (``RobotModel.wipm_inputs``: the state, then :func:`param_values`' floats), without
        the :class:`WIPMParams`: the same host vector to the bit. The state is checked as by
        :meth:`inputs`; ``ValueError`` for a vector of another dtype or length."""
        n = self._shapes[0][1]
        if (
            type(wipm_inputs) is not np.ndarray
            or wipm_inputs.dtype != np.float64
            or wipm_inputs.shape != (n + _N_PARAMS,)
        ):
            raise ValueError(
                f"MPC inputs must be a float64 vector of shape ({n + _N_PARAMS},) (the state, "
                f"then lambda(q)), got {getattr(wipm_inputs, 'dtype', type(wipm_inputs))} of "
                f"shape {np.shape(wipm_inputs)}"
            )
        if not np.isfinite(wipm_inputs[:n]).all():
            raise ValueError(f"MPC state is not finite: {wipm_inputs[:n]}")
        host = np.empty(HOST_HEAD + n + _N_PARAMS)
        host[0] = min(max(int(index), 0), self._last_index)
        host[1] = self._first
        host[HOST_HEAD:] = wipm_inputs
        return host

    def inputs_from(self, index: int, robot: RobotModel) -> np.ndarray:
        """:meth:`inputs_of` of ``robot.wipm_inputs()`` (the high level's path), the robot's
        vector written in place in the host vector: the same host vector to the bit. The state
        is not checked again: an updated ``RobotModel`` refuses a state that is not finite.
        ``ValueError`` for a robot whose WIPM is not the plan's (planar or 3-D)."""
        host = np.empty(self._host_size)
        robot.wipm_inputs(host[HOST_HEAD:])
        host[0] = min(max(int(index), 0), self._last_index)
        host[1] = self._first
        return host

    def solve(self, host: np.ndarray) -> MPCStep:
        """One MPC step from :meth:`inputs`' vector (made after the previous solve):
        :meth:`take` of :meth:`run`."""
        return self.take(self.run(host))

    def run(self, host: np.ndarray) -> tuple[Any, Any]:
        """The compiled step on :meth:`inputs`' vector from the current warm start: its packed
        result and the next warm start, as the backend returns them. Changes nothing: the
        solve beside the control loop runs this in its thread, and the control thread hands
        the result to :meth:`take` (the Python of a step stays off the MPC's thread)."""
        return self.compiled(host, self._warm, self._plan_states, self._plan_controls)  # type: ignore[no-any-return]

    def take(self, outputs: tuple[Any, Any]) -> MPCStep:
        """The :class:`MPCStep` of :meth:`run`'s ``outputs``, which become the current warm
        start (each ``run``'s outputs taken once, in order)."""
        packed, self._warm = outputs
        self._first = False
        self.solves += 1
        out = np.asarray(packed)
        nx, nu = self._sizes
        X = out[:nx].reshape(self._shapes[0])
        U = out[nx : nx + nu].reshape(self._shapes[1])
        accepted = bool(out[-1])
        if not accepted:
            self.rejected += 1
        return MPCStep(
            control=U[0].copy(),
            predicted_states=X,
            predicted_controls=U,
            cost=float(out[-3]),
            accepted=accepted,
        )
