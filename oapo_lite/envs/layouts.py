"""Generated two-agent mazes for the layout study: one parameter varied at a time.

Every layout is a *fork*: red and black start on one cell, walk ``prefix`` moves up a shared
column, reach a horizontal fork corridor where red must go left and black right, climb
``branch + 1`` rows through their own cells (R left, B right), meet again in an open top
corridor and climb ``suffix`` moves up a shared column to the star::

    #########
    ####*####   suffix: shared moves after the fork
    ####.####
    #.......#   top corridor: both walk towards its middle (they agree here)
    #R#####B#   branch rows: red's cells on the left, black's on the right
    #R#####B#
    #RR...BB#   fork corridor: its open cells are the conflict cells
    ####.####   prefix: shared moves before the fork
    ####.####   <- both start here

In the fork corridor an open cell is a *conflict cell* (oracle.conflict_cells): both agents
may stand there and see the same observation, but red's only good move is left and black's
right. The other corridor cells belong to one colour, so only one agent may stand there. The
agents' routes are unique (corridors one cell wide), so "the shared part of the routes" is
well defined: ``prefix`` moves before the conflict and ``suffix`` moves after it.
``fork(prefix=0, conflicts=7, branch=2, suffix=3)`` is exactly Black-Red.

Maps are text in the project's map format (``maps.py``); the engine spec
``layout:<name>`` trains on one (``envs/registry.py``), e.g. ``layout:fork-p2-c3-b4-s3-h3``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from .core import make_vec as make_maze_vec
from .maps import Maze, parse_maze
from .oracle import conflict_cells, optimal_actions, shortest_route


@dataclass(frozen=True)
class Fork:
    """One fork layout; the fields are what the generator claims about it."""

    prefix: int  # moves both agents make together from the start, before the fork
    conflicts: int  # open cells of the fork corridor = conflict cells of red and black
    branch: int  # rows of coloured cells between the fork and the top corridor
    suffix: int  # moves both make together from the top corridor's middle to the star
    half: int = 3  # fork and top corridors reach this far left and right of the middle

    def __post_init__(self):
        for name, low in (("prefix", 0), ("conflicts", 1), ("branch", 1), ("suffix", 1), ("half", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        if self.conflicts > 2 * self.half + 1:
            raise ValueError(f"conflicts must be at most the fork corridor's {2 * self.half + 1} cells "
                             f"(2 * half + 1 with half = {self.half}), got {self.conflicts}")

    @property
    def name(self) -> str:
        return f"fork-p{self.prefix}-c{self.conflicts}-b{self.branch}-s{self.suffix}-h{self.half}"

    @property
    def route_length(self) -> int:
        """Moves from the start to the star, the same for both agents."""
        return self.prefix + 2 * self.half + self.branch + 1 + self.suffix

    @property
    def first_move(self) -> str:
        """"shared" when the agents' first moves agree, "conflict" when the start is a conflict cell."""
        return "shared" if self.prefix > 0 else "conflict"

    def text(self) -> str:
        """The map, in the project's map format."""
        width, mid = 2 * self.half + 3, self.half + 1
        column = "#" * mid + "." + "#" * mid
        # the fork corridor's open cells, outward from the middle: right, left, right, ...
        offsets = [0] + [s * k for k in range(1, self.half + 1) for s in (1, -1)]
        open_cols = {mid + d for d in offsets[: self.conflicts]}
        fork_row = "#" + "".join("." if c in open_cols else "R" if c < mid else "B"
                                 for c in range(1, width - 1)) + "#"
        rows = (["#" * width, "#" * mid + "*" + "#" * mid] + [column] * (self.suffix - 1)
                + ["#" + "." * (width - 2) + "#"] + ["#R" + "#" * (width - 4) + "B#"] * self.branch
                + [fork_row] + [column] * self.prefix + ["#" * width])
        start = f"{len(rows) - 2},{mid}"
        return f"agents: red black\nstart: {start} {start}\n" + "\n".join(rows) + "\n"


# The base layout: 16 moves per agent, 2 shared before the fork and 3 after, 3 conflict cells.
BASE = dict(prefix=2, conflicts=3, branch=4, suffix=3)


