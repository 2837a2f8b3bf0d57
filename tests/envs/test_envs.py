"""Maze core, oracle, PettingZoo view and pictures, each against something independent of itself."""
import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from oapo_lite.envs import (
    MAPS, STEP_COST, MazeParallelEnv, VecMaze, conflict_cells, distances, load_maze, make_vec,
    one_policy_return, optimal_actions, optimal_return, save_maze_png, shortest_route,
)
from oapo_lite.envs.layouts import load_layout
from oapo_lite.envs.maps import ALLOWED, STAR, WALL

NAMES = sorted(MAPS)
UP, DOWN, LEFT, RIGHT, NOP = range(5)
STEP_OF = {UP: (-1, 0), DOWN: (1, 0), LEFT: (0, -1), RIGHT: (0, 1), NOP: (0, 0)}


class LoopMaze:
    """One maze episode written out with plain loops and the rules as stated in words."""

    def __init__(self, maze, max_steps):
        self.maze, self.max_steps = maze, max_steps
        self.h, self.w = maze.shape

    def reset(self):
        self.pos = [divmod(s, self.w) for s in self.maze.starts]
        self.t, self.ret = 0, 0.0

    def obs(self):
        out = []
        for r, c in self.pos:
            view = []
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    rr, cc = r + dr, c + dc
                    inside = 0 <= rr < self.h and 0 <= cc < self.w
                    view.append(np.eye(6)[self.maze.terrain[rr, cc] if inside else WALL])
            out.append(np.concatenate(view + [np.eye(self.h)[r], np.eye(self.w)[c]]))
        return np.array(out)

    def state(self):
        s = []
        for r, c in self.pos:
            s.extend(np.eye(self.h * self.w)[r * self.w + c])
        return np.array(s + [self.t / self.max_steps])

    def on_star(self, p):
        return self.maze.terrain[p] == STAR

    def step(self, actions):
        reward = 0.0
        for k, a in enumerate(actions):
            if self.on_star(self.pos[k]):
                continue
            r, c = self.pos[k][0] + STEP_OF[a][0], self.pos[k][1] + STEP_OF[a][1]
            if 0 <= r < self.h and 0 <= c < self.w and self.maze.terrain[r, c] in ALLOWED[self.maze.agents[k]]:
                self.pos[k] = (r, c)
            reward += float(self.on_star(self.pos[k])) - STEP_COST
        reward /= self.maze.n_agents
        self.t += 1
        self.ret += reward
        terminated = all(self.on_star(p) for p in self.pos)
        truncated = self.t >= self.max_steps and not terminated
        return reward, terminated, truncated


def policy_actions(maze, cells, rng, p_greedy):
    """Oracle moves mixed with random ones, so that episodes both end and time out."""
    best = optimal_actions(maze)[np.arange(maze.n_agents), cells]
    greedy = np.argmax(best, axis=-1)
    return np.where(rng.random(cells.shape) < p_greedy, greedy, rng.integers(0, 5, cells.shape))


def play_routes(vec):
    """Every seat follows its oracle route, then waits; returns the steps taken."""
    routes = [shortest_route(vec.maze, k) for k in range(vec.n_agents)]
    moves = []
    for k, route in enumerate(routes):
        moves.append([next(a for a in range(5) if vec.maze.next_cell[k, c, a] == n) for c, n in zip(route, route[1:])])
    length = max(len(m) for m in moves)
    actions = np.array([m + [NOP] * (length - len(m)) for m in moves]).T  # (steps, seats)
    return [vec.step(np.tile(a, (vec.n_envs, 1))) for a in actions]


# ---------------------------------------------------------------- VecMaze


@pytest.mark.parametrize("name", NAMES)
def test_vec_matches_loop_reference(name):
    maze, n_envs, max_steps = load_maze(name), 5, 20
    vec = VecMaze(maze, n_envs, max_steps)
    refs = [LoopMaze(maze, max_steps) for _ in range(n_envs)]
    out = vec.reset()
    for ref in refs:
        ref.reset()
    rng = np.random.default_rng(0)
    ended = {"terminated": 0, "truncated": 0}
    for _ in range(300):
        assert np.array_equal(out.obs, np.stack([ref.obs() for ref in refs]))
        assert np.array_equal(out.state, np.stack([ref.state() for ref in refs]).astype(np.float32))
        assert out.avail.all()
        actions = policy_actions(maze, vec.cells, rng, p_greedy=np.linspace(1.0, 0.2, n_envs)[:, None])
        out = vec.step(actions)
        for i, ref in enumerate(refs):
            reward, terminated, truncated = ref.step(actions[i])
            assert out.reward[i] == pytest.approx(reward, abs=1e-7)
            assert (out.terminated[i], out.truncated[i]) == (terminated, truncated)
            assert np.array_equal(out.final_obs[i], ref.obs())
            assert np.array_equal(out.final_state[i], ref.state().astype(np.float32))
            if terminated or truncated:
                assert out.episode_return[i] == pytest.approx(ref.ret, abs=1e-6)
                assert out.episode_success[i] == float(terminated)
                ended["terminated" if terminated else "truncated"] += 1
                ref.reset()
            else:
                assert np.isnan(out.episode_return[i]) and np.isnan(out.episode_success[i])
                assert np.array_equal(out.obs[i], out.final_obs[i]) and np.array_equal(out.state[i], out.final_state[i])
    assert ended["terminated"] > 5 and ended["truncated"] > 5  # both kinds of ending were exercised


