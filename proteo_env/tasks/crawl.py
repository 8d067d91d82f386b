"""The crawl: a chain travelling head first, modules leaving its tail and joining it at its head.

The crawl is a behaviour without a task of its own: it is the second stage of ``snake-v0``
(:mod:`proteo_env.tasks.snake`, whose modes are the chain's followed by these). This file holds
what the task side and the crawl's rule (:mod:`baselines.crawl`) share: its modes.
"""

from __future__ import annotations

from enum import IntEnum


class CrawlMode(IntEnum):
    """The crawl's modes, numbered within the crawl: CRAWL (a module travelling along the chain
    to its head), HEAD (the chain's front end, where the chain grows) and BODY (the rest of the
    chain)."""

    CRAWL = 0
    HEAD = 1
    BODY = 2


CRAWL, HEAD, BODY = (int(m) for m in CrawlMode)
"""The crawl's modes as plain ints, for the numba kernels."""
