"""Train PPO on a wip-gym env, on JAX and optax (docs/learning.md §8).

    python examples/train_ppo.py --env wip_gym/WIP-v0 --steps 3000000 --out out/ppo_wip

A small PPO in the manner of PureJaxRL (clipped surrogate, GAE, advantage normalisation per
minibatch, separate tanh actor and critic MLPs with orthogonal initialisation, a
state-independent log standard deviation, Adam with a global gradient-norm clip, a learning
rate decaying linearly to zero), but with the rollout in Python: the MuJoCo env is not
JAX-native, so a Gymnasium ``SyncVectorEnv`` of ``num_envs`` wrapped envs steps in Python and
only the minibatch update is jitted (one small function: no loop is unrolled in it, so it
compiles in about a second; next_facts §3.1's trap is a 1024-step GAE loop unrolled in a jit).

Each env is ``wip_gym.wrappers.wrap_for_learning(gym.make(env, frame_skip=...))``: the dense
reward, a goal drawn uniformly in ``[goal_low, goal_high]`` at every reset, the normalised
observation and actions in [-1, 1] (beyond them clipped and counted). The vector env resets
ended episodes on the same step (``AutoresetMode.SAME_STEP``); a truncated episode's last reward
is bootstrapped with the value of its final observation (the time limit is not a state).
Observations are standardised by running statistics and rewards scaled by the running standard
deviation of the discounted return (PureJaxRL's ``NormalizeVecObservation``/``Reward``).

Every ``--eval-every`` env steps the policy is saved (``controllers.learned`` checkpoint) and run
as the ``ppo`` controller through ``benchmarks.rollout`` (as ``wip-bench compare`` runs it) on
``--eval-seeds`` seeds of the env's default task, deterministically (the mean action); the
curve (success rate, falls, final goal distance against env steps and wall time) goes to
``curve.json`` and, with ``--plot``, ``curve.png``.

Outputs in ``--out``: ``checkpoint.npz`` (the final policy), ``checkpoint_<steps>.npz`` (the
policy of each evaluation), ``curve.json``, ``log.jsonl`` (one
line per update: losses, KL, clip fraction, entropy, episode returns), ``probe.npz`` (flat
observations and the jitted network's mean actions on them, to check a reloaded checkpoint).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

# one thread per XLA computation: the networks are small and the machine is shared
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import gymnasium as gym  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run from a checkout: python examples/train_ppo.py
    sys.path.insert(0, str(ROOT))

import wip_gym  # noqa: E402, F401
from controllers.learned import LearnedConfig, save_checkpoint  # noqa: E402
from wip_gym.wrappers import (  # noqa: E402
    DenseRewardConfig,
    ObservationNormalizer,
    wrap_for_learning,
)

Params = dict[str, Any]


# --------------------------------------------------------------------------------- networks
def orthogonal(rng: np.random.Generator, shape: tuple[int, int], gain: float) -> np.ndarray:
    """An orthogonal matrix times ``gain`` (the QR of a Gaussian matrix, signs fixed), drawn in
    NumPy: no eager JAX operation to compile."""
    rows, cols = shape
    a = rng.standard_normal((max(rows, cols), min(rows, cols)))
    q, r = np.linalg.qr(a)
    q *= np.sign(np.diag(r))
    return (gain * (q if rows >= cols else q.T)).astype(np.float32)


def init_mlp(rng: np.random.Generator, sizes: list[int], last_gain: float) -> list[dict[str, Any]]:
    """Layers ``sizes[i] -> sizes[i + 1]``: orthogonal weights (gain sqrt(2) hidden,
    ``last_gain`` last), zero biases."""
    layers = []
    for i in range(len(sizes) - 1):
        gain = last_gain if i == len(sizes) - 2 else math.sqrt(2.0)
        w = orthogonal(rng, (sizes[i], sizes[i + 1]), gain)
        layers.append({"w": jnp.asarray(w), "b": jnp.asarray(np.zeros(sizes[i + 1], np.float32))})
    return layers


def mlp(layers: list[dict[str, jax.Array]], x: jax.Array) -> jax.Array:
    for layer in layers[:-1]:
        x = jnp.tanh(x @ layer["w"] + layer["b"])
    return x @ layers[-1]["w"] + layers[-1]["b"]


def init_params(
    rng: np.random.Generator, obs_size: int, act_size: int, hidden: list[int], log_std: float
) -> Params:
    return {
        "actor": init_mlp(rng, [obs_size, *hidden, act_size], 0.01),
        "critic": init_mlp(rng, [obs_size, *hidden, 1], 1.0),
        "log_std": jnp.asarray(np.full(act_size, log_std, np.float32)),
    }


@jax.jit
def forward(params: Params, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The policy's mean and the value of standardised observations."""
    return mlp(params["actor"], obs), mlp(params["critic"], obs)[..., 0]


