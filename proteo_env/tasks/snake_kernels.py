"""The snake task's modes (:mod:`proteo_env.tasks.snake` is the task).

The snake is a composed behaviour: the chain's modes (:class:`~proteo_env.tasks.chain.ChainMode`)
followed by the crawl's (:class:`CrawlMode`), so ``SnakeMode`` numbers the crawl's modes from 4.
The success test is locomotion's (:func:`~proteo_env.tasks.locomotion_kernels.locomotion_update_and_test`).
"""

from __future__ import annotations

from enum import IntEnum

from .chain import ChainMode


class CrawlMode(IntEnum):
    """The crawl's modes, numbered within the crawl (a chain travelling head first): CRAWL (a
    module travelling along the chain to its head), HEAD (the chain's front end, where the
    chain grows) and BODY (the rest of the chain)."""

    CRAWL = 0
    HEAD = 1
    BODY = 2


CRAWL, HEAD, BODY = (int(m) for m in CrawlMode)
"""The crawl's modes as plain ints, for the numba kernels."""

SnakeMode = IntEnum(
    "SnakeMode",
    [(m.name, int(m)) for m in ChainMode] + [(m.name, len(ChainMode) + int(m)) for m in CrawlMode],
)
SnakeMode.__doc__ = "The snake's modes: the chain's (0-3), then the crawl's (4-6)."
