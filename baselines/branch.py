"""The paper's recursive branching behaviour (section 4.2) as a policy over observations.

Rules, as the paper lists them (modes SLEEP, SEARCH, SEED, FINAL, NODE, INODE; a *regular*
scent on channel 0 and a *node* scent on channel 1):

- If in SLEEP mode, if regular scent is detected, go to SEARCH mode.
- If in SEARCH mode, propagate both scents and move along the regular scent gradient.
- If in SEED mode, propagate the node scent, and emit a regular scent; if there is a
  neighbouring module in the direction of growth of the branch, set that module to be a
  seed, and go to FINAL mode.
- If in FINAL mode, propagate both scents; if the node scent is weak (i.e., has a value
  greater than some threshold ``T``), go to NODE mode.
- If in NODE mode, emit both scents, spawn seeds in random directions, until a certain count
  is reached ``B``, then go to INODE mode.
- If in INODE mode, emit a node scent and propagate the regular scent.

Growth starts from one NODE that the task places near the blob's centre (the paper's module
that "randomly decides to switch to the NODE mode", chosen centrally); with ``p_node > 0`` a
SLEEP module that detects no scent becomes a NODE with that probability each cycle instead.

How each rule is carried out through the agent interface (one module's observation in, one
action out, plus the module's own private memory; nothing else is read). SEARCH and SEED
reuse the chain behaviour (:class:`baselines.chain.ChainPolicy`) unchanged except that the
modes of the grown tree (SEED, FINAL, NODE, INODE) all count as "the structure":

- SLEEP: relays the regular scent (so that it spreads through the blob), is silent on the
  node scent (so that node distances are measured along the tree and the searching crowd,
  not through the unused blob), and goes SEARCH when it or a neighbour carries regular scent.
- SEARCH: relays both scents (with ``search_relays_node``, the paper's rule; off, it is
  silent on the node scent) and climbs the regular gradient exactly as the chain's SEARCH
  (:func:`baselines.chain_rules.search_moves`), seeing a NODE neighbour as a seed (it rolls over the
  node's faces to the growth spot the node broadcasts) and an INODE neighbour as FINAL.
- SEED: emits the regular scent, relays the node scent, and otherwise is the chain's seed:
  it broadcasts its growth direction; a SLEEP or SEARCH module at its growth site gets the
  message ``BECOME_SEED`` and the seed goes FINAL in the same action; the receiver grows on
  in the same direction. A seed whose growth site is blocked (solid, the wall, or a site
  touching a grown module other than itself: SEED, FINAL, NODE, INODE) turns by at most 90
  degrees; growth stays in the horizontal plane of the first node (``horizontal``).
- Refusal (not in the paper; ``refuse``): a seed sees only 4 of its growth site's 11 other
  neighbours, and in the horizontal plane none of the in-plane ones, so a branch could grow
  into the side of another. The module asked to become a seed sees its own neighbours: when
  one of them, other than the sender, is a grown module, it stays as it is and answers
  ``REFUSE`` (14) to the sender. A FINAL module that gets ``REFUSE`` becomes a SEED again and
  turns (it remembers the refused direction); a NODE or INODE counts one seed fewer (an
  INODE goes back to NODE) and does not use that direction again.
- FINAL: relays both scents; when its own node scent is known and greater than ``T`` and no
  neighbour is a NODE or INODE (so two adjacent modules never both turn into nodes while the
  new node's scent is still one hop away), it goes NODE.
- NODE: emits both scents. "Spawn seeds in random directions until a count B is reached":
  the node keeps in private memory the number of seeds spawned and its current growth spot,
  a uniformly random choice among the neighbour sites (horizontal ones with
  ``horizontal``) that hold no grown module and whose seen neighbours (the 4 sites next to
  both the node and the spot) hold no grown module; when its spot has stayed empty for
  ``patience`` cycles it chooses again (under the stricter motion models a module may have no roll into a given site).
  It broadcasts that direction (message ``growth + 1``, like a seed) so that searching
  modules come to the spot; when a SLEEP module, or a SEARCH module that has heard the
  broadcast and therefore holds still, is at the spot, the node sends it ``BECOME_SEED``:
  the receiver becomes a SEED growing straight away from the node (the message arrived from
  the opposite side). After ``B`` seeds, or when no site is left, the node goes INODE. A
  point of a tree has at most 4 neighbours in it (3 new branches on a branch), in the plane
  and in 3D alike (docs/tasks/branch.md), so ``B`` above that is capped by the geometry.
- INODE: emits the node scent, relays the regular scent, never moves.

The rules run as the numba kernels of :mod:`baselines.branch_rules` (:func:`~baselines.branch_rules.branch_actions`,
which calls the chain's SEARCH and seed kernels) on the observation fields stacked over modules;
the private memory is one row per module (:class:`BranchMemory`).
"""

