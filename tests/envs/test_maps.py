"""The map format: parsing, the move rule, observations, and a clear MapError for every malformed map."""
import numpy as np
import pytest

from oapo_lite.envs import MAPS, MapError, load_maze, parse_maze
from oapo_lite.envs.maps import ALLOWED, MOVES, SYMBOLS

GOOD = """\
agents: red black
start: 3,2 3,2
#####
#.*.#
#R.B#
#...#
#####
"""


def test_good_map_parses():
    maze = parse_maze(GOOD, name="tiny")
    assert maze.shape == (5, 5)
    assert maze.agents == ("red", "black")
    assert maze.starts == (17, 17)
    assert maze.cell(maze.star) == (1, 2)


@pytest.mark.parametrize("name", sorted(MAPS))
def test_builtin_maps_load(name):
    maze = load_maze(name)
    assert maze.name == name
    assert maze.shape == (9, 9)  # Section 6.1: a 9 x 9 map
    assert len(set(maze.starts)) == 1  # all seats start together, so their first observations coincide


@pytest.mark.parametrize(
    "text, fragment",
    [
        (GOOD.replace("#R.B#", "#RxB#"), "unknown symbols ['x']"),
        (GOOD.replace("*", "."), "exactly one star '*', found 0"),
        (GOOD.replace("#...#", "#.*.#"), "exactly one star '*', found 2"),
        (GOOD.replace("start: 3,2 3,2", "start: 2,3 3,2"), "red may not start on 2,3 ('B')"),
        (GOOD.replace("start: 3,2 3,2", "start: 3,2 0,0"), "black may not start on 0,0 ('#')"),
        (GOOD.replace("start: 3,2 3,2", "start: 3,2 1,2"), "black may not start on 1,2 ('*')"),
        (GOOD.replace("#.*.#\n#R.B#", "#B*B#\n#R#B#"), "the red agent can never reach the star from 3,2"),
        (GOOD.replace("#R.B#", "#R.B##"), "ragged rows: widths [5, 6]"),
        (GOOD.replace("agents: red black\n", ""), "needs a header line 'agents:"),
        (GOOD.replace("agents: red black", "agents: red green"), "unknown agent types ['green']"),
        (GOOD.replace("start: 3,2 3,2", "start: 3,2"), "gives 1 start cells for 2 agents"),
        (GOOD.replace("start: 3,2 3,2", "start: 3,2 3;2"), "start '3;2' of black is not 'row,col'"),
        (GOOD.replace("start: 3,2 3,2", "start: 3,2 9,9"), "start 9,9 of black lies outside the 5 x 5 grid"),
        ("agents: red\nstart: 1,1\n", "has no grid rows"),
    ],
)
def test_malformed_maps_raise_helpful_errors(text, fragment):
    with pytest.raises(MapError) as err:
        parse_maze(text, name="bad")
    assert fragment in str(err.value)


def test_unknown_name_lists_builtin_maps():
    with pytest.raises(MapError, match="built-in maps are"):
        load_maze("no_such_map")


@pytest.mark.parametrize("name", sorted(MAPS))
def test_move_table_matches_the_rule_cell_by_cell(name):
    # The rule in words: move unless the target is off the grid or forbidden; the star absorbs.
    maze = load_maze(name)
    h, w = maze.shape
    inv = {v: k for k, v in SYMBOLS.items()}
    for k, agent in enumerate(maze.agents):
        for cell in range(maze.n_cells):
            r, c = maze.cell(cell)
            for a, (dr, dc) in enumerate(MOVES):
                tr, tc = r + dr, c + dc
                inside = 0 <= tr < h and 0 <= tc < w
                allowed = inside and maze.terrain[tr, tc] in ALLOWED[agent]
                expected = cell if cell == maze.star or not allowed else tr * w + tc
                assert maze.next_cell[k, cell, a] == expected, (agent, inv[maze.terrain[r, c]], (r, c), a)


@pytest.mark.parametrize("name", sorted(MAPS))
def test_observation_is_local_view_plus_location(name):
    maze = load_maze(name)
    h, w = maze.shape
    obs = maze.obs_table
    assert obs.shape == (maze.n_cells, 9 * len(SYMBOLS) + h + w)
    assert set(np.unique(obs)) <= {0.0, 1.0}
    # every 3 x 3 view slot holds exactly one terrain, and location makes every cell distinct
    assert (obs[:, : 9 * len(SYMBOLS)].reshape(maze.n_cells, 9, -1).sum(-1) == 1).all()
    assert len(np.unique(obs, axis=0)) == maze.n_cells
    r, c = maze.cell(maze.starts[0])
    view = obs[maze.starts[0], : 9 * len(SYMBOLS)].reshape(3, 3, -1).argmax(-1)
    assert (view == maze.terrain[r - 1 : r + 2, c - 1 : c + 2]).all()