def test_truncation_and_auto_reset():
    vec = make_vec("black_red", n_envs=2, max_steps=7)
    first = vec.reset()
    for t in range(1, 8):
        out = vec.step(np.full((2, 2), NOP))
        assert out.truncated.all() == (t == 7) and not out.terminated.any()
    assert np.allclose(out.episode_return, -STEP_COST * 7)
    assert (out.episode_success == 0.0).all()
    assert (out.final_state[:, -1] == 1.0).all()  # the ended episode's clock ran out
    assert np.array_equal(out.obs, first.obs) and np.array_equal(out.state, first.state)  # already reset
    assert (vec.t == 0).all()


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("gamma", [1.0, 0.99, 0.9])
def test_oracle_routes_earn_the_optimal_return(name, gamma):
    vec = make_vec(name, n_envs=3)
    vec.reset()
    outs = play_routes(vec)
    last = outs[-1]
    assert last.terminated.all() and (last.episode_success == 1.0).all()
    assert not any(o.terminated.any() or o.truncated.any() for o in outs[:-1])
    rewards = np.array([o.reward[0] for o in outs], dtype=np.float64)
    assert last.episode_return[0] == pytest.approx(optimal_return(vec.maze), abs=1e-6)
    assert np.sum(gamma ** np.arange(len(rewards)) * rewards) == pytest.approx(optimal_return(vec.maze, gamma), abs=1e-6)


def test_get_state_set_state_continues_bit_exactly():
    rng = np.random.default_rng(1)
    a, b = make_vec("black_blue_red", 4, max_steps=9), make_vec("black_blue_red", 4, max_steps=9)
    a.reset()
    b.reset()
    for _ in range(13):
        a.step(rng.integers(0, 5, (4, 3)))
    b.set_state(a.get_state())
    for _ in range(40):
        actions = policy_actions(a.maze, a.cells, rng, p_greedy=0.7)
        oa, ob = a.step(actions), b.step(actions)
        for field in ("obs", "state", "reward", "terminated", "truncated", "final_state", "episode_return"):
            assert np.array_equal(getattr(oa, field), getattr(ob, field), equal_nan=field == "episode_return"), field


@pytest.mark.parametrize(
    "actions, error, fragment",
    [
        (np.zeros((3, 2), dtype=int), ValueError, "shape (n_envs, n_agents) = (2, 2)"),
        (np.zeros((2, 2)), TypeError, "must be integers"),
        (np.array([[0, 5], [0, 0]]), ValueError, "got [5]"),
        (np.array([[0, -1], [0, 0]]), ValueError, "got [-1]"),
    ],
)
def test_bad_actions_raise(actions, error, fragment):
    vec = make_vec("black_red", 2)
    vec.reset()
    with pytest.raises(error) as err:
        vec.step(actions)
    assert fragment in str(err.value)


def test_bad_set_state_raises():
    vec = make_vec("black_red", 2)
    good = vec.get_state()
    with pytest.raises(ValueError, match="keys"):
        vec.set_state({"cells": good["cells"]})
    with pytest.raises(ValueError, match="may not stand"):
        vec.set_state({**good, "cells": np.zeros((2, 2), dtype=int)})  # cell 0 is a wall
    with pytest.raises(ValueError, match="shape"):
        vec.set_state({**good, "t": np.zeros(3, dtype=int)})


# ---------------------------------------------------------------- oracle


@pytest.mark.parametrize("name", NAMES)
def test_bfs_distances_equal_bellman_ford(name):
    maze = load_maze(name)
    d = np.full((maze.n_agents, maze.n_cells), np.inf)
    d[:, maze.star] = 0.0
    while True:  # relax d(c) <- 1 + min_a d(next(c, a)) until nothing changes
        new = np.minimum(d, 1.0 + np.take_along_axis(d, maze.next_cell.reshape(maze.n_agents, -1), 1)
                         .reshape(maze.next_cell.shape).min(-1))
        new[:, maze.star] = 0.0
        if np.array_equal(new, d):
            break
        d = new
    d[~maze.passable] = np.inf
    assert np.array_equal(distances(maze), d)


