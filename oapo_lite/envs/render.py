"""Pictures of a maze: every seat's optimal route (the paper's Fig. 3a and 5a), and episodes
played on it as an animation."""
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


def episode_animation(maze, trajectories: dict, title: str | None = None, interval: int = 350,
                      figsize: tuple[float, float] | None = None, dpi: int = 72, label_colours: dict | None = None):
    """One episode per label, side by side, as a ``matplotlib.animation.FuncAnimation``.

    ``maze``: a ``Maze`` or a built-in map name. ``trajectories``: label -> where every agent
    stands at every step, ``[[seat 0, seat 1, ...] at step 0 (the start cells), at step 1, ...]``,
    each position a flat cell or a ``(row, col)`` pair. Frame k shows step k of every episode (an
    episode that ended earlier stays on its last step), so there are as many frames as the longest
    trajectory has steps. Every agent is a disc in its colour (``AGENT_COLOURS``) with the path it
    has walked so far as a thin line; the seats are drawn slightly apart, so agents on one cell
    stay visible. Each panel's title (in the label's colour from ``label_colours``, else black)
    counts the steps and says how many agents are on the star.

    The figure is not pyplot's, so nothing is shown twice in a notebook. Its ``to_jshtml()``
    gives HTML that needs no network: matplotlib's own links a CDN stylesheet (Font Awesome)
    for its button icons; here that link is dropped and the icons are Unicode characters. Its
    PNG frames are stored on 64 colours, a third of the bytes (the maze has few colours).
    """
    import base64
    import io
    import re

    from matplotlib.animation import FuncAnimation

    maze = as_maze(maze)
    h, w = maze.shape
    n = maze.n_agents
    paths = {}
    for label, steps in trajectories.items():
        rc = np.array([[maze.cell(p) if np.ndim(p) == 0 else tuple(p) for p in step] for step in steps], float)
        if rc.ndim != 3 or rc.shape[1:] != (n, 2) or len(rc) == 0:
            raise ValueError(f"trajectory {label!r}: every step must give the {n} agents' positions "
                             f"(a flat cell or (row, col) each), got shape {np.shape(steps)}")
        paths[label] = rc
    if not paths:
        raise ValueError("episode_animation needs at least one trajectory")
    frames = max(len(rc) for rc in paths.values())
    star = np.array(maze.cell(maze.star), float)

    title_inches = 0.25 * (title.count("\n") + 1) if title else 0.0  # room for the title's lines
    fig = Figure(figsize=figsize or (3.6 * len(paths) + 0.4, 4.0 + title_inches), dpi=dpi)
    axes = fig.subplots(1, len(paths), squeeze=False)[0]
    height = fig.get_figheight()
    fig.subplots_adjust(left=0.02, right=0.98, top=1 - (0.5 + title_inches) / height, bottom=0.55 / height,
                        wspace=0.08)
    if title:
        fig.suptitle(title)
    cmap = ListedColormap([TERRAIN_COLOURS[code] for code in sorted(TERRAIN_COLOURS)])
    offset = (np.arange(n) - (n - 1) / 2) * 0.2  # seat k sits this far right of and below its cell's centre
    colours = [AGENT_COLOURS[a] for a in maze.agents]
    outline = [pe.withStroke(linewidth=3.2, foreground="white")]  # a black path stays visible on black cells
    panels = []
    for ax, (label, rc) in zip(axes, paths.items()):
        ax.imshow(maze.terrain, cmap=cmap, vmin=-0.5, vmax=len(TERRAIN_COLOURS) - 0.5, interpolation="nearest")
        ax.set_xticks(np.arange(-0.5, w), minor=True)
        ax.set_yticks(np.arange(-0.5, h), minor=True)
        ax.grid(False)
        ax.grid(which="minor", color="#b0b0b0", linewidth=0.6)
        ax.tick_params(which="both", length=0, labelbottom=False, labelleft=False)
        ax.plot(star[1], star[0], marker="*", markersize=20, color="gold", markeredgecolor="#8a6d00",
                linestyle="none", zorder=3)
        trails = [ax.plot([], [], color=c, lw=1.6, zorder=4, path_effects=outline)[0] for c in colours]
        discs = [ax.plot([], [], marker="o", markersize=11, color=c, markeredgecolor="white", markeredgewidth=1.5,
                         linestyle="none", zorder=5)[0] for c in colours]
        panels.append((ax, str(label), rc, trails, discs))

    def update(k: int):
        artists = []
        for ax, label, rc, trails, discs in panels:
            s = min(k, len(rc) - 1)
            for seat in range(n):
                rows, cols = rc[: s + 1, seat, 0] + offset[seat], rc[: s + 1, seat, 1] + offset[seat]
                trails[seat].set_data(cols, rows)
                discs[seat].set_data([cols[-1]], [rows[-1]])
            arrived = (rc[s] == star).all(axis=1)
            note = "every agent on the star" if arrived.all() else f"{int(arrived.sum())} of {n} on the star"
            ax.set_title(f"{label}\nstep {s} of {len(rc) - 1}: {note}", fontsize=10, color=(label_colours or {}).get(label, "black"))
            artists += [*trails, *discs, ax.title]
        return artists

    handles = [Line2D([], [], marker="o", markersize=9, color=c, markeredgecolor="white", linestyle="none",
                      label=f"{a} agent") for a, c in {a: AGENT_COLOURS[a] for a in maze.agents}.items()]
    handles.append(Line2D([], [], marker="*", markersize=13, color="gold", markeredgecolor="#8a6d00",
                          linestyle="none", label="star"))
    handles += [Patch(facecolor=TERRAIN_COLOURS[code], edgecolor="#b0b0b0", label=name)
                for code, name in TERRAIN_NAMES.items() if (maze.terrain == code).any()]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), frameon=False, fontsize=8,
               handletextpad=0.3, columnspacing=0.9)
    anim = FuncAnimation(fig, update, frames=frames, init_func=lambda: update(0), interval=interval, blit=False)

    icons = {"fa fa-minus": "&minus;", "fa fa-fast-backward": "&#9646;&#9664;", "fa fa-step-backward": "&#9665;",
             "fa fa-play fa-flip-horizontal": "&#9664;", "fa fa-pause": "&#9646;&#9646;", "fa fa-play": "&#9654;",
             "fa fa-step-forward": "&#9655;", "fa fa-fast-forward": "&#9654;&#9646;", "fa fa-plus": "+"}
    matplotlib_jshtml = anim.to_jshtml

    def smaller(match) -> str:  # one base64 PNG frame, again on 64 colours
        from PIL import Image

        out = io.BytesIO()
        frame = Image.open(io.BytesIO(base64.b64decode(match.group(1)))).convert("RGB")
        frame.quantize(64, method=Image.Quantize.FASTOCTREE).save(out, "png")
        return f"data:image/png;base64,{base64.b64encode(out.getvalue()).decode()}"

    def to_jshtml(fps=None, embed_frames=True, default_mode=None):
        html = matplotlib_jshtml(fps, embed_frames, default_mode)
        html = re.sub(r'<link rel="stylesheet"\s+href="https?://[^"]*">', "", html)
        html = re.sub(r"data:image/png;base64,([A-Za-z0-9+/=\s\\]+)", smaller, html)
        return re.sub(r'<i class="(fa [^"]*)"></i>', lambda m: icons.get(m.group(1), ""), html)

    anim.to_jshtml = to_jshtml
    return anim
