"""Maze maps as data: the text format, its validation, and the one move rule.

A map is a small text file. Header lines ``agents:`` and ``start:`` name the agents
(their types, in seat order) and their start cells ``row,col``; the grid follows:

    agents: red black
    start: 7,4 7,4
    #########
    ####*####
    ...

Terrain symbols (who may stand on them):

    #  wall       nobody
    .  open       everyone
    R  red cell   red only
    B  black cell black only
    U  blue trap  red and black, never blue
    *  star       everyone; the goal (exactly one)

Actions are 0 up, 1 down, 2 left, 3 right, 4 nop. A move into a cell the agent may
not stand on (or off the grid) leaves it where it is. An agent on the star stays there.

The team reward of a step is ``(1/n) * sum_k [1{k reaches the star now} - STEP_COST * 1{k was
not on the star before the step}]``: an agent on the star pays nothing.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

WALL, OPEN, RED, BLACK, TRAP, STAR = range(6)
SYMBOLS = {"#": WALL, ".": OPEN, "R": RED, "B": BLACK, "U": TRAP, "*": STAR}
N_TERRAIN = len(SYMBOLS)
ALLOWED = {
    "red": (OPEN, RED, TRAP, STAR),
    "black": (OPEN, BLACK, TRAP, STAR),
    "blue": (OPEN, STAR),
}
ACTIONS = ("up", "down", "left", "right", "nop")
MOVES = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (0, 0)])
N_ACTIONS = len(ACTIONS)
STEP_COST = 0.01

MAPS = {
    # Red detours left through red cells, black right through black cells; both then
    # climb the shared open column to the star (same observation, same best action).
    "black_red": """\
agents: red black
start: 7,4 7,4
#########
####*####
####.####
####.####
#.......#
#R#####B#
#R#####B#
#.......#
#########
""",
    # Red goes left through red cells; black right through its black/trap shortcut;
    # blue, barred from R, B and U cells, takes the long open way round on the right.
    # Red and black disagree along the whole bottom corridor, black and blue once.
    "black_blue_red": """\
