"""Multi-agent MuJoCo through the env registry: names, spaces, action bounds, resume, training."""
import dataclasses
import numpy as np
import pandas as pd
import pytest
import torch

from oapo_lite.envs import mamujoco, registry
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.nets import Actors
from oapo_lite.neural.results import learning
from oapo_lite.neural.rollout import collect
from oapo_lite.neural.runstate import load_checkpoint, read_data
from oapo_lite.neural.train import train

import fakes

CHEETAH = "mamujoco:HalfCheetah-2x3"
TINY = dict(env=CHEETAH, n_envs=2, rollout_len=20, max_steps=30, eval_every=1, eval_episodes=2)


def test_unknown_names_raise_listing_the_allowed_ones():
    with pytest.raises(ValueError) as err:
        TrainConfig(env="mamujoco:HalfCheetah-3x2")
    assert "HalfCheetah-3x2" in str(err.value) and "HalfCheetah-2x3" in str(err.value) and "Ant-2x4" in str(err.value)
    registry.check(CHEETAH)


@pytest.mark.parametrize("name", sorted(mamujoco.PARTITIONS))
def test_homogeneous_flags_match_the_engines_spaces(name):
    env = mamujoco.env_fn(name, 10)()
    spaces = [(env.observation_space(a), env.action_space(a)) for a in env.possible_agents]
    assert mamujoco.PARTITIONS[name] == all(s == spaces[0] for s in spaces)


def test_actions_reach_the_engine_inside_the_box_even_from_extreme_policies():
    vec = registry.make_vec(CHEETAH, n_envs=2, seed=0, max_steps=30)
    space = vec.envs[0].action_space(vec.agents[0])
    sent = []
    for env in vec.envs:  # a spy at the engine boundary: the robot action every copy's MuJoCo env receives
        robot = env.single_agent_env

        def spy(action, _step=robot.step):
            sent.append(np.array(action))
            return _step(action)
        robot.step = spy
    gen = torch.Generator().manual_seed(0)
    actors = Actors(2, vec.obs_dim, vec.n_actions, (8,), continuous=True, gen=gen)
    with torch.no_grad():  # means of +-50 (far outside [-1, 1]) in alternating dimensions
        for k in range(2):
            actors.weights[k][-2].copy_(torch.tensor([50.0, -50.0, 50.0]))
    batch, _ = collect(vec, vec.reset(), actors, [0, 1], 10, gen)
    sent = np.stack(sent)
    assert sent.shape == (20, 6)  # two agents' three joints each, in the robot's order
    assert (batch.act.abs() > 10).all()  # the policy's own actions are far out of bounds
    assert (sent >= space.low[0]).all() and (sent <= space.high[0]).all()
    np.testing.assert_array_equal(sent, np.broadcast_to([1.0, -1.0, 1.0, 1.0, -1.0, 1.0], sent.shape))


@pytest.mark.parametrize("name", ["HalfCheetah-2x3", "Hopper-3x1"])
def test_the_direct_step_equals_pettingzoo_step_bit_for_bit(name):
    """MaMuJoCoVec steps the robot's MuJoCo env and gathers the agents' observations; the
    generic PettingZooVec goes through MaMuJoCo's own step. Same actions, same numbers,
    across episode ends (max_steps 30) and on a partition with unequal observations."""
    from oapo_lite.envs.mamujoco import env_fn
    from oapo_lite.envs.pettingzoo_vec import PettingZooVec

    fast = registry.make_vec(f"mamujoco:{name}", n_envs=3, seed=4, max_steps=30)
    slow = PettingZooVec(env_fn(name, 30), n_envs=3, seed=4, max_steps=30)
    steps = [fast.reset(), slow.reset()]
    rng = np.random.default_rng(1)
    ends = 0
    for _ in range(70):
        actions = rng.uniform(-1.5, 1.5, (3, fast.n_agents, fast.n_actions)).astype(np.float32)
        steps = [fast.step(actions), slow.step(actions)]
        for field in dataclasses.fields(steps[0]):
            np.testing.assert_array_equal(getattr(steps[0], field.name), getattr(steps[1], field.name),
                                          err_msg=field.name)
        ends += int(np.isfinite(steps[0].episode_return).sum())
    assert ends >= 6  # every copy ended (and was reset) at least twice: at step 30 and step 60


