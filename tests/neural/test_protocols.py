"""Every engine is a ``VecEnv`` and both algorithm families are a ``Learner``: the protocols the
loop reads (``envs.vec``, ``neural.learner``) are the ones the code implements, member by member."""
import pytest
import torch

from oapo_lite.envs import MazeParallelEnv, grf, load_maze, make_vec
from oapo_lite.envs.pettingzoo_vec import PettingZooVec
from oapo_lite.envs.registry import make_vec as make_engine
from oapo_lite.envs.vec import HasSeatSpaces, StepsSomeCopies, VecEnv, check_copies
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.learner import Learner
from oapo_lite.neural.runstate import RunState

ENGINES = ["black_red", "smax:3m", "mamujoco:HalfCheetah-2x3"] + (["grf:academy_3_vs_1_with_keeper"]
                                                                   if grf.installed() else [])


@pytest.mark.parametrize("name", ENGINES)
def test_every_engine_is_a_vec_env_and_steps_some_copies_only_where_it_says(name):
    env = make_engine(name, 2, 0, 20)
    assert isinstance(env, VecEnv)
    assert isinstance(env, StepsSomeCopies) == name.startswith("grf:")
    assert not isinstance(env, HasSeatSpaces) or name.startswith("mamujoco:")  # a PettingZoo env names its spaces


def test_a_pettingzoo_env_is_a_vec_env_with_seat_spaces():
    env = PettingZooVec(lambda: MazeParallelEnv(load_maze("black_red"), max_steps=5), 2, seed=0)
    assert isinstance(env, VecEnv) and isinstance(env, HasSeatSpaces) and not isinstance(env, StepsSomeCopies)


def test_something_short_of_the_protocol_is_not_a_vec_env():
    class NoReset:
        n_envs = n_agents = n_actions = obs_dim = state_dim = 1
        agents = agent_types = ("a",)
        continuous = time_in_state = False
        optimum = float("nan")

        def step(self, actions): ...

        def get_state(self): ...

        def set_state(self, state): ...

    assert not isinstance(NoReset(), VecEnv)
    NoReset.reset = lambda self: None
    assert isinstance(NoReset(), VecEnv)


@pytest.mark.parametrize("algo", ["oappo", "oatrpo", "happo", "mappo", "seac", "seps"])
def test_both_algorithm_families_are_a_learner(algo):
    learner = RunState.start(TrainConfig(algo=algo, env="black_red", n_envs=2, eval_episodes=2)).learner
    assert isinstance(learner, Learner)
    assert all(isinstance(opt, torch.optim.Optimizer) and lr > 0 for opt, lr in learner.optimisers())


@pytest.mark.parametrize("n_envs, max_steps, own_limit, bad", [
    (0, 10, False, "n_envs"), (2.5, 10, False, "n_envs"), ("2", 10, False, "n_envs"),
    (2, None, False, "max_steps"), (2, 0, True, "max_steps"), (2, None, True, None), (2, 10.0, False, None),
])
def test_the_constructor_checks_every_engine_shares(n_envs, max_steps, own_limit, bad):
    if bad is None:
        assert check_copies(n_envs, max_steps, own_limit) == (2, None if max_steps is None else 10)
    else:
        with pytest.raises(ValueError, match=f"^{bad} must be a positive integer, got"):
            check_copies(n_envs, max_steps, own_limit)


def test_the_maze_engine_refuses_a_missing_time_limit():
    with pytest.raises(ValueError, match="max_steps must be a positive integer, got None"):
        make_vec("black_red", 2, None)
