"""The snake (:mod:`proteo_env.tasks.snake`): the paper's chain rules, then a crawl, composed.

The first stage is the chain (:mod:`baselines.chain`, the paper's rules unchanged): the
modules form one chain from the blob, growing from the task's seed. The second is the crawl
(:mod:`baselines.crawl`): modules leave the chain's tail, travel along the chain and join it
at its head, so the chain moves head first towards the goal. Each module hands over on its
own (:func:`chain_handover`, local conditions only):

- a FINAL module that is the chain's tail (one module neighbour) and sees no module still
  looking for the chain (SLEEP or SEARCH) becomes a CRAWL module: the chain is finished
  where it starts, and its modules begin to travel;
- a SEED that sees a module of the crawl becomes the HEAD (a crawler has come round);
- a SLEEP or SEARCH module asked by a HEAD to join the chain at its head becomes a CRAWL
  module, and then the HEAD, as a crawler would.

Across the stages the modes read as their counterparts: to the chain's rules a CRAWL module
is a SEARCH module, the HEAD a SEED and BODY a FINAL; to the crawl's, SLEEP and SEARCH modules
are crawlers, the SEED a HEAD and FINAL modules BODY. Composition: :mod:`baselines.compose`.
"""

from __future__ import annotations

from proteo_env.core.jit import kernel
from proteo_env.spaces import KIND_MODULE
from proteo_env.tasks.chain import ChainMode
from proteo_env.tasks.crawl import CrawlMode
from proteo_env.tasks.snake import SnakeMode

from .chain import ChainPolicy
from .compose import Stage, compose
from .crawl import BECOME_HEAD, CrawlPolicy, is_tail

SLEEP, SEARCH, SEED, FINAL = (int(SnakeMode[m]) for m in ("SLEEP", "SEARCH", "SEED", "FINAL"))
CRAWL, HEAD = int(SnakeMode.CRAWL), int(SnakeMode.HEAD)


@kernel
def chain_handover(seen, i, rules):
    """The snake's handover from the chain to the crawl (module docstring): the composed mode
    the chain module at row ``i`` of ``seen`` moves on to, or -1 (``rules``: the chain's
    :class:`~baselines.chain.ChainRuleParams`)."""
    own = seen.own_mode[i, 0]
    looking, crawl = False, False
    for k in range(12):
        if seen.neighbour_kind[i, k] == KIND_MODULE:
            m = seen.neighbour_mode[i, k]
            looking |= m == SLEEP or m == SEARCH
            crawl |= m >= CRAWL
    if own == FINAL and not looking and is_tail(seen.neighbour_kind, i):
        return CRAWL
    if own == SEED and crawl:
        return HEAD
    if own == SLEEP or own == SEARCH:
        for k in range(12):
            if seen.messages[i, k] == BECOME_HEAD:
                return CRAWL
    return -1


SnakePolicy = compose(
    "snake",
    Stage(ChainPolicy, tuple(ChainMode.__members__), sees={"CRAWL": "SEARCH", "HEAD": "SEED", "BODY": "FINAL"}),
    Stage(
        CrawlPolicy,
        tuple(CrawlMode.__members__),
        sees={"SLEEP": "CRAWL", "SEARCH": "CRAWL", "SEED": "HEAD", "FINAL": "BODY"},
    ),
    chain_handover,
    doc=__doc__.split("\n\n")[0],
)

__all__ = ["SnakePolicy", "chain_handover"]
