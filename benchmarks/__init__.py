"""wip-bench: benchmarks of wip-gym controllers (the ``wip-bench`` command)."""