from __future__ import annotations

import numpy as np

from .branch_rules import NO_COUNT, BranchRuleParams, branch_decide
from .chain import ChainPolicy, ModuleMemory
from .chain_rules import ChainRuleParams


class BranchMemory(ModuleMemory):
    """The branch rule's private memory: the chain's (:class:`~baselines.chain.ModuleMemory`) and,
    per slot, a NODE's seeds spawned (``spawned``, :data:`~baselines.branch_rules.NO_COUNT`: none
    yet), its current growth spot (``spot_direction``, -1: none; ``spot_announced``;
    ``spot_waited``, cycles) and the directions whose module refused to become a seed
    (``refused``, a bit set)."""

    FIELDS = {
        **ModuleMemory.FIELDS,
        "spawned": (np.int64, NO_COUNT),
        "spot_direction": (np.int64, -1),
        "spot_announced": (np.bool_, False),
        "spot_waited": (np.int64, 0),
        "refused": (np.int64, 0),
    }


class BranchPolicy(ChainPolicy):
    """Hand-coded recursive branching (rules and how they are carried out in the module docstring).

    Args:
        T: node-scent threshold (paper 12); a FINAL module with node scent above it goes NODE.
        B: seeds a NODE spawns before going INODE (paper 6).
        p_node: per-cycle probability that a SLEEP module with no scent around becomes a NODE
            (0: rely on the task's central first node).
        search_relays_node: SEARCH modules relay the node scent (the paper's rule).
        patience: cycles a NODE waits for a module at an empty growth spot before choosing
            another spot.
        refuse: a module asked to become a seed refuses when it touches a grown module other
            than the sender (see the module docstring).
        **chain: the parameters of :class:`ChainPolicy` for SEARCH and SEED (``p_random``,
            ``horizontal``, ``turn``, ...).
    """

    name = "branch"
    rule = staticmethod(branch_decide)

    def __init__(
        self,
        action_layout,
        modes,
        *,
        scent_max=65535,
        seed=None,
        T=12,
        B=6,
        p_node=0.0,
        search_relays_node=True,
        refuse=True,
        patience=30,
        **chain,
    ):
        super().__init__(action_layout, modes, scent_max=scent_max, seed=seed, **chain)
        if T < 1:
            raise ValueError(f"T={T!r} is not allowed; allowed: an integer >= 1")
        if B < 1:
            raise ValueError(f"B={B!r} is not allowed; allowed: an integer >= 1")
        if not 0.0 <= p_node <= 1.0:
            raise ValueError(f"p_node={p_node!r} is not allowed; allowed: a probability in [0, 1]")
        self.T = int(T)
        self.B = int(B)
        self.p_node = p_node
        self.search_relays_node = search_relays_node
        self.refuse = refuse
        self.patience = patience
        self.memory = BranchMemory()
        """Private memory of every module (see :class:`BranchMemory`)."""

    @property
    def branch_params(self) -> BranchRuleParams:
        """The branch's own parameters as the kernels of :mod:`baselines.branch_rules` read them."""
        return BranchRuleParams(
            T=int(self.T),
            B=int(self.B),
            p_node=float(self.p_node),
            search_relays_node=bool(self.search_relays_node),
            refuse=bool(self.refuse),
            patience=int(self.patience),
        )

    @classmethod
    def for_env(cls, env, *, seed=None, **params):
        """Build from the environment's static interface; ``T``, ``B`` and ``horizontal`` (the
        task's ``planar``) default to the task's."""
        task_params = env.task.params
        params.setdefault("T", getattr(task_params, "T", 12))
        params.setdefault("B", getattr(task_params, "B", 6))
        params.setdefault("horizontal", getattr(task_params, "planar", True))
        return super().for_env(env, seed=seed, **params)

    @property
    def rule_params(self) -> tuple[ChainRuleParams, BranchRuleParams]:
        """The chain's and the branch's parameters, as :func:`~baselines.branch_rules.branch_decide` reads them."""
        return super().rule_params, self.branch_params
