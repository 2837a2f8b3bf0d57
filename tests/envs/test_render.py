"""render.episode_animation: one frame per step of the longest episode, one disc per agent per
panel in the agent's colour at the agent's cell, and HTML that needs no network."""
import re

import numpy as np
import pytest
from matplotlib.animation import FuncAnimation

from oapo_lite.envs import load_maze, render


def _discs(ax):
    return [line for line in ax.get_lines() if line.get_marker() == "o"]


def test_episode_animation_frames_markers_and_offline_html():
    maze = load_maze("black_red")
    start, star = maze.starts, maze.star
    # flat cells for one label, (row, col) pairs for the other; seat 0 is red, seat 1 black
    short = [list(start), [start[0] - 1, start[1] + 1], [start[0] - 2, start[1] + 2]]
    long = [[(7, 4), (7, 4)], [(7, 3), (7, 4)], [(7, 2), (7, 5)], [(7, 1), (7, 6)], [(6, 1), (7, 7)]]
    anim = render.episode_animation(maze, {"mappo": short, "oappo": long}, title="test")
    assert isinstance(anim, FuncAnimation)
    assert len(list(anim.new_frame_seq())) == len(long) == 5

    axes = anim._fig.axes
    assert len(axes) == 2
    anim._init_func()
    for k in range(5):
        anim._func(k)
        for ax, traj in zip(axes, (short, long)):
            discs = _discs(ax)
            assert len(discs) == maze.n_agents  # one marker per agent per panel
            assert [d.get_color() for d in discs] == [render.AGENT_COLOURS[a] for a in maze.agents]
            step = traj[min(k, len(traj) - 1)]  # a shorter episode stays on its last step
            for seat, disc in enumerate(discs):
                row, col = maze.cell(step[seat]) if np.ndim(step[seat]) == 0 else step[seat]
                x, y = disc.get_xdata()[0], disc.get_ydata()[0]
                assert abs(x - col) < 0.5 and abs(y - row) < 0.5  # drawn inside the agent's cell
            assert f"step {min(k, len(traj) - 1)} of {len(traj) - 1}" in ax.get_title()
    # the star panel title: every agent on the star at the last step of an arrived episode
    arrived = render.episode_animation(maze, {"happo": [list(start), [star, star]]})
    arrived._func(1)
    assert "every agent on the star" in arrived._fig.axes[0].get_title()

    html = anim.to_jshtml()
    assert "https://" not in html and "http://" not in html and 'class="fa' not in html
    assert len(re.findall(r'frames\[\d+\] = "data:image/png;base64,', html)) == 5
    arrived.to_jshtml()  # rendered, so matplotlib does not warn that it was never drawn


def test_episode_animation_rejects_a_trajectory_of_the_wrong_shape():
    maze = load_maze("black_red")
    with pytest.raises(ValueError, match="trajectory 'mappo'"):
        render.episode_animation(maze, {"mappo": [[maze.starts[0]]]})
    with pytest.raises(ValueError, match="at least one"):
        render.episode_animation(maze, {})
