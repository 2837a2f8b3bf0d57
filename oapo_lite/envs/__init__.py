"""Every engine behind one vector interface (``vec``; real engines by name through ``registry``),
and the maze games of Section 6.1: map format and rules, vectorised core, search oracle,
pictures and episode animations, PettingZoo view."""
from .core import VecMaze, make_vec
from .maps import ACTIONS, MAPS, STEP_COST, Maze, MapError, load_maze, parse_maze
from .oracle import conflict_cells, distances, one_policy_return, optimal_actions, optimal_return, shortest_route
from .parallel import MazeParallelEnv
from .render import draw_maze, save_maze_png
from .vec import VecStep

__all__ = [
    "ACTIONS", "MAPS", "STEP_COST", "MapError", "Maze", "MazeParallelEnv", "VecMaze", "VecStep",
    "conflict_cells", "distances", "draw_maze", "load_maze", "make_vec", "one_policy_return",
    "optimal_actions", "optimal_return", "parse_maze", "save_maze_png", "shortest_route",
]
