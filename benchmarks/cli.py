"""``wip-bench``: the benchmark command line.

wip-bench compare --env PlanarTray-v0 --controllers decoupled --episodes 3 --video
wip-bench figures --env PlanarTray-v0 --out docs/figures
wip-bench solvers --json out/solvers.json
wip-bench profile --env KrangTray-v0 --controller unified --json out/profile.json
wip-bench sweep benchmarks/sweeps/claim_map.toml --out out/claim_map
wip-bench render out/compare --camera tray --size 640x480
wip-bench view --env PlanarTray-v0 --controller unified
wip-bench view --replay out/compare/recording_unified.npz

``--import MODULE`` (repeatable) on compare, profile and sweep imports a module that registers
controllers (``controllers.registry``) before the command reads its arguments; compare's and the
sweep's workers import it too. Installed plug-ins (the entry-point group
``wip_gym.controllers``) need no flag (docs/extending.md §2).
"""

from __future__ import annotations

import argparse
import os
import sys

from benchmarks import compare, figures, render, view
from benchmarks.speed import profile, solvers
from benchmarks.sweep import cli as sweep_cli
from controllers import registry
from controllers.optimizer import jax_setup

IMPORT_COMMANDS = ("compare", "profile", "sweep")


def add_import_argument(parser: argparse.ArgumentParser) -> None:
    """``--import MODULE`` (repeatable): a module whose import registers controllers."""
    parser.add_argument(
        "--import",
        dest="imports",
        action="append",
        default=[],
        metavar="MODULE",
        help="import MODULE first, a module that registers controllers (repeatable; the "
        "workers import it too; it must be importable: installed or on PYTHONPATH)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="wip-bench", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    compare_parser = commands.add_parser("compare", help="controllers x seeds on one scenario")
    compare.add_arguments(compare_parser)
    figures_parser = commands.add_parser("figures", help="the paper's Figure 3 as PNGs")
    figures.add_arguments(figures_parser)
    solvers_parser = commands.add_parser(
        "solvers", help="DDP and task-QP solvers, ours against crocoddyl, NumPy iLQR and QP peers"
    )
    solvers.add_arguments(solvers_parser)
    profile_parser = commands.add_parser(
        "profile", help="one closed-loop episode's time per control step, part by part"
    )
    profile.add_arguments(profile_parser)
    sweep_parser = commands.add_parser(
        "sweep", help="a map over cells x controllers x seeds on Ray (or --report DIR)"
    )
    sweep_cli.add_arguments(sweep_parser)
    render_parser = commands.add_parser(
        "render", help="re-render a recorded compare run's videos without simulating"
    )
    render.add_arguments(render_parser)
    view_parser = commands.add_parser(
        "view", help="a controller driving an env, or a recording, in MuJoCo's viewer"
    )
    view.add_arguments(view_parser)
    for name in IMPORT_COMMANDS:
        add_import_argument(commands.choices[name])
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "solvers":  # its peers call the WIPM's JAX functions themselves
        jax_setup.configure()  # the compilation cache and float64 for the whole process
    else:  # the solvers scope float64 themselves (docs/DESIGN.md §4)
        jax_setup.use_compilation_cache()
    try:
        registry.import_modules(getattr(args, "imports", []))
        if args.command == "compare":
            compare.run(args)
        elif args.command == "figures":
            figures.run(args)
        elif args.command == "solvers":
            solvers.run(args)
        elif args.command == "profile":
            profile.run(args)
        elif args.command == "sweep":
            return sweep_cli.run(args)
        elif args.command == "render":
            render.run(args)
        elif args.command == "view":
            view.run(args)
    except ValueError as error:
        parser.error(str(error))  # exits with status 2 and the message
    except BrokenPipeError:  # the reader went away (`... --list-keys | head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


if __name__ == "__main__":
    sys.exit(main())