agents: red black blue
start: 6,4 6,4 6,4
#########
#R*.....#
#R####U.#
#R####U.#
#R####U.#
#R####B.#
#.......#
#########
#########
""",
}


class MapError(ValueError):
    """A map text that does not describe a playable maze."""


@dataclass(frozen=True)
class Maze:
    """A parsed, validated maze. Cells are addressed by flat index ``row * width + col``."""

    name: str
    terrain: np.ndarray  # (H, W) int, values from SYMBOLS
    agents: tuple[str, ...]  # agent type per seat
    starts: tuple[int, ...]  # flat start cell per seat
    star: int = field(init=False)

    def __post_init__(self):
        object.__setattr__(self, "star", int(np.flatnonzero(self.terrain.ravel() == STAR)[0]))

    @property
    def shape(self) -> tuple[int, int]:
        return self.terrain.shape

    @property
    def n_agents(self) -> int:
        return len(self.agents)

    @property
    def n_cells(self) -> int:
        return self.terrain.size

    def cell(self, flat: int) -> tuple[int, int]:
        return divmod(int(flat), self.shape[1])

    @cached_property
    def passable(self) -> np.ndarray:
        """(n_agents, n_cells) bool: may seat k stand on cell c."""
        flat = self.terrain.ravel()
        return np.stack([np.isin(flat, ALLOWED[a]) for a in self.agents])

    @cached_property
    def next_cell(self) -> np.ndarray:
        """(n_agents, n_cells, N_ACTIONS) int: the move rule, tabulated once.

        Every consumer (vector core, oracle, exact engine) steps through this table, so
        the game has exactly one definition of movement.
        """
        h, w = self.shape
        rows, cols = np.divmod(np.arange(h * w), w)
        tr = np.clip(rows[:, None] + MOVES[:, 0], 0, h - 1)
        tc = np.clip(cols[:, None] + MOVES[:, 1], 0, w - 1)
        target = tr * w + tc  # (cells, actions)
        table = np.empty((self.n_agents, h * w, N_ACTIONS), dtype=np.int64)
        for k in range(self.n_agents):
            ok = self.passable[k][target]
            table[k] = np.where(ok, target, np.arange(h * w)[:, None])
            table[k, self.star] = self.star
        return table

    @cached_property
    def obs_table(self) -> np.ndarray:
        """(n_cells, obs_dim) float32: the observation of an agent standing on a cell.

        One-hot terrain of the 3 x 3 view (outside the grid reads as wall), then one-hot
        row and one-hot column. It carries no agent identity, so two agents on the same
        cell see the same thing.
        """
        h, w = self.shape
        padded = np.pad(self.terrain, 1, constant_values=WALL)
        rows, cols = np.divmod(np.arange(h * w), w)
        views = np.stack([padded[rows + dr, cols + dc] for dr in range(3) for dc in range(3)], 1)
        view_1hot = np.eye(N_TERRAIN, dtype=np.float32)[views].reshape(h * w, -1)
        return np.concatenate(
            [view_1hot, np.eye(h, dtype=np.float32)[rows], np.eye(w, dtype=np.float32)[cols]], 1
        )


def parse_maze(text: str, name: str = "custom") -> Maze:
    """Parse and validate a map text (see the module docstring for the format)."""
    header: dict[str, list[str]] = {}
    given: dict[str, list[int]] = {}  # the line numbers of each header key
    grid: list[str] = []
    for number, raw in enumerate(text.removeprefix("\ufeff").splitlines(), 1):  # a byte-order mark is no cell
        line = raw.rstrip()
        if not line:
            continue
        key, sep, value = line.partition(":")
        if sep and key.strip() in ("agents", "start"):
            if grid:
                raise MapError(f"map {name!r} has its {key.strip()!r} line after the grid; the header lines "
                               "'agents: ...' and 'start: ...' come first")
            header[key.strip()] = value.split()
            given.setdefault(key.strip(), []).append(number)
        else:
            grid.append(line)
    twice = {key: lines for key, lines in given.items() if len(lines) > 1}
    if twice:  # a second line would silently replace the first
        key, lines = next(iter(twice.items()))
        raise MapError(f"map {name!r} gives its {key!r} line {len(lines)} times (lines {lines}); give each header "
                       "line once")
    if not grid:
        raise MapError(f"map {name!r} has no grid rows")
    widths = {len(r) for r in grid}
    if len(widths) != 1:
        raise MapError(f"map {name!r} has ragged rows: widths {sorted(widths)}; every row must be equally long")
    unknown = sorted({ch for r in grid for ch in r} - set(SYMBOLS))
    if unknown:
        raise MapError(f"map {name!r} has unknown symbols {unknown}; allowed are {sorted(SYMBOLS)}")
    terrain = np.array([[SYMBOLS[ch] for ch in r] for r in grid], dtype=np.int64)
    n_stars = int((terrain == STAR).sum())
    if n_stars != 1:
        raise MapError(f"map {name!r} must have exactly one star '*', found {n_stars}")

    agents = tuple(header.get("agents", []))
    if not agents:
        raise MapError(f"map {name!r} needs a header line 'agents: <type> ...' with types from {sorted(ALLOWED)}")
    bad = [a for a in agents if a not in ALLOWED]
    if bad:
        raise MapError(f"map {name!r} names unknown agent types {bad}; allowed are {sorted(ALLOWED)}")
    start_words = header.get("start", [])
    if len(start_words) != len(agents):
        raise MapError(
            f"map {name!r} gives {len(start_words)} start cells for {len(agents)} agents; "
            "write 'start: row,col ...' with one cell per agent"
        )
    h, w = terrain.shape
    starts = []
    for agent, word in zip(agents, start_words):
        try:
            r, c = (int(v) for v in word.split(","))
        except ValueError:
            raise MapError(f"map {name!r}: start {word!r} of {agent} is not 'row,col'") from None
        if not (0 <= r < h and 0 <= c < w):
            raise MapError(f"map {name!r}: start {word} of {agent} lies outside the {h} x {w} grid")
        if terrain[r, c] not in ALLOWED[agent] or terrain[r, c] == STAR:
            raise MapError(
                f"map {name!r}: {agent} may not start on {word} ({grid[r][c]!r}); "
                f"a {agent} agent stands on {[s for s, t in SYMBOLS.items() if t in ALLOWED[agent] and t != STAR]}"
            )
        starts.append(r * w + c)
    maze = Maze(name=name, terrain=terrain, agents=agents, starts=tuple(starts))
    for k, agent in enumerate(agents):
        if not reachable(maze.next_cell[k], maze.starts[k])[maze.star]:
            raise MapError(f"map {name!r}: the {agent} agent can never reach the star from {start_words[k]}")
    return maze


def reachable(table: np.ndarray, start: int) -> np.ndarray:
    """(n_cells,) bool: the cells one seat's move table can reach from ``start``."""
    seen = np.zeros(table.shape[0], dtype=bool)
    seen[start] = True
    frontier = np.array([start])
    while frontier.size:
        nxt = np.unique(table[frontier].ravel())
        frontier = nxt[~seen[nxt]]
        seen[frontier] = True
    return seen


def load_maze(name_or_text: str) -> Maze:
    """A built-in map by name (see ``MAPS``) or a map text containing a grid."""
    if name_or_text in MAPS:
        return parse_maze(MAPS[name_or_text], name=name_or_text)
    if "\n" not in name_or_text:
        raise MapError(f"unknown map {name_or_text!r}; built-in maps are {sorted(MAPS)} (or pass a map text)")
    return parse_maze(name_or_text)
