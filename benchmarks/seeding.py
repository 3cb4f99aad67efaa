"""The seed rule of every ``wip-bench`` command and tool that runs episodes by index.

Episode ``index`` (0, 1, 2, ...) of a run started with ``--seed base_seed`` resets its env with
``episode_seed(base_seed, index) = base_seed + index``. The same seed gives the same reset noise
and link-mass randomisation whichever command runs it, in any process, in any order: a
``compare`` episode can be re-run alone by ``figures`` or a tool with ``--seed`` set to its
``seed`` column in ``episodes.jsonl``. A sweep's episodes have no index: their seed is
derived from what they are (``benchmarks.sweep.seeding.cell_seed``: a hash of the cell's
parameters and the replicate), and is recorded in each row for the same re-run.
"""

from __future__ import annotations

import operator


def episode_seed(base_seed: int, index: int) -> int:
    """The env seed of episode ``index`` of a run with base seed ``base_seed``.

    Raises ``ValueError`` for a negative index or a result outside NumPy's seed range.
    """
    base, position = operator.index(base_seed), operator.index(index)
    if position < 0:
        raise ValueError(f"episode index must be >= 0, got {position}")
    seed = base + position
    if not 0 <= seed < 2**32:
        raise ValueError(
            f"episode seed {seed} (base {base} + index {position}) is outside [0, 2^32)"
        )
    return seed
