"""Speed: our solvers against peer libraries on the same problems, and the closed loop against
the bare ``mj_step`` of the same model (the yardstick), apart from the experiment harness.

``wip-bench solvers`` and ``wip-bench profile`` run these; ``python -m
benchmarks.speed.closed_loop_table`` runs ``wip-bench profile`` for every column of the closed
loop's table (docs/performance.md). The one-off experiments that led to today's design are kept
at the git tag ``lab-notebook``."""
