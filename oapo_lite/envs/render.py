"""Pictures of a maze with every seat's optimal route (the paper's Fig. 3a and 5a)."""
from __future__ import annotations

import matplotlib.patheffects as pe
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from .core import as_maze
from .maps import BLACK, OPEN, RED, STAR, TRAP, WALL, Maze
from .oracle import shortest_route

# indexed by terrain code (WALL, OPEN, RED, BLACK, TRAP, STAR)
TERRAIN_COLOURS = {WALL: "#5a5a5a", OPEN: "#ffffff", RED: "#f4a3a3", BLACK: "#1c1c1c", TRAP: "#a8d8f0", STAR: "#ffffff"}
TERRAIN_NAMES = {WALL: "wall", RED: "red cell", BLACK: "black cell", TRAP: "blue trap"}
AGENT_COLOURS = {"red": "#d62728", "black": "#000000", "blue": "#1f5fd6"}
ROUTE_SPREAD = 0.14  # cells between neighbouring seats' polylines, so shared stretches stay visible


def draw_maze(maze: Maze | str, routes: list[list[int]] | None = None, ax=None, title: str | None = None):
    """Draw terrain, star, start cells and one route per seat (the oracle's by default).

    ``routes[k]`` is a list of flat cells for seat k. Returns the matplotlib axes.
    """
    maze = as_maze(maze)
    if routes is None:
        routes = [shortest_route(maze, k) for k in range(maze.n_agents)]
    if len(routes) != maze.n_agents:
        raise ValueError(f"routes must hold one route per seat ({maze.n_agents}), got {len(routes)}")
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(5, 5))
    h, w = maze.shape
    cmap = ListedColormap([TERRAIN_COLOURS[code] for code in sorted(TERRAIN_COLOURS)])
    ax.imshow(maze.terrain, cmap=cmap, vmin=-0.5, vmax=len(TERRAIN_COLOURS) - 0.5, interpolation="nearest")
    ax.set_xticks(np.arange(-0.5, w), minor=True)
    ax.set_yticks(np.arange(-0.5, h), minor=True)
    ax.grid(which="minor", color="#b0b0b0", linewidth=0.6)
    ax.tick_params(which="both", length=0, labelbottom=False, labelleft=False)

    handles = [Patch(facecolor=TERRAIN_COLOURS[code], edgecolor="#b0b0b0", label=name)
               for code, name in TERRAIN_NAMES.items() if (maze.terrain == code).any()]
    star_r, star_c = maze.cell(maze.star)
    ax.plot(star_c, star_r, marker="*", markersize=22, color="gold", markeredgecolor="#8a6d00", linestyle="none", zorder=5)
    handles.append(Line2D([], [], marker="*", markersize=14, color="gold", markeredgecolor="#8a6d00",
                          linestyle="none", label="star"))
    offsets = (np.arange(maze.n_agents) - (maze.n_agents - 1) / 2) * ROUTE_SPREAD
    outline = [pe.withStroke(linewidth=3.6, foreground="white")]  # keeps the black route visible on black cells
    for k, (agent, route, off) in enumerate(zip(maze.agents, routes, offsets)):
        colour = AGENT_COLOURS[agent]
        rows, cols = np.divmod(np.asarray(route), w)
        ax.plot(cols + off, rows + off, color=colour, linewidth=2.4, path_effects=outline,
                label=f"{agent} {k}: {len(route) - 1} steps")
        start_r, start_c = maze.cell(maze.starts[k])
        ax.plot(start_c + off, start_r + off, marker="o", markersize=9, color=colour,
                markeredgecolor="white", linestyle="none")
    handles += ax.get_legend_handles_labels()[0]
    handles.append(Line2D([], [], marker="o", markersize=8, color="grey", markeredgecolor="white",
                          linestyle="none", label="start"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, fontsize=8)
    ax.set_title(title if title is not None else maze.name)
    return ax


def save_maze_png(maze: Maze | str, path, routes: list[list[int]] | None = None, dpi: int = 120) -> None:
    """Write ``draw_maze`` to a PNG file, without touching pyplot's global state."""
    fig = Figure(figsize=(6.5, 4.5), layout="constrained")
    draw_maze(maze, routes=routes, ax=fig.add_subplot())
    fig.savefig(path, dpi=dpi)
