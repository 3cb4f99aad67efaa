"""The WIPM as an optimal-control problem for the DDP (paper section "Receding Horizon
Control"): discretised dynamics with the control rate as input, tracking costs, and the
penalties that keep a plan one a robot carrying a cup can follow.

The state the DDP sees is the WIPM state augmented with the current control,
``z = [s, u]``, and its input is the control's rate ``w = du/dt`` (the authors' later code, 46
``mpc_params.cfg``, penalised the control change this way):

    s_{k+1} = s_k + dt f(s_k, u_k)          (explicit Euler, paper eq. after ``WIPdyn``)
    u_{k+1} = u_k + dt w_k

Planar: ``s = [theta, thetad, x, xd]``, ``u = thdd``. 3-D: ``s = [x, psi, theta, xd, psid,
thetad, X0, Y0]``, ``u = [thdd, tau_0]``. The running cost is ``dt`` times

    (s - s_ref)^T Q (s - s_ref) + u^T R u + w^T R_rate w
      + w_acc relu(a - a_lim)^2 + w_theta relu(|theta| - theta_lim)^2

with ``a`` the horizontal acceleration of the axle (planar ``|xdd|``, 3-D
``sqrt(xdd^2 + (xd psid)^2)``) and the limits a margin inside ``a_max`` and ``theta_max``; the
terminal cost is ``(s - s_ref)^T Q_f (s - s_ref)``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from controllers.optimizer.ddp import DDPConfig, DDPSolver, RunningDerivatives, make_ddp_solver
from controllers.simplified.wipm import WIPMParams, planar_dynamics, spatial_dynamics
from wip_gym.robot_model import RobotModel

Array = jax.Array

PLANAR_STATE = ("theta", "thetad", "x", "xd")
SPATIAL_STATE = ("x", "psi", "theta", "xd", "psid", "thetad", "X0", "Y0")


@dataclass(frozen=True)
class Weights:
    """Diagonal weights of one problem (state order of the model; see the module docstring).

    Attributes:
        q: running state weights. r: control weights. r_rate: control-rate weights.
        q_terminal: terminal state weights.
        a_max, theta_max: the bounds the plan must respect (m/s^2, rad).
        margin: the penalties start at ``margin`` times the bound.
        w_acceleration, w_theta: penalty weights.
    """

    q: tuple[float, ...]
    r: tuple[float, ...]
    r_rate: tuple[float, ...]
    q_terminal: tuple[float, ...]
    a_max: float
    theta_max: float
    margin: float = 0.85
    w_acceleration: float = 1e4
    w_theta: float = 1e4


def _weight_vector(values: tuple[float, ...] | tuple[Array, ...]) -> np.ndarray | Array:
    """Diagonal weights as a vector: NumPy constants where they are numbers (the JAX solver's
    case), a JAX array where they are traced (:meth:`WIPMProblem.with_constants`)."""
    if all(isinstance(v, int | float | np.number) for v in values):
        return np.asarray(values, dtype=float)
    return jnp.stack([jnp.asarray(v, dtype=float) for v in values])


def _concatenate(a: np.ndarray | Array, b: np.ndarray | Array) -> np.ndarray | Array:
    both = isinstance(a, np.ndarray) and isinstance(b, np.ndarray)
    return np.concatenate([a, b]) if both else jnp.concatenate([jnp.asarray(a), jnp.asarray(b)])


def _diagonal(v: np.ndarray | Array) -> np.ndarray | Array:
    """``diag(v)``; traced, as a product with the identity (no scatter: its zeros are literal,
    and ``controllers.optimizer.scalar_codegen`` folds them)."""
    return np.diag(v) if isinstance(v, np.ndarray) else jnp.eye(v.shape[0]) * v


def _along_inputs(linear: Callable[[Array], Array], inputs: tuple[int, ...], size: int) -> Array:
    """A linear map of ``R^size`` (a JVP or an HVP from ``jax.linearize``) applied to the basis
    vectors of ``inputs`` only, its results the rows of a ``(size, out)`` array whose other rows
    are exact zeros (where the map is known to vanish). The rows are stacked, not scattered: a
    scatter inside the DDP's loops keeps XLA from compiling each loop into one kernel (3 to 5
    times slower, measured)."""
    rows = jax.vmap(linear)(jnp.asarray(np.eye(size)[list(inputs)]))
    zero = jnp.zeros(rows.shape[1], rows.dtype)
    return jnp.stack([rows[inputs.index(i)] if i in inputs else zero for i in range(size)])


@dataclass(frozen=True)
class WIPMProblem:
    """Discrete dynamics and costs for ``controllers.optimizer.ddp`` (pure JAX functions)."""

    planar: bool
    dt: float
    weights: Weights
    rate_input: bool = True  # z = [s, u] with input du/dt; False: state s, input u

    def constants(self) -> np.ndarray:
        """The problem's numbers as one vector, in :meth:`with_constants`' layout:
        ``[dt, q, r, r_rate, q_terminal, a_max, theta_max, margin, w_acceleration, w_theta]``."""
        w = self.weights
        return np.array(
            [self.dt, *w.q, *w.r, *w.r_rate, *w.q_terminal]
            + [w.a_max, w.theta_max, w.margin, w.w_acceleration, w.w_theta],
            dtype=float,
        )

    def with_constants(self, vector: Array | np.ndarray) -> WIPMProblem:
        """This problem with :meth:`constants` read from ``vector`` (traced, in
        ``controllers.optimizer.numba_ddp``: the generated code takes the weights, bounds and
        ``dt`` as inputs, so one compilation serves every problem of this structure).
        ``ValueError`` for a vector of another length."""
        w = self.weights
        sizes = (1, len(w.q), len(w.r), len(w.r_rate), len(w.q_terminal), 5)
        if vector.shape != (sum(sizes),):
            raise ValueError(f"problem constants of shape {vector.shape}: expected ({sum(sizes)},)")
        parts, at = [], 0
        for size in sizes:
            parts.append(tuple(vector[at + i] for i in range(size)))
            at += size
        (dt,), q, r, r_rate, q_terminal, (a_max, theta_max, margin, w_acc, w_theta) = parts
        weights = Weights(
            q=q,
            r=r,
            r_rate=r_rate,
            q_terminal=q_terminal,
            a_max=a_max,
            theta_max=theta_max,
            margin=margin,
            w_acceleration=w_acc,
            w_theta=w_theta,
        )
        return WIPMProblem(self.planar, dt, weights, self.rate_input)  # type: ignore[arg-type]

    @property
    def n_state(self) -> int:
        return 4 if self.planar else 8

    @property
    def n_control(self) -> int:
        return 1 if self.planar else 2

    @property
    def theta_index(self) -> int:
        return 0 if self.planar else 2

    @property
    def penalty_inputs(self) -> tuple[int, ...]:
        """The entries of ``[s, u]`` that :meth:`penalty` depends on (its gradient is exactly 0
        in the others): ``theta`` and the inputs of the axle's acceleration. Planar ``xdd``
        depends on ``theta, thetad, thdd`` (:func:`planar_dynamics`); 3-D ``xdd`` on ``theta``,
        ``nu = [xd, psid, thetad]`` and ``u = [thdd, tau_0]`` (:func:`spatial_terms`, which
        does not read ``x``, ``psi``, ``X0``, ``Y0``), the centripetal part on ``xd, psid``."""
        return (0, 1, 4) if self.planar else (2, 3, 4, 5, 8, 9)

    @property
    def dynamics_inputs(self) -> tuple[int, ...]:
        """The entries of ``[s, u]`` that :meth:`continuous` reads (its Jacobian is exactly 0
        in the others): planar ``theta, thetad, xd, thdd`` (not ``x``); 3-D ``psi`` (the
        axle's world velocity), ``theta``, ``nu = [xd, psid, thetad]`` and ``u`` (not ``x``,
        ``X0``, ``Y0``)."""
        return (0, 1, 3, 4) if self.planar else (1, 2, 3, 4, 5, 8, 9)

    def continuous(self, s: Array, u: Array, params: WIPMParams) -> Array:
        if self.planar:
            return planar_dynamics(s, u[0], params)
        return spatial_dynamics(s, u, params)

    def horizontal_acceleration(self, s: Array, u: Array, params: WIPMParams) -> Array:
        """Axle acceleration magnitude: planar ``|xdd|``; 3-D with the turn's centripetal part."""
        sdot = self.continuous(s, u, params)
        if self.planar:
            return jnp.sqrt(sdot[3] ** 2 + 1e-12)
        return jnp.sqrt(sdot[3] ** 2 + (s[3] * s[4]) ** 2 + 1e-12)

    def dynamics(self) -> Callable[[Array, Array, WIPMParams], Array]:
        n, dt = self.n_state, self.dt
        if not self.rate_input:

            def plain(s: Array, u: Array, params: WIPMParams) -> Array:
                return s + dt * self.continuous(s, u, params)

            return plain

        def step(z: Array, w: Array, params: WIPMParams) -> Array:
            s, u = z[:n], z[n:]
            return jnp.concatenate([s + dt * self.continuous(s, u, params), u + dt * w])

        return step

    def dynamics_derivatives(self) -> Callable[[Array, Array, WIPMParams], tuple[Array, Array]]:
        """``(f_x, f_u)`` of :meth:`dynamics`, exact: forward-mode autodiff of
        :meth:`continuous` along only the directions of :attr:`dynamics_inputs` (7 of 10 3-D,
        4 of 5 planar; ``jax.jacfwd`` of the discrete step pushes 10 and 5, or 12 and 7 with
        the rate input, through the whole model), the Euler step's identity and ``dt`` blocks
        assembled around them. Equal to ``jax.jacfwd(dynamics())`` to round-off (1e-15 of its
        scale, tests/test_ddp_speed.py; the recorded plans and MPC steps to 1e-9)."""
        n, m, dt = self.n_state, self.n_control, self.dt
        inputs = self.dynamics_inputs
        identity_s, identity_u = np.eye(n), np.eye(m)

        def continuous_jacobian(s: Array, u: Array, params: WIPMParams) -> Array:
            """``d continuous / d[s, u]`` (``n`` x ``n + m``), zero outside ``inputs``."""

            def value(v: Array) -> Array:
                return self.continuous(v[:n], v[n:], params)

            _, jvp = jax.linearize(value, jnp.concatenate([s, u]))
            return _along_inputs(jvp, inputs, n + m).T  # rows: inputs; columns of the Jacobian

        def derivatives(z: Array, w: Array, params: WIPMParams) -> tuple[Array, Array]:
            s, u = self._split(z, w)
            jacobian = continuous_jacobian(s, u, params)
            f_s = identity_s + dt * jacobian[:, :n]  # s + dt f(s, u)
            f_u = dt * jacobian[:, n:]
            if not self.rate_input:
                return f_s, f_u
            # z = [s, u]: u_{k+1} = u_k + dt w
            f_z = jnp.block([[f_s, f_u], [jnp.zeros((m, n)), identity_u]])
            f_w = jnp.concatenate([jnp.zeros((n, m)), dt * identity_u])
            return f_z, f_w

        return derivatives

    def penalty(self, s: Array, u: Array, params: WIPMParams) -> Array:
        """``w_acc relu(a - a_lim)^2 + w_theta relu(|theta| - theta_lim)^2`` (module docstring),
        and whether it is active (either ``relu`` argument positive: outside, it and its first
        and second derivatives are exactly zero)."""
        wts = self.weights
        a = self.horizontal_acceleration(s, u, params)
        over_a = a - wts.margin * wts.a_max
        over_theta = jnp.abs(s[self.theta_index]) - wts.margin * wts.theta_max
        value = wts.w_acceleration * jax.nn.relu(over_a) ** 2
        value += wts.w_theta * jax.nn.relu(over_theta) ** 2
        return value, (over_a > 0.0) | (over_theta > 0.0)

    def _split(self, z: Array, w: Array) -> tuple[Array, Array]:
        """The WIPM state and control ``(s, u)`` of the DDP's state and input."""
        n = self.n_state
        return (z[:n], z[n:]) if self.rate_input else (z, w)

    def costs(
        self,
    ) -> tuple[Callable[[Array, Array, Array], Array], Callable[[Array, Array], Array]]:
        """``running(z, w, ref)`` and ``terminal(z, ref)`` with ``ref = (s_ref, params)``: the
        reference state and the WIPM parameters the acceleration penalty needs."""
        wts, n, dt = self.weights, self.n_state, self.dt
        q, r = _weight_vector(wts.q), _weight_vector(wts.r)
        r_rate, q_terminal = _weight_vector(wts.r_rate), _weight_vector(wts.q_terminal)

        def running(z: Array, w: Array, ref: tuple[Array, WIPMParams]) -> Array:
            s_ref, params = ref
            s, u = self._split(z, w)
            e = s - s_ref
            penalty, _ = self.penalty(s, u, params)
            rate = jnp.sum(r_rate * w * w) if self.rate_input else 0.0
            return dt * (jnp.sum(q * e * e) + jnp.sum(r * u * u) + rate + penalty)

        def terminal(z: Array, ref: tuple[Array, WIPMParams]) -> Array:
            s_ref, _ = ref
            e = z[:n] - s_ref
            return jnp.sum(q_terminal * e * e)

        return running, terminal

    def running_derivatives(self) -> RunningDerivatives:
        """``(l_x, l_u, l_xx, l_ux, l_uu)`` of ``costs()``'s running cost at one step, exact:
        the quadratic terms in closed form (``2 dt Q e``, ``2 dt diag(Q)``, ...), the penalty's by
        autodiff only where it is active (``lax.cond``; elsewhere they are exactly zero). The
        autodiff Hessian of the whole cost cost ~5 us per step for the 3-D model, most of it
        spent on the (usually inactive) penalty. Tested against ``jax.hessian`` of the cost.

        The penalty's Hessian is forward-over-reverse autodiff (what ``jax.hessian`` does) along
        only the directions of :attr:`penalty_inputs` (3 of 5 planar, 6 of 10 3-D): its other
        rows and columns are exactly zero. Measured (3-D MPC problem, 2 shared cores): 2.9 ->
        1.0 us per active step; the same rows as ``jax.hessian``'s to round-off. The penalty is
        active at ~40 % of the MPC's steps along a plan's acceleration phase."""
        wts, n, m, dt = self.weights, self.n_state, self.n_control, self.dt
        q, r, r_rate = _weight_vector(wts.q), _weight_vector(wts.r), _weight_vector(wts.r_rate)
        if self.rate_input:
            x_diag, u_diag = _concatenate(q, r), r_rate  # z = [s, u], input w
        else:
            x_diag, u_diag = q, r
        lxx = _diagonal(2.0 * dt * x_diag)
        luu = _diagonal(2.0 * dt * u_diag)
        nx, nu = x_diag.shape[0], u_diag.shape[0]
        zero_penalty = (np.zeros(n + m), np.zeros((n + m, n + m)))

        inputs = self.penalty_inputs

        def penalty_derivatives(su: Array, params: WIPMParams) -> tuple[Array, Array]:
            def value(v: Array) -> Array:
                return dt * self.penalty(v[:n], v[n:], params)[0]

            gradient, hvp = jax.linearize(jax.grad(value), su)
            return gradient, _along_inputs(hvp, inputs, n + m)  # the Hessian's rows `inputs`

        def derivatives(z: Array, w: Array, ref: tuple[Array, WIPMParams]) -> tuple[Array, ...]:
            s_ref, params = ref
            s, u = self._split(z, w)
            su = jnp.concatenate([s, u])
            _, active = self.penalty(s, u, params)
            g, h = jax.lax.cond(active, penalty_derivatives, lambda *_: zero_penalty, su, params)
            if self.rate_input:
                e = jnp.concatenate([s - s_ref, u])
                lx = 2.0 * dt * (jnp.asarray(x_diag) * e) + g
                lu = 2.0 * dt * (jnp.asarray(u_diag) * w)
                return lx, lu, lxx + h, jnp.zeros((nu, nx)), luu
            # state s, input u: the penalty's Hessian splits into the (s, u) blocks
            lx = 2.0 * dt * (jnp.asarray(x_diag) * (s - s_ref)) + g[:n]
            lu = 2.0 * dt * (jnp.asarray(u_diag) * u) + g[n:]
            return lx, lu, lxx + h[:n, :n], h[n:, :n], luu + h[n:, n:]

        return derivatives


