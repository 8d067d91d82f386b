"""A chain travelling head first (the second stage of the snake, :mod:`baselines.snake`) as a
policy over observations.

Rules (modes CRAWL, HEAD, BODY, numbered 0-2 within the crawl), in the paper's style:

- HEAD, the chain's front end: emits scent and broadcasts its growth direction to all
  neighbours every cycle (message ``growth + 1``, as the chain's SEED does). It picks the
  growth by following the ground towards the goal (the observation's ``hint``): among the
  empty sites next to no other chain module (the chain stays one module thick), those ahead,
  the lowest first; else those level with the goal direction, the highest first (up the face
  of a step); else any. When a CRAWL module sits at the growth spot it asks that module to
  become the HEAD (message ``BECOME_HEAD``) and becomes BODY; a fresh HEAD first lets the
  crawlers hear its growth. A growth spot that gets blocked is chosen again.
- BODY: relays scent and never moves; the chain's tail (a BODY with exactly one module
  neighbour, so no crawler is holding on to it) becomes a CRAWL module. (A chain whose end
  came round to touch itself has no such module and stops; other tests of the tail lost more
  than they saved, docs/evidence/snake.md.)
- CRAWL: relays scent. Next to the HEAD it rolls over the HEAD's faces to the growth spot it
  heard (:func:`~baselines.primitives.approach_spot`) and holds still there; elsewhere it
  climbs the scent gradient along the chain (:func:`~baselines.primitives.lowest_rolls`; a
  chain module counts as lower than a crawler of the same scent, so crawlers travel on the
  chain rather than on each other), preferring rolls ahead, then level. With probability
  ``p_random``, and after ``patience`` cycles in a row without a roll to ask for, it makes a
  uniformly random legal roll instead.
- A HEAD that no crawler reached in ``head_patience`` cycles gives its growth spot up for
  another (walls and the ground can leave no roll into a spot).

So modules leave the chain at its tail, travel along it and join it at its head: the chain
moves head first, one module thick with at most one layer of crawlers beside it, which is
what a tunnel two layers high leaves room for.

The rule runs as the numba kernel :func:`baselines.crawl_rules.crawl_actions`; every decision
reads only that agent's observation and its private memory (:class:`CrawlMemory`).
"""

from __future__ import annotations

import numpy as np

from .base import KernelPolicy, SlotMemory
from .crawl_rules import PREFER_AHEAD, PREFER_DOWNHILL, PREFER_NONE, CrawlRuleParams, crawl_decide

PREFER = {"none": PREFER_NONE, "ahead": PREFER_AHEAD, "downhill": PREFER_DOWNHILL}
"""``CrawlPolicy(prefer=...)``: the names of :data:`~baselines.crawl_rules.CrawlRuleParams.prefer`'s values."""


class CrawlMemory(SlotMemory):
    """The crawl rule's private memory of every module: ``growth`` (S,) int64, a HEAD's growth
    direction (-1: none); ``idle`` (S,) int64, cycles in a row without a roll to ask for."""

    FIELDS = {"growth": (np.int64, -1), "idle": (np.int64, 0)}


class CrawlPolicy(KernelPolicy):
    """A chain travelling head first (rules in the module docstring).

    Args:
        p_random: probability of a uniformly random legal roll instead of the rule's.
        patience: cycles in a row without a roll to ask for after which a CRAWL module makes a
            random legal roll.
        head_patience: cycles a HEAD waits for a crawler at its growth spot before it gives the
            spot up for another (walls and the ground can leave no roll into a spot).
        greedy_approach: next to the HEAD, roll over its faces to the sites nearest the growth
            spot rather than to any.
    """

    name = "crawl"
    rule = staticmethod(crawl_decide)

    def __init__(
        self,
        action_layout,
        modes,
        *,
        scent_max=65535,
        seed=None,
        p_random=0.02,
        patience=10,
        head_patience=40,
        greedy_approach=True,
        prefer="downhill",
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed)
        if isinstance(p_random, bool) or not 0.0 <= p_random <= 1.0:
            raise ValueError(f"p_random={p_random!r} is not allowed; allowed: a probability in [0, 1]")
        for name, value in (("patience", patience), ("head_patience", head_patience)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}={value!r} is not allowed; allowed: an integer >= 1")
        self.p_random = p_random
        self.patience = patience
        self.head_patience = head_patience
        if prefer not in PREFER:
            raise ValueError(f"prefer={prefer!r} is not allowed; allowed: {', '.join(PREFER)}")
        self.greedy_approach = greedy_approach
        self.prefer = prefer
        self.memory = CrawlMemory()
        """Private memory of every module (see :class:`CrawlMemory`)."""

    @property
    def rule_params(self) -> CrawlRuleParams:
        """The parameters as :func:`~baselines.crawl_rules.crawl_actions` reads them."""
        return CrawlRuleParams(
            scent_max=int(self.scent_max),
            p_random=float(self.p_random),
            patience=int(self.patience),
            head_patience=int(self.head_patience),
            greedy_approach=bool(self.greedy_approach),
            prefer=PREFER[self.prefer],
        )


__all__ = ["CrawlMemory", "CrawlPolicy"]