def first_move_family(shared: int = BASE["prefix"], **base) -> list[Fork]:
    """Share the first moves or conflict on them: the ``shared`` moves before the fork move
    after it, so route length, the number of shared moves and the conflict count stay the same."""
    b = {**BASE, **base}
    total = b["prefix"] + b["suffix"]
    return [Fork(**{**b, "prefix": shared, "suffix": total - shared}), Fork(**{**b, "prefix": 0, "suffix": total})]


def shared_prefix_family(prefixes=(0, 1, 2, 3, 5), **base) -> list[Fork]:
    """How long the shared first part of the routes is: prefix + branch is held fixed, so the
    route length and everything else stay the same."""
    b = {**BASE, **base}
    total = b["prefix"] + b["branch"]
    if max(prefixes) >= total:
        raise ValueError(f"prefixes must be below prefix + branch = {total} (a branch needs a row), got {prefixes}")
    return [Fork(**{**b, "prefix": p, "branch": total - p}) for p in prefixes]


def conflicts_family(counts=(1, 3, 5, 7), **base) -> list[Fork]:
    """How many conflict cells there are: more open cells in the fork corridor, nothing else changes."""
    b = {**BASE, **base}
    return [Fork(**{**b, "conflicts": c}) for c in counts]


# family -> (its layouts, the Fork attribute it varies)
FAMILIES = {
    "first_move": (first_move_family(), "first_move"),
    "shared_prefix": (shared_prefix_family(), "prefix"),
    "conflicts": (conflicts_family(), "conflicts"),
}
LAYOUTS: dict[str, Fork] = {f.name: f for forks, _ in FAMILIES.values() for f in forks}  # the base is in every family
NAME = re.compile(r"fork-p(\d+)-c(\d+)-b(\d+)-s(\d+)-h(\d+)")


def parse_name(name: str) -> Fork:
    """``"fork-p2-c3-b4-s3-h3"`` -> ``Fork(prefix=2, conflicts=3, branch=4, suffix=3, half=3)``."""
    match = NAME.fullmatch(name)
    if match is None:
        raise ValueError(f"layout name {name!r} is not 'fork-p<prefix>-c<conflicts>-b<branch>-s<suffix>-h<half>'; "
                         f"the study's layouts are {sorted(LAYOUTS)}")
    return Fork(*(int(g) for g in match.groups()))


def load_layout(name: str) -> Maze:
    """A generated layout by name (any valid fork name, e.g. from ``LAYOUTS``), parsed and
    validated like every map."""
    return parse_maze(parse_name(name).text(), name=name)


def measure(maze: Maze) -> dict[str, int | bool]:
    """What the oracle sees in a two-agent maze: shared moves at the start and at the end of the
    (shortest) routes, conflict cells, route lengths, and whether each route is the only shortest one."""
    if maze.n_agents != 2:
        raise ValueError(f"measure needs a two-agent maze, {maze.name!r} has {maze.n_agents} agents")
    routes = [shortest_route(maze, k) for k in range(2)]
    best = optimal_actions(maze)

    def common(a, b) -> int:  # leading cells the two lists share
        n = 0
        while n < min(len(a), len(b)) and a[n] == b[n]:
            n += 1
        return n

    return {
        "shared_prefix": common(*routes) - 1,  # moves, not cells
        "shared_suffix": common(routes[0][::-1], routes[1][::-1]) - 1,
        "conflicts": len(conflict_cells(maze, 0, 1)),
        "first_move_conflict": maze.starts[0] in conflict_cells(maze, 0, 1),
        "route_red": len(routes[0]) - 1,
        "route_black": len(routes[1]) - 1,
        "unique_routes": all(best[k, cell].sum() == 1 for k in range(2) for cell in routes[k][:-1]),
    }


# --- the engine interface of envs/registry.py ------------------------------------------------

def check(name: str) -> None:
    parse_name(name)


def make_vec(name: str, n_envs: int, seed: int, max_steps: int):
    """The layout as a ``VecMaze`` (the maze has no randomness, so ``seed`` is unused)."""
    return make_maze_vec(load_layout(name), n_envs, max_steps)
