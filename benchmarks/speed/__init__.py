"""Speed: our solvers against peer libraries on the same problems, and the closed loop against
the bare ``mj_step`` of the same model (the yardstick), apart from the experiment harness.

``wip-bench solvers`` and ``wip-bench profile`` run these; the other modules are
``python -m benchmarks.speed.<module>`` measurements (docs/performance.md)."""