def gaussian_log_prob(action: Any, mean: Any, log_std: Any, xp: Any = jnp) -> Any:
    return xp.sum(
        -0.5 * ((action - mean) / xp.exp(log_std)) ** 2 - log_std - 0.5 * math.log(2 * math.pi),
        axis=-1,
    )


def make_update(
    optimizer: optax.GradientTransformation, clip: float, vf_coef: float, ent_coef: float
) -> Callable[..., Any]:
    """One jitted minibatch step of PPO's clipped objective."""

    def loss(params: Params, batch: dict[str, jax.Array]) -> tuple[jax.Array, dict[str, jax.Array]]:
        mean, value = forward(params, batch["obs"])
        log_std = params["log_std"]
        log_prob = gaussian_log_prob(batch["action"], mean, log_std)
        ratio = jnp.exp(log_prob - batch["log_prob"])
        adv = batch["advantage"]
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        policy_loss = -jnp.minimum(ratio * adv, jnp.clip(ratio, 1 - clip, 1 + clip) * adv).mean()
        value_loss = 0.5 * ((value - batch["target"]) ** 2).mean()
        entropy = jnp.sum(log_std + 0.5 * math.log(2 * math.pi * math.e))
        total = policy_loss + vf_coef * value_loss - ent_coef * entropy
        stats = {
            "policy_loss": policy_loss,
            "value_loss": value_loss,
            "entropy": entropy,
            "approx_kl": ((ratio - 1) - jnp.log(ratio)).mean(),
            "clip_fraction": (jnp.abs(ratio - 1) > clip).mean(),
        }
        return total, stats

    @jax.jit
    def update(
        params: Params, opt_state: Any, batch: dict[str, jax.Array]
    ) -> tuple[Params, Any, dict[str, jax.Array]]:
        grads, stats = jax.grad(loss, has_aux=True)(params, batch)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, stats

    return update


# ------------------------------------------------------------------------ running statistics
class RunningMeanStd:
    """Mean and variance of a stream of batches (Chan et al.'s parallel update)."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.mean = np.zeros(shape)
        self.var = np.ones(shape)
        self.count = 1e-4

    def update(self, batch: np.ndarray) -> None:
        mean, var, n = batch.mean(axis=0), batch.var(axis=0), batch.shape[0]
        delta, total = mean - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        m2 = self.var * self.count + var * n + delta**2 * self.count * n / total
        self.var, self.count = m2 / total, total

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(self.var + 1e-8)


# ------------------------------------------------------------------------------ the envs
class WithoutInfo(gym.Wrapper[Any, Any, Any, Any]):
    """Drop the step's info: the trainer reads none of it, and the vector env's batching of a
    wip-gym info (about 20 keys) costs more than a step's normalisation."""

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        return self.env.reset(**kwargs)[0], {}

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, _ = self.env.step(action)
        return observation, reward, terminated, truncated, {}


