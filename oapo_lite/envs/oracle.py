"""Search oracle: shortest routes to the star per seat, by breadth-first search on ``next_cell``.

Seats never interact, so the team optimum is every seat taking its own shortest route.
Distances are ``np.inf`` on cells a seat may not stand on or from which it cannot reach the star.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from .maps import STEP_COST, Maze


def distances(maze: Maze) -> np.ndarray:
    """(n_agents, n_cells) float: fewest steps from each cell to the star, ``np.inf`` where none."""
    dist = np.full((maze.n_agents, maze.n_cells), np.inf)
    for k in range(maze.n_agents):
        table = maze.next_cell[k]
        # search backwards from the star: predecessors of a cell are the cells that move into it
        preds: list[list[int]] = [[] for _ in range(maze.n_cells)]
        for c in np.flatnonzero(maze.passable[k]):
            for nxt in set(table[c].tolist()) - {c}:
                preds[nxt].append(int(c))
        dist[k, maze.star] = 0
        queue = deque([maze.star])
        while queue:
            cell = queue.popleft()
            for p in preds[cell]:
                if dist[k, p] == np.inf:
                    dist[k, p] = dist[k, cell] + 1
                    queue.append(p)
    return dist


def optimal_actions(maze: Maze) -> np.ndarray:
    """(n_agents, n_cells, 5) bool: the actions that bring a seat one step closer to the star.

    On the star every action is optimal (the agent stays anyway); on cells with infinite
    distance none is.
    """
    dist = distances(maze)
    after = dist[np.arange(maze.n_agents)[:, None, None], maze.next_cell]
    best = np.isfinite(dist)[..., None] & (after == dist[..., None] - 1)
    best[:, maze.star] = True
    return best


def _check_seat(maze: Maze, k: int) -> int:
    if int(k) != k or not 0 <= k < maze.n_agents:
        raise ValueError(f"seat must be an integer in 0..{maze.n_agents - 1} (agents {maze.agents}), got {k!r}")
    return int(k)


def shortest_route(maze: Maze, k: int) -> list[int]:
    """Flat cells from seat k's start to the star, both included (``distances + 1`` cells).

    Ties are broken by the lowest action index (up, down, left, right), so the route is
    deterministic.
    """
    k = _check_seat(maze, k)
    best = optimal_actions(maze)[k]
    route = [maze.starts[k]]
    while route[-1] != maze.star:
        action = int(np.argmax(best[route[-1]]))
        route.append(int(maze.next_cell[k, route[-1], action]))
    return route


def optimal_return(maze: Maze, gamma: float = 1.0) -> float:
    """Best team return: ``mean_k(gamma^(d_k - 1) - STEP_COST * sum_{t < d_k} gamma^t)``.

    ``d_k`` is seat k's shortest distance; gamma = 1 gives the undiscounted
    ``mean_k(1 - STEP_COST * d_k)``. Truncation is ignored: it assumes every ``d_k`` fits
    in the episode (true for the built-in maps, d_k <= 13 < 50).
    """
    if not 0.0 < gamma <= 1.0:
        raise ValueError(f"gamma must lie in (0, 1], got {gamma!r}")
    d = distances(maze)[np.arange(maze.n_agents), list(maze.starts)].astype(int)
    costs = np.array([np.sum(gamma ** np.arange(dk)) for dk in d])
    return float(np.mean(gamma ** (d - 1.0) - STEP_COST * costs))


def check_fits(maze: Maze, max_steps: int) -> None:
    """Raise ``ValueError`` unless every seat can reach the star within ``max_steps`` and the
    best team return is positive (so that a fraction of it, ``frac_opt``, means something)."""
    d = distances(maze)[np.arange(maze.n_agents), list(maze.starts)]
    longest = int(d.max())
    if longest > max_steps:
        raise ValueError(f"max_steps = {max_steps} is invalid for maze {maze.name!r}: its longest shortest route "
                         f"is {longest} moves; allowed: max_steps >= {longest}")
    if optimal_return(maze) <= 0:
        raise ValueError(f"maze {maze.name!r} is invalid: its best team return is {optimal_return(maze):.3g} <= 0 "
                         f"(each route of d moves earns 1 - {STEP_COST:g} d), so a fraction of the optimum means "
                         f"nothing; allowed: routes shorter than {round(1 / STEP_COST)} moves")


def conflict_cells(maze: Maze, k: int, l: int) -> list[int]:
    """Cells (not the star) where seats k and l may both stand but share no optimal action.

    On such a cell both seats see the same observation, so one shared policy cannot be
    optimal for both.
    """
    k, l = _check_seat(maze, k), _check_seat(maze, l)
    dist, best = distances(maze), optimal_actions(maze)
    both = np.isfinite(dist[k]) & np.isfinite(dist[l])
    both[maze.star] = False
    disjoint = ~(best[k] & best[l]).any(-1)
    return np.flatnonzero(both & disjoint).tolist()


def one_policy_return(maze: Maze, max_steps: int, resolution: int = 100) -> tuple[float, dict[int, float]]:
    """The best expected team return of two seats that follow one policy of the cell alone, as
    one network must where observations carry no agent identity (``Maze.obs_table``).

    The policy takes the seats' shared optimal move where they have one, the optimal move of
    the seat that can use a cell elsewhere, and on each conflict cell (``conflict_cells``) seat
    0's optimal move with probability q and seat 1's with 1 - q. Its return under the reward
    rule (``core``) within ``max_steps`` is exact: each seat's distribution over cells is
    propagated step by step (seats never interact). Every q is chosen by coordinate ascent
    on a grid of step 1 / ``resolution``. Returns that return and the q of each conflict cell.
    """
    if maze.n_agents != 2:
        raise ValueError(f"one_policy_return compares two seats, maze {maze.name!r} has {maze.n_agents}")
    best = optimal_actions(maze)
    usable = best[0] & best[1]
    usable = np.where(usable.any(-1, keepdims=True), usable, best[0] | best[1])
    base = np.zeros((maze.n_cells, best.shape[-1]))
    base[np.arange(maze.n_cells), np.argmax(usable, -1)] = 1.0
    conflicts = conflict_cells(maze, 0, 1)
    moves = {c: (int(np.argmax(best[0, c])), int(np.argmax(best[1, c]))) for c in conflicts}
    cells = np.arange(maze.n_cells)

    def team_return(q: dict[int, float]) -> float:
        policy = base.copy()
        for c, (a0, a1) in moves.items():
            policy[c] = 0.0
            policy[c, a0], policy[c, a1] = q[c], 1.0 - q[c]
        total = 0.0
        for k in range(2):
            step = np.zeros((maze.n_cells, maze.n_cells))
            for a in range(policy.shape[1]):
                np.add.at(step, (cells, maze.next_cell[k, :, a]), policy[:, a])
            p = np.zeros(maze.n_cells)
            p[maze.starts[k]] = 1.0
            for _ in range(max_steps):
                arrived = p[maze.star]
                p = p @ step
                total += p[maze.star] - arrived - STEP_COST * (1.0 - arrived)
        return total / 2

    q = {c: 0.5 for c in conflicts}
    value, grid = team_return(q), np.linspace(0.0, 1.0, resolution + 1)
    while True:
        before = value
        for c in conflicts:
            values = [team_return(q | {c: g}) for g in grid]
            q[c], value = float(grid[int(np.argmax(values))]), max(values)
        if value <= before + 1e-12:
            return value, q