@functools.lru_cache(maxsize=16)
def ddp_solver_for(problem: WIPMProblem, ddp: DDPConfig) -> DDPSolver:
    """One compiled DDP solver per problem (weights, bounds, dt) and solver settings, shared by
    every plan and MPC that poses the same problem."""
    running, terminal = problem.costs()
    return make_ddp_solver(
        problem.dynamics(),
        running,
        terminal,
        ddp,
        running_derivatives=problem.running_derivatives(),
        dynamics_derivatives=problem.dynamics_derivatives(),
    )


def refs_for(states: np.ndarray, params: WIPMParams) -> tuple[Array, WIPMParams]:
    """The per-step references ``(s_ref[k], params)`` with the parameters broadcast along the
    horizon (the DDP wants a leading axis of ``N + 1`` on every leaf)."""
    count = states.shape[0]
    broadcast = jax.tree_util.tree_map(
        lambda leaf: np.broadcast_to(np.asarray(leaf), (count, *np.shape(leaf))), params
    )
    return np.asarray(states, dtype=float), broadcast


def wipm_state(robot: RobotModel) -> np.ndarray:
    """The WIPM state of the full robot (its ``lambda(q)`` part): planar
    ``[theta, thetad, x, xd]``, 3-D ``[x, psi, theta, xd, psid, thetad, X0, Y0]``
    (``RobotModel.wipm_state``: from the compiled update's scalars, one array of floats; every
    control step records it)."""
    return robot.wipm_state()
