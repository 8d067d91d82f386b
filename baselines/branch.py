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
  (:func:`baselines.chain.search_moves`), seeing a NODE neighbour as a seed (it rolls over the
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

The rules run as the numba kernel :func:`branch_actions` (the policy's ``rule``, which calls
the chain's SEARCH and seed kernels) on the observation fields stacked over modules (array
shapes as in :mod:`baselines.chain`); the private memory is one row per module
(:class:`BranchMemory`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from proteo_env.core.jit import kernel
from proteo_env.core.lattice import OPPOSITE
from proteo_env.core.world import MESSAGE_TO_ALL
from proteo_env.spaces import EMIT, KIND_EMPTY, KIND_MODULE, RELAY, SILENT
from proteo_env.tasks.branch import FINAL, INODE, NODE, SEARCH, SEED, SLEEP

from .chain import BECOME_SEED, ChainPolicy, ModuleMemory, search_actions, seed_blocked
from .primitives import (
    ALL_BITS,
    HORIZONTAL_BITS,
    detects_scent,
    fewest_ruled_out,
    growth_direction,
    legal_bits,
    spot_touches,
    uniform_pick,
    write_action,
)

REFUSE = 14
"""Message value: "I will not become your seed: I touch another part of the tree"."""
GROWN_BITS = (1 << SEED) | (1 << FINAL) | (1 << NODE) | (1 << INODE)
"""The modes of the grown tree (SEED, FINAL, NODE, INODE), as a bit set."""
NO_COUNT = np.iinfo(np.int64).min
"""``spawned`` of a module that has no count (a count may go below 0 when seeds refuse)."""


@kernel
def branch_seed_action(neighbour_kind, neighbour_mode, i, growth, fresh, previous, refused, rules, rng, actions):
    """Write the action of the branch seed at row ``i`` into ``actions[i]``; return the growth it
    keeps in memory (-1: none).

    The chain's seed (:func:`seed_action`) with the tree's modes (SEED, FINAL, NODE, INODE) as
    the structure to keep away from, the bit set ``refused`` of directions whose module refused
    to become a seed (never chosen again), ``previous`` as the direction it came in when
    ``growth`` is unknown, and no second, non-horizontal try.
    """
    known = growth >= 0
    if (
        not known
        or (refused >> growth) & 1
        or (rules.turn and seed_blocked(neighbour_kind, neighbour_mode, i, growth, GROWN_BITS))
    ):
        new = growth_direction(
            neighbour_kind,
            neighbour_mode,
            i,
            rng,
            rules.horizontal,
            growth if known else previous,
            GROWN_BITS,
            rules.clean_exit,
        )
        if new >= 0 and (refused >> new) & 1:
            new = -1
        if new >= 0 or not known or (refused >> growth) & 1:
            growth = new
    if growth < 0:
        write_action(actions, i, 0, SEED, EMIT, RELAY, 0, 0)
        return -1
    kind, m = neighbour_kind[i, growth], neighbour_mode[i, growth]
    if (
        not fresh
        and kind == KIND_MODULE
        and (m == SLEEP or m == SEARCH)
        and not (rules.turn and seed_blocked(neighbour_kind, neighbour_mode, i, growth, GROWN_BITS))
    ):
        write_action(actions, i, 0, FINAL, RELAY, RELAY, growth, BECOME_SEED)
        return -1
    write_action(actions, i, 0, SEED, EMIT, RELAY, MESSAGE_TO_ALL, growth + 1)
    return growth


@kernel
def _spot_free(neighbour_kind, neighbour_mode, i, k):
    """Can a new branch start at the face site ``k`` of row ``i``? It holds no grown module and the
    sites seen next to it hold none."""
    kind = neighbour_kind[i, k]
    if kind == KIND_MODULE:
        m = neighbour_mode[i, k]
        if m >= 0 and (GROWN_BITS >> m) & 1:
            return False
    elif kind != KIND_EMPTY:
        return False
    return spot_touches(neighbour_mode, i, k, GROWN_BITS) == 0


@kernel
def _retire(s, spawned, spot_direction, spot_announced, spot_waited, refused):
    """Forget a node's memory at slot ``s`` (it goes INODE)."""
    spawned[s] = NO_COUNT
    spot_direction[s] = -1
    spot_announced[s] = False
    spot_waited[s] = 0
    refused[s] = 0


@kernel
def node_action(
    neighbour_kind,
    neighbour_mode,
    i,
    s,
    spawned,
    spot_direction,
    spot_announced,
    spot_waited,
    refused,
    rules,
    branch,
    rng,
    actions,
):
    """Write the action of the NODE at row ``i`` (memory slot ``s``) into ``actions[i]``.

    It keeps the number of seeds spawned (``spawned``, :data:`NO_COUNT`: none yet) and its current growth
    spot (direction, announced last cycle, cycles waited; direction -1: none). A spot that is
    no longer free, or has stayed empty for ``patience`` cycles, is replaced by a uniform
    choice (one ``rng.integers`` draw) among the free face sites (horizontal ones with
    ``horizontal``) it has not been refused that rule out the fewest other free sites
    (:func:`~baselines.primitives.fewest_ruled_out`; in the plane none rules out another). A SLEEP module at the spot, or a SEARCH one that has
    heard the spot announced, gets ``BECOME_SEED``; after ``B`` seeds, or with no free site
    left, the node goes INODE. Otherwise it announces the spot (message ``direction + 1``).
    """
    count = spawned[s] if spawned[s] != NO_COUNT else 0
    if count >= branch.B:
        _retire(s, spawned, spot_direction, spot_announced, spot_waited, refused)
        write_action(actions, i, 0, INODE, RELAY, EMIT, 0, 0)
        return
    direction, announced, waited = spot_direction[s], spot_announced[s], spot_waited[s]
    if (
        direction < 0
        or not _spot_free(neighbour_kind, neighbour_mode, i, direction)
        or (neighbour_kind[i, direction] != KIND_MODULE and waited >= branch.patience)
    ):
        allowed = HORIZONTAL_BITS if rules.horizontal else ALL_BITS
        pool = 0
        for k in range(12):
            if (allowed >> k) & 1 and not (refused[s] >> k) & 1 and _spot_free(neighbour_kind, neighbour_mode, i, k):
                pool |= 1 << k
        if pool == 0:
            _retire(s, spawned, spot_direction, spot_announced, spot_waited, refused)
            write_action(actions, i, 0, INODE, RELAY, EMIT, 0, 0)
            return
        new = uniform_pick(rng, fewest_ruled_out(pool))
        announced = announced and new == direction
        direction, waited = new, 0
    spawned[s] = count
    kind, m = neighbour_kind[i, direction], neighbour_mode[i, direction]
    if kind == KIND_MODULE and (m == SLEEP or (m == SEARCH and announced)):
        spawned[s] = count + 1
        spot_direction[s] = -1
        spot_announced[s] = False
        spot_waited[s] = 0
        if count + 1 >= branch.B:  # the last seed: go INODE in the same action
            write_action(actions, i, 0, INODE, RELAY, EMIT, direction, BECOME_SEED)
        else:
            write_action(actions, i, 0, NODE, EMIT, EMIT, direction, BECOME_SEED)
        return
    spot_direction[s] = direction
    spot_announced[s] = True
    spot_waited[s] = waited + 1
    write_action(actions, i, 0, NODE, EMIT, EMIT, MESSAGE_TO_ALL, direction + 1)


@kernel
def branch_actions(seen, slots, memory, chain_and_branch, rng, actions):
    """Every agent's action under the branch rule: the policy's ``rule``
    (:attr:`baselines.base.KernelPolicy.rule`; ``memory`` is the 8 arrays of
    :class:`BranchMemory`, ``chain_and_branch`` a ``(ChainRuleParams, BranchRuleParams)`` pair).

    Shapes as in :mod:`baselines.chain`, two scent channels (0 regular, 1 node); the branch
    memory (S,): ``spawned``, ``spot_direction``, ``spot_announced``, ``spot_waited`` (see
    :func:`node_action`) and ``refused`` (bit set of refused directions). In order: defaults;
    modules asked to become a seed refuse (``REFUSE`` to the sender, with ``refuse``, when they
    touch a grown module other than the sender) or become a fresh seed; a FINAL module whose
    seed refused becomes a seed again; a NODE or INODE whose seed refused counts one seed
    fewer; SEEDs act; SLEEP modules are silent on the node scent and wake on regular scent
    (with ``p_node`` one that detects none becomes a NODE); FINAL modules with a known node
    scent above ``T`` and no NODE or INODE next to them become NODEs; NODEs (and INODEs whose
    seed refused) act as nodes, INODEs emit the node scent; SEARCH modules act as the chain's,
    seeing a NODE as a SEED and an INODE as FINAL; grown modules forget their heading.
    """
    own_mode, messages, own_scent, action_mask = seen.own_mode, seen.messages, seen.own_scent, seen.action_mask
    neighbour_kind, neighbour_mode, neighbour_scent = seen.neighbour_kind, seen.neighbour_mode, seen.neighbour_scent
    heading, growth, asked, spawned, spot_direction, spot_announced, spot_waited, refused = memory
    rules, branch = chain_and_branch
    n_agents = own_mode.shape[0]
    smax = rules.scent_max
    promoted = np.full(n_agents, -1, dtype=np.int64)
    refused_from = np.full(n_agents, -1, dtype=np.int64)
    for i in range(n_agents):
        own = own_mode[i, 0]
        write_action(actions, i, 0, own, RELAY, RELAY, 0, 0)
        for k in range(12):
            if messages[i, k] == REFUSE:
                refused_from[i] = k
                break
        if own == SLEEP or own == SEARCH:
            for k in range(12):
                if messages[i, k] == BECOME_SEED:
                    promoted[i] = k
                    break
    for i in range(n_agents):
        if promoted[i] < 0:
            continue
        if branch.refuse:
            touches_tree = False
            for k in range(12):
                m = neighbour_mode[i, k]
                if k != promoted[i] and neighbour_kind[i, k] == KIND_MODULE and m >= 0 and (GROWN_BITS >> m) & 1:
                    touches_tree = True
            if touches_tree:  # joining would touch another part of the tree
                actions[i, actions.shape[1] - 2] = promoted[i]
                actions[i, actions.shape[1] - 1] = REFUSE
                promoted[i] = -2  # neither a seed nor moving this cycle
                continue
        growth[slots[i]] = branch_seed_action(
            neighbour_kind, neighbour_mode, i, OPPOSITE[promoted[i]], True, -1, refused[slots[i]], rules, rng, actions
        )
    for i in range(n_agents):  # the seed it made refused: seed again
        if refused_from[i] >= 0 and own_mode[i, 0] == FINAL:
            s = slots[i]
            refused[s] |= 1 << refused_from[i]
            growth[s] = branch_seed_action(
                neighbour_kind, neighbour_mode, i, -1, True, refused_from[i], refused[s], rules, rng, actions
            )
    for i in range(n_agents):  # a node's seed refused: one seed fewer
        own = own_mode[i, 0]
        if refused_from[i] >= 0 and (own == NODE or own == INODE):
            s = slots[i]
            refused[s] |= 1 << refused_from[i]
            spawned[s] = min(spawned[s] if spawned[s] != NO_COUNT else branch.B, branch.B) - 1
            spot_direction[s] = -1
            spot_announced[s] = False
            spot_waited[s] = 0
    for i in range(n_agents):
        if own_mode[i, 0] == SEED:
            s = slots[i]
            growth[s] = branch_seed_action(
                neighbour_kind, neighbour_mode, i, growth[s], False, -1, refused[s], rules, rng, actions
            )
    for i in range(n_agents):
        if own_mode[i, 0] != SLEEP or promoted[i] != -1:
            continue
        actions[i, 3] = SILENT
        if detects_scent(own_scent, neighbour_kind, neighbour_scent, i, smax):
            if not rules.wake_when_free or legal_bits(action_mask, i):
                actions[i, 1] = SEARCH
        elif branch.p_node > 0 and rng.random() < branch.p_node:
            node_action(
                neighbour_kind,
                neighbour_mode,
                i,
                slots[i],
                spawned,
                spot_direction,
                spot_announced,
                spot_waited,
                refused,
                rules,
                branch,
                rng,
                actions,
            )
    for i in range(n_agents):  # FINAL: a weak node scent (known, > T) with no node next to it: go NODE
        if own_mode[i, 0] != FINAL or refused_from[i] >= 0:
            continue
        node_scent = own_scent[i, 1]
        near_node = False
        for k in range(12):
            m = neighbour_mode[i, k]
            near_node |= m == NODE or m == INODE
        if node_scent > branch.T and node_scent < smax and not near_node:
            node_action(
                neighbour_kind,
                neighbour_mode,
                i,
                slots[i],
                spawned,
                spot_direction,
                spot_announced,
                spot_waited,
                refused,
                rules,
                branch,
                rng,
                actions,
            )
    for i in range(n_agents):
        own = own_mode[i, 0]
        if own == NODE or (own == INODE and refused_from[i] >= 0):
            node_action(
                neighbour_kind,
                neighbour_mode,
                i,
                slots[i],
                spawned,
                spot_direction,
                spot_announced,
                spot_waited,
                refused,
                rules,
                branch,
                rng,
                actions,
            )
        elif own == INODE:
            actions[i, 3] = EMIT
    n_search = 0
    for i in range(n_agents):
        if own_mode[i, 0] == SEARCH and promoted[i] == -1:
            n_search += 1
    search = np.empty(n_search, dtype=np.int64)
    n_search = 0
    for i in range(n_agents):
        if own_mode[i, 0] == SEARCH and promoted[i] == -1:
            search[n_search] = i
            n_search += 1
            if not branch.search_relays_node:
                actions[i, 3] = SILENT
    seen = neighbour_mode.copy()  # a NODE is a seed to approach, an INODE part of the chain
    for i in range(n_agents):
        for k in range(12):
            if seen[i, k] == NODE:
                seen[i, k] = SEED
            elif seen[i, k] == INODE:
                seen[i, k] = FINAL
    search_actions(
        search, messages, neighbour_kind, seen, neighbour_scent, action_mask, slots, heading, asked, rules, rng, actions
    )
    for i in range(n_agents):
        if own_mode[i, 0] >= FINAL:
            heading[slots[i]] = -1
            asked[slots[i]] = False


class BranchRuleParams(NamedTuple):
    """The branch rule's own parameters, :class:`BranchPolicy`'s keywords besides the chain's
    (:class:`~baselines.chain.ChainRuleParams`, for SEARCH and SEED).

    Attributes:
        T: node-scent threshold (paper 12); a FINAL module with node scent above it goes NODE.
        B: seeds a NODE spawns before going INODE (paper 6).
        p_node: per-cycle probability that a SLEEP module with no scent around becomes a NODE
            (0: rely on the task's central first node).
        search_relays_node: SEARCH modules relay the node scent (the paper's rule).
        patience: cycles a NODE waits for a module at an empty growth spot before choosing
            another spot.
        refuse: a module asked to become a seed refuses when it touches a grown module other
            than the sender (see the module docstring).
    """

    T: int = 12
    B: int = 6
    p_node: float = 0.0
    search_relays_node: bool = True
    refuse: bool = True
    patience: int = 30

    def check(self) -> None:
        """A ``ValueError`` for a value not allowed."""
        for name in ("T", "B"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)!r} is not allowed; allowed: an integer >= 1")
        if not 0.0 <= self.p_node <= 1.0:
            raise ValueError(f"p_node={self.p_node!r} is not allowed; allowed: a probability in [0, 1]")


class BranchMemory(ModuleMemory):
    """The branch rule's private memory: the chain's (:class:`~baselines.chain.ModuleMemory`) and,
    per slot, a NODE's seeds spawned (``spawned``, :data:`NO_COUNT`: none
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
    """Hand-coded recursive branching (rules and how they are carried out in the module docstring;
    parameters: :class:`BranchRuleParams` and the chain's :class:`~baselines.chain.ChainRuleParams`)."""

    name = "branch"
    Params = BranchRuleParams
    Memory = BranchMemory
    rule = staticmethod(branch_actions)

    @classmethod
    def for_env(cls, env, *, seed=None, **params):
        """Build from the environment's static interface; ``T``, ``B`` and ``horizontal`` (the
        task's ``planar``) default to the task's."""
        task_params = env.task.params
        params.setdefault("T", getattr(task_params, "T", 12))
        params.setdefault("B", getattr(task_params, "B", 6))
        params.setdefault("horizontal", getattr(task_params, "planar", True))
        return super().for_env(env, seed=seed, **params)