def test_distances_by_hand():
    # Counted on the maps: black_red both 3 sideways + 3 up + 3 across + 3 up; black_blue_red
    # red 3 + 5 + 1, black 2 + 5 + 4, blue 3 + 5 + 5.
    for name, expected in (("black_red", [12, 12]), ("black_blue_red", [9, 11, 13])):
        maze = load_maze(name)
        assert distances(maze)[np.arange(maze.n_agents), list(maze.starts)].tolist() == expected


@pytest.mark.parametrize("name", NAMES)
def test_routes_are_valid_and_shortest(name):
    maze = load_maze(name)
    d = distances(maze)
    for k in range(maze.n_agents):
        route = shortest_route(maze, k)
        assert route[0] == maze.starts[k] and route[-1] == maze.star
        assert len(route) == d[k, maze.starts[k]] + 1
        for c, n in zip(route, route[1:]):
            assert n in maze.next_cell[k, c]


@pytest.mark.parametrize("name", NAMES)
def test_any_optimal_action_sequence_reaches_the_star_in_d_steps(name):
    maze, rng = load_maze(name), np.random.default_rng(2)
    best, d = optimal_actions(maze), distances(maze)
    for k in range(maze.n_agents):
        for start in np.flatnonzero(np.isfinite(d[k])):
            cell, steps = start, 0
            while cell != maze.star:
                cell = maze.next_cell[k, cell, rng.choice(np.flatnonzero(best[k, cell]))]
                steps += 1
            assert steps == d[k, start]


def test_bad_seat_raises():
    with pytest.raises(ValueError, match="seat must be an integer in 0..1"):
        shortest_route(load_maze("black_red"), 2)


# ---------------------------------------------------------------- PettingZoo view


@pytest.mark.parametrize("name", NAMES)
def test_parallel_api(name):
    env = MazeParallelEnv(name, max_steps=30)
    parallel_api_test(env, num_cycles=100)
    env.reset(seed=0)
    assert env.state().shape == env.state_space.shape == (env.maze.n_agents * env.maze.n_cells + 1,)
    assert env.possible_agents == [f"{a}_{k}" for k, a in enumerate(env.maze.agents)]


def test_parallel_env_plays_the_optimal_episode():
    env = MazeParallelEnv("black_blue_red")
    obs, _ = env.reset()
    vec = make_vec("black_blue_red", 1)
    vec.reset()
    total, steps = 0.0, 0
    while env.agents:
        seats = np.argmax(env.state()[:-1].reshape(env.maze.n_agents, -1), axis=1)
        greedy = np.argmax(optimal_actions(env.maze)[np.arange(env.maze.n_agents), seats], axis=-1)
        obs, rewards, terms, truncs, infos = env.step(dict(zip(env.possible_agents, greedy.tolist())))
        ref = vec.step(greedy[None])
        assert all(np.array_equal(obs[a], ref.final_obs[0, k]) for k, a in enumerate(env.possible_agents))
        assert len(set(rewards.values())) == 1  # one team reward for everyone
        total += rewards["red_0"]
        steps += 1
    assert steps == 13 and all(terms.values()) and not any(truncs.values())
    assert total == pytest.approx(optimal_return(env.maze), abs=1e-6)
    assert infos["blue_2"]["episode_success"] == 1.0
    with pytest.raises(RuntimeError, match="call reset"):
        env.step({})


def test_parallel_render_returns_a_picture():
    env = MazeParallelEnv("black_red", render_mode="rgb_array")
    env.reset()
    env.step({"red_0": LEFT, "black_1": RIGHT})
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0
    with pytest.raises(ValueError, match="render_mode"):
        MazeParallelEnv("black_red", render_mode="human")


# ---------------------------------------------------------------- the paper's maze properties


