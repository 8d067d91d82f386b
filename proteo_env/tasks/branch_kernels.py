"""The branch task's tree measure and success test as numba kernels (:mod:`proteo_env.tasks.branch`
is the task); the environment measures the tree with :func:`measure_tree` after every cycle, a
compiled rollout tests success with :func:`branch_update_and_test`."""

from __future__ import annotations

from enum import IntEnum

from ..core.jit import kernel


class BranchMode(IntEnum):
    """The branch task's modes (paper section 4.2): the chain's four, then the branching points; the one definition the task and its rules share."""

    SLEEP = 0
    SEARCH = 1
    SEED = 2
    FINAL = 3
    NODE = 4
    INODE = 5


SLEEP, SEARCH, SEED, FINAL, NODE, INODE = (int(m) for m in BranchMode)
"""The same modes as plain ints, for the numba kernels."""
"""The branch task's modes."""


@kernel
def measure_tree(
    grid,
    cell,
    mode,
    n_modules,
    dir_delta,
    root,
    min_gap,
    degree,
    parent,
    queue,
    arm,
    longc,
    real_up,
    real_d,
    any_d,
    level,
):
    """Breadth-first search of the grown piece from ``root`` and its branching levels (O(N)).

    A module is grown when its mode is SEED, FINAL, NODE or INODE. Scratch (N,) arrays are
    filled for grown modules reached from the root: ``degree`` (neighbours in the piece),
    ``parent`` (-2 when not reached, -1 for the root), ``arm`` (modules from here down the
    branch to the next branching point or leaf, both included), ``longc`` (child arms of at
    least ``min_gap`` modules), ``real_up``/``real_d`` (nearest *real* branching point above
    and its distance), ``any_d`` (distance to the nearest branching point above, 0 if none),
    ``level`` (at real branching points). Returns ``(size, edges, points, levels, children,
    most_children, distance_sum, distance_count, leaves)`` (``children``: summed over the
    branching points, ``most_children``: the largest at one point); see the module docstring
    for the definitions.
    """
    for n in range(n_modules):
        parent[n] = -2
        degree[n] = 0
        arm[n] = 0
        longc[n] = 0
        level[n] = 0
    m = mode[root]
    if not (m == 2 or m == 3 or m == 4 or m == 5):
        return 0, 0, 0, 0, 0, 0, 0, 0, 0
    parent[root] = -1
    queue[0] = root
    head, tail = 0, 1
    while head < tail:
        n = queue[head]
        head += 1
        for k in range(12):
            nb = grid[cell[n] + dir_delta[k]]
            if nb >= 0:
                mb = mode[nb]
                if mb == 2 or mb == 3 or mb == 4 or mb == 5:
                    degree[n] += 1
                    if parent[nb] == -2:
                        parent[nb] = n
                        queue[tail] = nb
                        tail += 1
    size = tail
    # children before parents: arm lengths and long child arms
    for i in range(size - 1, -1, -1):
        n = queue[i]
        if degree[n] == 2 and parent[n] >= 0:
            arm[n] += 1  # arm[n] held the arm of its one child
        else:
            arm[n] = 1
        p = parent[n]
        if p >= 0:
            if arm[n] >= min_gap:
                longc[p] += 1
            if degree[p] == 2 and parent[p] >= 0:
                arm[p] = arm[n]
    edges = 0
    points = 0
    levels = 0
    children = 0
    most_children = 0
    dist_sum = 0
    dist_count = 0
    leaves = 0
    # parents before children: nearest branching points above, levels
    for i in range(size):
        n = queue[i]
        edges += degree[n]
        if degree[n] == 1:
            leaves += 1
        p = parent[n]
        if p < 0:
            real_up[n] = -1
            real_d[n] = 0
            any_d[n] = 0
        else:
            if degree[p] >= 3:
                any_d[n] = 1
            else:
                any_d[n] = any_d[p] + 1 if any_d[p] > 0 else 0
            if degree[p] >= 3 and longc[p] >= 2:
                real_up[n] = p
                real_d[n] = 1
            else:
                real_up[n] = real_up[p]
                real_d[n] = real_d[p] + 1
        if degree[n] < 3:
            continue
        points += 1
        here = degree[n] if p < 0 else degree[n] - 1
        children += here
        if here > most_children:
            most_children = here
        if any_d[n] > 0:
            dist_sum += any_d[n]
            dist_count += 1
        if longc[n] >= 2:
            a = real_up[n]
            if a < 0:
                level[n] = 1
            else:
                level[n] = level[a] + (1 if real_d[n] >= min_gap else 0)
            if level[n] > levels:
                levels = level[n]
    return size, edges // 2, points, levels, children, most_children, dist_sum, dist_count, leaves


@kernel
def branch_update_and_test(grid, cell, mode, anchored, dir_delta, cycle, test):
    """The branch task's success test as a task's ``update_and_test`` (:class:`~proteo_env.tasks.base.TaskKernels`):
    the grown piece from the root is a tree with at least ``target_levels`` levels of branching
    (:func:`measure_tree`). ``test`` is ``(first_node, min_gap, target_levels, scratch)``: the
    root is ``first_node``, or when it is -1 the lowest-index NODE or INODE (module 0 when there
    is none); ``scratch`` is ``(9, N)`` int64."""
    first_node, min_gap, target_levels, scratch = test
    n_modules = cell.shape[0]
    root = first_node
    if root < 0:
        root = 0
        for n in range(n_modules):
            if mode[n] == NODE or mode[n] == INODE:
                root = n
                break
    size, edges, _, levels, _, _, _, _, _ = measure_tree(
        grid,
        cell,
        mode,
        n_modules,
        dir_delta,
        root,
        min_gap,
        scratch[0],
        scratch[1],
        scratch[2],
        scratch[3],
        scratch[4],
        scratch[5],
        scratch[6],
        scratch[7],
        scratch[8],
    )
    return size > 0 and edges == size - 1 and levels >= target_levels