def reward_config(settings: list[str]) -> DenseRewardConfig:
    """``DenseRewardConfig`` with ``NAME=VALUE`` settings applied (``--reward``)."""
    fields = {f.name for f in dataclasses.fields(DenseRewardConfig)}
    values = {}
    for setting in settings:
        name, _, value = setting.partition("=")
        if name not in fields or not value:
            raise ValueError(f"--reward {setting!r}: expected NAME=VALUE, NAME in {sorted(fields)}")
        values[name] = float(value)
    return DenseRewardConfig(**values)


def make_env(args: argparse.Namespace) -> gym.Env[Any, Any]:
    return wrap_for_learning(
        gym.make(args.env, frame_skip=args.frame_skip),
        goal_low=args.goal_low,
        goal_high=args.goal_high,
        reward=reward_config(args.reward),
    )


def make_vector_env(args: argparse.Namespace) -> gym.vector.SyncVectorEnv:
    return gym.vector.SyncVectorEnv(
        [lambda: WithoutInfo(make_env(args)) for _ in range(args.num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )


# ------------------------------------------------------------------------------ evaluation
def evaluate(args: argparse.Namespace, checkpoint: Path) -> dict[str, Any]:
    """The checkpoint as the ``ppo`` controller on ``args.eval_seeds`` seeds of the env's
    default task (``benchmarks.rollout``, as ``wip-bench compare`` runs it)."""
    from benchmarks.rollout import rollout

    rows = [
        rollout(
            args.env,
            {"frame_skip": args.frame_skip},
            "ppo",
            LearnedConfig(checkpoint=str(checkpoint)),
            seed,
            args.eval_duration,
        ).metrics
        for seed in range(args.eval_seeds)
    ]
    result = {
        "success_rate": float(np.mean([r["success"] for r in rows])),
        "fell_rate": float(np.mean([r["fell"] for r in rows])),
        "final_goal_error_m": [float(r["final_goal_error_m"]) for r in rows],
        "sim_time_s": [float(r["sim_time_s"]) for r in rows],
    }
    if rows[0]["carried"] is not None:  # a tray task
        result["carried_rate"] = float(np.mean([r["carried"] for r in rows]))
        result["max_cup_friction_use"] = [float(r["max_cup_friction_use"]) for r in rows]
        result["max_tray_tilt_deg"] = [float(r["max_tray_tilt_deg"]) for r in rows]
    return result


def write_checkpoint(
    path: Path,
    params: Params,
    obs_stats: RunningMeanStd,
    normalizer: ObservationNormalizer,
    args: argparse.Namespace,
    control_dt: float,
    env_steps: int,
    wall_s: float,
) -> None:
    actor = params["actor"]
    save_checkpoint(
        path,
        [np.asarray(layer["w"]) for layer in actor],
        [np.asarray(layer["b"]) for layer in actor],
        obs_stats.mean,
        obs_stats.std,
        {
            "env_id": args.env,
            "frame_skip": args.frame_skip,
            "control_dt": control_dt,
            "wheel_angles": normalizer.wheel_angles,
            "tray": normalizer.tray,
            "observation_names": normalizer.names,
            "training": {
                **{k: v for k, v in vars(args).items() if k != "out"},
                "reward_config": dataclasses.asdict(reward_config(args.reward)),
                "env_steps": env_steps,
                "wall_s": wall_s,
            },
        },
    )


# ------------------------------------------------------------------------------ training
def train(args: argparse.Namespace) -> dict[str, Any]:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    envs = make_vector_env(args)
    probe_env = make_env(args)
    normalizer: ObservationNormalizer = probe_env.get_wrapper_attr("normalizer")
    control_dt = float(probe_env.unwrapped.dt)
    obs_size = envs.single_observation_space.shape[0]
    act_size = envs.single_action_space.shape[0]
    n, T = args.num_envs, args.rollout
    batch_size = n * T
    if batch_size % args.minibatches:
        raise ValueError(f"num_envs x rollout ({batch_size}) must divide into --minibatches")
    updates = max(1, args.steps // batch_size)
    schedule = optax.linear_schedule(args.lr, 0.0, updates * args.epochs * args.minibatches)
    optimizer = optax.chain(
        optax.clip_by_global_norm(args.max_grad_norm), optax.adam(schedule, eps=1e-5)
    )
    rng = np.random.default_rng(args.seed)
    params = init_params(rng, obs_size, act_size, args.hidden, args.log_std_init)
    opt_state = optimizer.init(params)
    update = make_update(optimizer, args.clip, args.vf_coef, args.ent_coef)
    obs_stats = RunningMeanStd((obs_size,))
    return_stats = RunningMeanStd(())
    discounted = np.zeros(n)

    buf_obs = np.zeros((T, n, obs_size), np.float32)
    buf_act = np.zeros((T, n, act_size), np.float32)
    buf_logp = np.zeros((T, n), np.float32)
    buf_val = np.zeros((T, n), np.float32)
    buf_rew = np.zeros((T, n), np.float32)
    buf_done = np.zeros((T, n), np.float32)

    obs, _ = envs.reset(seed=args.seed)
    episode_return, episode_length = np.zeros(n), np.zeros(n, int)
    finished: list[tuple[float, int]] = []
    curve: list[dict[str, Any]] = []
    log = open(out / "log.jsonl", "w")  # noqa: SIM115 - closed at the end
    start = time.perf_counter()
    eval_time = 0.0
    env_steps = 0
    next_eval = args.eval_every if args.eval_every > 0 else math.inf

    def standardise(o: np.ndarray) -> np.ndarray:
        return ((o - obs_stats.mean) / obs_stats.std).astype(np.float32)

    def run_eval() -> None:
        nonlocal eval_time
        tick = time.perf_counter()
        path = out / "checkpoint.npz"
        wall = tick - start - eval_time
        write_checkpoint(path, params, obs_stats, normalizer, args, control_dt, env_steps, wall)
        result = evaluate(args, path)
        shutil.copyfile(path, out / f"checkpoint_{env_steps}.npz")  # the curve's policies
        eval_time += time.perf_counter() - tick
        point = {"env_steps": env_steps, "train_wall_s": wall, "wall_s": tick - start, **result}
        curve.append(point)
        (out / "curve.json").write_text(json.dumps(curve, indent=1))
        carried = f", carried {result['carried_rate']:.1f}" if "carried_rate" in result else ""
        print(
            f"eval at {env_steps} steps ({wall:.0f} s training): success "
            f"{result['success_rate']:.1f}, fell {result['fell_rate']:.1f}{carried}, final "
            f"distance median {np.median(result['final_goal_error_m']):.3f} m",
            flush=True,
        )

    for k in range(updates):
        for t in range(T):
            obs_stats.update(obs)
            x = standardise(obs)
            mean, value = (np.asarray(a) for a in forward(params, x))
            std = np.exp(np.asarray(params["log_std"]))
            action = (mean + std * rng.standard_normal(mean.shape)).astype(np.float32)
            log_prob = gaussian_log_prob(action, mean, np.asarray(params["log_std"]), np)
            obs, reward, terminated, truncated, info = envs.step(action)
            episode_return += reward
            episode_length += 1
            discounted = discounted * args.gamma + reward
            return_stats.update(discounted)
            scaled = reward / return_stats.std
            ended = terminated | truncated
            cut = truncated & ~terminated
            if cut.any():  # bootstrap a truncated episode from its final observation
                final = obs.copy()  # the batch's shape: the jitted network is not compiled again
                for i in np.flatnonzero(cut):
                    final[i] = info["final_obs"][i]
                final_value = np.asarray(forward(params, standardise(final))[1])
                scaled[cut] += args.gamma * final_value[cut]
            buf_obs[t], buf_act[t], buf_logp[t], buf_val[t] = x, action, log_prob, value
            buf_rew[t], buf_done[t] = scaled, ended
            for i in np.flatnonzero(ended):
                finished.append((float(episode_return[i]), int(episode_length[i])))
                episode_return[i], episode_length[i] = 0.0, 0
            discounted[ended] = 0.0
        env_steps += batch_size
        last_value = np.asarray(forward(params, standardise(obs))[1])
        # GAE (numpy, reversed over the rollout)
        advantages = np.zeros((T, n), np.float32)
        gae = np.zeros(n, np.float32)
        for t in reversed(range(T)):
            next_value = last_value if t == T - 1 else buf_val[t + 1]
            nonterminal = 1.0 - buf_done[t]
            delta = buf_rew[t] + args.gamma * next_value * nonterminal - buf_val[t]
            gae = delta + args.gamma * args.gae_lambda * nonterminal * gae
            advantages[t] = gae
        targets = advantages + buf_val
        flat = {
            "obs": buf_obs.reshape(batch_size, obs_size),
            "action": buf_act.reshape(batch_size, act_size),
            "log_prob": buf_logp.reshape(batch_size),
            "advantage": advantages.reshape(batch_size),
            "target": targets.reshape(batch_size),
        }
        stats: dict[str, list[float]] = {}
        size = batch_size // args.minibatches
        for _ in range(args.epochs):
            order = rng.permutation(batch_size)
            for j in range(args.minibatches):
                idx = order[j * size : (j + 1) * size]
                batch = {name: jnp.asarray(v[idx]) for name, v in flat.items()}
                params, opt_state, s = update(params, opt_state, batch)
                for name, value in s.items():
                    stats.setdefault(name, []).append(float(value))
        line = {
            "update": k + 1,
            "env_steps": env_steps,
            "wall_s": time.perf_counter() - start,
            **{name: float(np.mean(v)) for name, v in stats.items()},
            "std": float(np.exp(np.asarray(params["log_std"])).mean()),
            "episodes": len(finished),
            "return_mean": float(np.mean([f[0] for f in finished])) if finished else None,
            "length_mean": float(np.mean([f[1] for f in finished])) if finished else None,
        }
        finished.clear()
        if not all(math.isfinite(line[name]) for name in stats):
            raise FloatingPointError(f"non-finite loss at update {k + 1}: {line}")
        log.write(json.dumps(line) + "\n")
        log.flush()
        if (k + 1) % args.print_every == 0:
            print(
                f"update {k + 1}/{updates}: {env_steps} steps, {line['wall_s']:.0f} s, return "
                f"{line['return_mean']}, length {line['length_mean']}, kl "
                f"{line['approx_kl']:.4f}, std {line['std']:.3f}",
                flush=True,
            )
        if env_steps >= next_eval:
            run_eval()
            next_eval += args.eval_every
    log.close()
    wall = time.perf_counter() - start - eval_time
    write_checkpoint(
        out / "checkpoint.npz", params, obs_stats, normalizer, args, control_dt, env_steps, wall
    )
    if args.eval_every > 0 and (not curve or curve[-1]["env_steps"] != env_steps):
        run_eval()
    # the jitted network's mean actions on observations of a few resets: a reloaded
    # checkpoint (NumPy) must give them
    probes = np.stack([probe_env.reset(seed=s)[0] for s in range(n)])
    probe_mean = np.asarray(forward(params, standardise(probes))[0])
    np.savez(out / "probe.npz", observations=probes, mean_actions=probe_mean)
    summary = {"env_steps": env_steps, "train_wall_s": wall, "eval_wall_s": eval_time}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    envs.close()
    probe_env.close()
    return summary


def plot_curves(runs: list[Path], labels: list[str], path: Path) -> None:
    """The runs' success rates (and, on tray tasks, carried rates) and median final goal
    distances against env steps and training wall time, one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(9, 5.6), sharex="col", sharey="row")
    seeds = 0
    for run, label in zip(runs, labels, strict=True):
        curve = json.loads((run / "curve.json").read_text())
        seeds = len(curve[0]["final_goal_error_m"])
        success = [p["success_rate"] for p in curve]
        distance = [float(np.median(p["final_goal_error_m"])) for p in curve]
        for column, x in enumerate(
            ([p["env_steps"] / 1e6 for p in curve], [p["train_wall_s"] / 60 for p in curve])
        ):
            line = axes[0, column].plot(x, success, "o-", label=label)[0]
            if "carried_rate" in curve[0]:  # a tray task: the cup carried, dashed
                carried = [p["carried_rate"] for p in curve]
                axes[0, column].plot(
                    x, carried, "s--", color=line.get_color(), label=f"{label}: cup carried"
                )
            axes[1, column].plot(x, distance, "o-", label=label)
    for column in (0, 1):
        axes[1, column].axhline(0.05, color="k", lw=0.8, ls="--")
    axes[1, 0].set_xlabel("env steps (millions)")
    axes[1, 1].set_xlabel("training wall time (min)")
    axes[0, 0].set_ylabel(f"success over {seeds} seeds")
    axes[0, 0].set_ylim(-0.05, 1.05)
    axes[1, 0].set_ylabel("median final goal distance (m)")
    axes[1, 0].set_yscale("log")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    axes[0, 0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", default="wip_gym/WIP-v0")
    p.add_argument("--frame-skip", type=int, default=10, help="1 ms MuJoCo steps per policy step")
    p.add_argument("--steps", type=int, default=3_000_000, help="env steps in all")
    p.add_argument("--num-envs", type=int, default=16)
    p.add_argument("--rollout", type=int, default=64, help="steps per env per update")
    p.add_argument("--epochs", type=int, default=10)
    p.add_argument("--minibatches", type=int, default=4)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--gae-lambda", type=float, default=0.95)
    p.add_argument("--clip", type=float, default=0.2)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--ent-coef", type=float, default=0.0)
    p.add_argument("--max-grad-norm", type=float, default=0.5)
    p.add_argument("--hidden", type=int, nargs="+", default=[64, 64])
    p.add_argument("--log-std-init", type=float, default=-0.5)
    p.add_argument("--goal-low", type=float, nargs="+", default=None, help="X (and Y), m")
    p.add_argument("--goal-high", type=float, nargs="+", default=None, help="X (and Y), m")
    p.add_argument("--eval-every", type=int, default=250_000, help="env steps; 0: never")
    p.add_argument("--eval-seeds", type=int, default=10)
    p.add_argument("--eval-duration", type=float, default=25.0, help="s")
    p.add_argument(
        "--reward",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="DenseRewardConfig fields (wip_gym.wrappers), e.g. spin=0.5",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--print-every", type=int, default=10, help="updates")
    p.add_argument("--plot", action="store_true", help="write curve.png")
    p.add_argument("--out", default="out/ppo")
    p.add_argument(
        "--plot-runs", nargs="+", metavar="DIR", help="only plot these runs' curves (no training)"
    )
    p.add_argument("--labels", nargs="+", help="one per --plot-runs run")
    p.add_argument("--plot-out", default="curves.png", help="the --plot-runs figure")
    args = p.parse_args(argv)
    if args.goal_low is not None:
        args.goal_low = args.goal_low[0] if len(args.goal_low) == 1 else tuple(args.goal_low)
    if args.goal_high is not None:
        args.goal_high = args.goal_high[0] if len(args.goal_high) == 1 else tuple(args.goal_high)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.plot_runs:
        runs = [Path(r) for r in args.plot_runs]
        plot_curves(runs, args.labels or [r.name for r in runs], Path(args.plot_out))
        return
    summary = train(args)
    out = Path(args.out)
    if args.plot and (out / "curve.json").exists():
        plot_curves([out], [args.env], out / "curve.png")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