def test_black_red_shared_policy_cannot_be_optimal():
    """Both seats start on one cell, so a shared policy gives them one first-action distribution p.

    Seats do not interact, so the team return is the mean of per-seat returns, and seat k's
    return is at most 1 - STEP_COST * T_k with T_k its arrival step. After first action a,
    T_k >= 1 + d_k(next_k(a)). Hence J(shared) <= sum_a p_a * mean_k [1 - STEP_COST * (1 +
    d_k(next_k(a)))], which is linear in p, so its maximum over the simplex is at a vertex.
    """
    maze = load_maze("black_red")
    start = maze.starts[0]
    best, d = optimal_actions(maze), distances(maze)
    red, black = best[0, start], best[1, start]
    assert red.any() and black.any() and not (red & black).any()  # disjoint optimal first moves
    # Any distribution p puts p_red + p_black <= 1 on the two disjoint sets, so
    # P(both first moves optimal) = p_red * p_black <= 1/4: check on a grid of distributions.
    grid = np.random.default_rng(3).dirichlet(np.ones(5), size=20000)
    assert (grid @ red * (grid @ black)).max() <= 0.25
    # A non-optimal first move leaves the seat at least d_k steps away, i.e. costs >= 1 step.
    seats = np.arange(maze.n_agents)
    after = d[seats[:, None], maze.next_cell[:, start, :]]  # (seats, actions)
    dk = d[seats, start][:, None]
    assert (after[~best[:, start]] >= np.broadcast_to(dk, after.shape)[~best[:, start]]).all()
    # Expected lost steps >= (1 - p_red) + (1 - p_black) >= 1, so J <= optimum - STEP_COST / n ...
    optimum = optimal_return(maze)
    analytic = optimum - STEP_COST / maze.n_agents
    # ... and the vertex bound from the oracle is tighter still (a wrong turn must be undone).
    vertex = (1.0 - STEP_COST * (1.0 + after)).mean(0).max()
    assert vertex <= analytic < optimum
    assert vertex == pytest.approx(optimum - STEP_COST)


def test_one_policy_on_one_conflict_cell_loses_one_move_per_agent():
    """On the single conflict cell a wrong move is a bump, so red stays there for (1 - q) / q
    moves on average and black for q / (1 - q); the sum is least, 2, at q = 1/2."""
    maze = load_layout("fork-p2-c1-b4-s3-h3")
    value, q = one_policy_return(maze, 50)
    assert q == {conflict_cells(maze, 0, 1)[0]: 0.5}
    assert value == pytest.approx(optimal_return(maze) - STEP_COST * 2 / 2, abs=1e-9)


def test_one_policy_return_is_what_sampled_episodes_earn():
    maze = load_layout("fork-p2-c3-b4-s3-h3")
    value, q = one_policy_return(maze, 50)
    best = optimal_actions(maze)
    common = best[0] & best[1]
    fixed = np.argmax(np.where(common.any(-1, keepdims=True), common, best[0] | best[1]), -1)  # per cell
    red, black = np.argmax(best[0], -1), np.argmax(best[1], -1)
    q_of = np.full(maze.n_cells, np.nan)
    q_of[list(q)] = list(q.values())
    rng = np.random.default_rng(0)
    env, returns = VecMaze(maze, n_envs=4000, max_steps=50), np.full(4000, np.nan)
    env.reset()
    while np.isnan(returns).any():
        cells = env.cells
        mixed = np.where(rng.random(cells.shape) < q_of[cells], red[cells], black[cells])  # red's move w.p. q
        out = env.step(np.where(np.isnan(q_of[cells]), fixed[cells], mixed))
        first = np.isnan(returns) & ~np.isnan(out.episode_return)
        returns[first] = out.episode_return[first]
    assert abs(returns.mean() - value) < 4 * returns.std() / np.sqrt(len(returns))
    assert value < optimal_return(maze)


def test_one_policy_level_falls_with_every_conflict_cell():
    levels = [one_policy_return(m, 50)[0] / optimal_return(m)
              for m in (load_layout(f"fork-p2-c{c}-b4-s3-h3") for c in (1, 3, 5, 7))]
    assert levels == sorted(levels, reverse=True) and levels[0] < 1
    with pytest.raises(ValueError, match="compares two seats"):
        one_policy_return(load_maze("black_blue_red"), 50)


def test_black_red_routes_share_cells_with_the_same_move():
    maze = load_maze("black_red")
    best = optimal_actions(maze)
    red, black = shortest_route(maze, 0), shortest_route(maze, 1)
    shared = [c for c in set(red) & set(black) if c != maze.star]
    agree = [c for c in shared if (best[0, c] & best[1, c]).any()]
    assert len(agree) >= 2  # the common climb to the star: reuse can help there
    assert set(conflict_cells(maze, 0, 1)).isdisjoint(agree)


def test_black_blue_red_conflicts_red_black_more_than_black_blue():
    maze = load_maze("black_blue_red")
    seat = {a: k for k, a in enumerate(maze.agents)}
    red_black = conflict_cells(maze, seat["red"], seat["black"])
    black_blue = conflict_cells(maze, seat["black"], seat["blue"])
    assert len(red_black) > len(black_blue) >= 1
    assert red_black == conflict_cells(maze, seat["black"], seat["red"])  # symmetric
    assert maze.starts[0] in red_black and maze.starts[0] not in black_blue


# ---------------------------------------------------------------- pictures


@pytest.mark.parametrize("name", NAMES)
def test_save_maze_png(name, tmp_path):
    path = tmp_path / f"{name}.png"
    save_maze_png(load_maze(name), path)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
