"""The layout generator: every map says what the oracle measures, and plays as a PettingZoo env."""
import itertools

import pytest
from pettingzoo.test import parallel_api_test

from oapo_lite.envs import MAPS, MazeParallelEnv, VecMaze, layouts as L, load_maze, registry
from oapo_lite.neural.config import TrainConfig

# a brute-force sweep beyond the study's layouts: every claim must hold on every fork
SWEEP = [L.Fork(p, c, b, s, h) for p, b, s, h in itertools.product((0, 1, 3), (1, 2), (1, 2), (1, 3))
         for c in range(1, 2 * h + 2)]


def claimed(fork):
    return {"shared_prefix": fork.prefix, "shared_suffix": fork.suffix, "conflicts": fork.conflicts,
            "first_move_conflict": fork.first_move == "conflict", "route_red": fork.route_length,
            "route_black": fork.route_length, "unique_routes": True}


@pytest.mark.parametrize("name", sorted(L.LAYOUTS))
def test_study_layouts_are_what_the_generator_claims(name):
    maze = L.load_layout(name)
    assert L.measure(maze) == claimed(L.LAYOUTS[name])
    assert maze.agents == ("red", "black") and maze.starts[0] == maze.starts[1]


def test_sweep_of_forks_is_what_the_generator_claims():
    assert len(SWEEP) == 120  # 3 prefixes x 2 branches x 2 suffixes x (3 + 7) conflict counts
    for fork in SWEEP:
        assert L.measure(L.load_layout(fork.name)) == claimed(fork), fork


def test_black_red_is_a_fork():
    fork = L.Fork(prefix=0, conflicts=7, branch=2, suffix=3)
    assert fork.text() == MAPS["black_red"]
    assert L.measure(load_maze("black_red")) == claimed(fork)


def _measured(family):
    return [L.measure(L.load_layout(f.name)) for f in L.FAMILIES[family][0]]


def test_first_move_family_moves_the_shared_part_across_the_conflict():
    shared, conflict = _measured("first_move")
    assert not shared["first_move_conflict"] and conflict["first_move_conflict"]
    assert shared["shared_prefix"] > 0 and conflict["shared_prefix"] == 0
    for key in ("conflicts", "route_red", "route_black"):
        assert shared[key] == conflict[key]
    assert (shared["shared_prefix"] + shared["shared_suffix"]
            == conflict["shared_prefix"] + conflict["shared_suffix"])


@pytest.mark.parametrize("family, varied", [("shared_prefix", "shared_prefix"), ("conflicts", "conflicts")])
def test_a_family_varies_one_measured_property(family, varied):
    measured = _measured(family)
    values = [m[varied] for m in measured]
    assert len(set(values)) == len(values) == len(L.FAMILIES[family][0])
    for key in ("shared_suffix", "conflicts", "route_red", "route_black"):
        if key != varied:
            assert len({m[key] for m in measured}) == 1, key


def test_the_base_layout_is_in_every_family():
    base = L.Fork(**L.BASE)
    assert all(base in forks for forks, _ in L.FAMILIES.values())


@pytest.mark.parametrize("name", sorted(L.LAYOUTS))
def test_parallel_api(name):
    env = MazeParallelEnv(L.load_layout(name), max_steps=30)
    parallel_api_test(env, num_cycles=100)


def test_layout_engine_spec_trains():
    spec = "layout:" + L.Fork(**L.BASE).name
    registry.check(spec)
    env = registry.make_vec(spec, n_envs=2, seed=0, max_steps=50)
    assert isinstance(env, VecMaze) and env.maze.name == L.Fork(**L.BASE).name
    TrainConfig(env=spec)  # validates the env name
    with pytest.raises(ValueError, match="is not 'fork-p<prefix>"):
        TrainConfig(env="layout:nowhere")


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(prefix=-1, conflicts=1, branch=1, suffix=1), "prefix must be an integer >= 0, got -1"),
    (dict(prefix=0, conflicts=0, branch=1, suffix=1), "conflicts must be an integer >= 1, got 0"),
    (dict(prefix=0, conflicts=1, branch=1.5, suffix=1), "branch must be an integer >= 1, got 1.5"),
    (dict(prefix=0, conflicts=8, branch=1, suffix=1), "at most the fork corridor's 7 cells"),
])
def test_bad_forks_raise(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment.replace("(", r"\(").replace(".", r"\.")):
        L.Fork(**kwargs)


def test_bad_family_arguments_raise():
    with pytest.raises(ValueError, match="prefixes must be below prefix \\+ branch = 6"):
        L.shared_prefix_family(prefixes=(0, 6))
    with pytest.raises(ValueError, match="needs a two-agent maze"):
        L.measure(load_maze("black_blue_red"))