def test_get_state_set_state_continues_bit_exactly(tmp_path):
    """The state goes through a checkpoint file as data (``runstate.read_data``) into fresh copies
    stepped elsewhere (Ant's contacts then differ in number: other MjData arrays' shapes)."""
    def make():
        return registry.make_vec("mamujoco:Ant-2x4", n_envs=2, seed=3, max_steps=30)

    vec = make()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (40, 2, 2, 4)).astype(np.float32)
    vec.reset()
    for a in actions[:25]:
        vec.step(a)
    torch.save(vec.get_state(), tmp_path / "state.pt")
    first = [vec.step(a) for a in actions[25:]]  # crosses the 30-step limit: reset and its randomness
    fresh = make()
    fresh.reset()
    for a in actions[:3]:
        fresh.step(a)
    fresh.set_state(read_data(tmp_path / "state.pt"))
    again = [fresh.step(a) for a in actions[25:]]
    assert any(s.truncated.any() for s in first)
    for x, y in zip(first, again):
        for field in ("obs", "state", "reward", "truncated", "final_obs"):
            np.testing.assert_array_equal(getattr(x, field), getattr(y, field))


@pytest.mark.parametrize("algo", ["happo", "mappo", "oappo"])
def test_a_few_iterations_end_to_end(tmp_path, algo):
    rows = train(TrainConfig(algo=algo, steps=120, **TINY), tmp_path / algo, progress=False)
    assert list(rows["step"]) == [0, 40, 80, 120]
    assert np.isfinite(rows["eval_return"]).all() and rows["frac_opt"].isna().all()
    assert (rows["env"] == CHEETAH).all()


def test_resuming_after_a_crash_gives_the_uninterrupted_numbers(tmp_path):
    cfg = TrainConfig(algo="oappo", steps=200, checkpoint_every=2, **TINY)
    full = train(cfg, tmp_path / "full", progress=False)

    fakes.interrupt(cfg, tmp_path / "resumed", at=3)
    assert load_checkpoint(tmp_path / "resumed")["iteration"] == 2
    pd.testing.assert_frame_equal(learning(full), learning(train(cfg, tmp_path / "resumed", progress=False)))


def test_reuse_on_a_heterogeneous_partition_raises_clearly(tmp_path):
    with pytest.raises(ValueError, match="needs equal spaces"):
        train(TrainConfig(algo="oappo", steps=40, **{**TINY, "env": "mamujoco:Hopper-3x1"}), tmp_path, progress=False)


def test_the_engine_writes_no_log_into_the_working_folder(tmp_path):
    """MuJoCo appends its warnings to MUJOCO_LOG.TXT in the working folder (HalfCheetah's model
    warns at every compile): made through the package, the env leaves the folder empty; made
    directly, the same compile writes the file (what the first check would miss)."""
    import subprocess
    import sys

    ours, direct = tmp_path / "ours", tmp_path / "direct"
    for folder, code in ((ours, "from oapo_lite.envs import mamujoco; mamujoco.env_fn('HalfCheetah-2x3', 50)()"),
                         (direct, "from gymnasium_robotics import mamujoco_v1; "
                                  "mamujoco_v1.parallel_env('HalfCheetah', '2x3', max_episode_steps=50)")):
        folder.mkdir()
        done = subprocess.run([sys.executable, "-c", code], cwd=folder, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
    assert list(ours.iterdir()) == [] and [p.name for p in direct.iterdir()] == ["MUJOCO_LOG.TXT"]


def test_a_compile_warning_stays_out_of_stderr_and_a_later_warning_reaches_it():
    """HalfCheetah's and Ant's models warn at every compile (a deprecated attribute nobody using the
    package can change): the env is made without a word on stderr, C's or Python's (a notebook's
    stderr is a Python stream, not file descriptor 2); a warning MuJoCo raises afterwards still
    reaches it through the package's handler."""
    import subprocess
    import sys

    code = ("import io, sys, mujoco; from oapo_lite.envs import mamujoco\n"
            "kernel, sys.stderr = sys.stderr, io.StringIO()  # as a Jupyter kernel's stream\n"
            "for name in ('HalfCheetah-2x3', 'Ant-4x2'): mamujoco.env_fn(name, 50)()\n"
            "print(repr(sys.stderr.getvalue()), flush=True)\n"
            "mujoco.get_mju_user_warning()('after the compile'); print(repr(sys.stderr.getvalue()))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["''", repr("MuJoCo warning: after the compile\n")] and done.stderr == ""
