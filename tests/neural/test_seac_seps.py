"""SEAC and SePS: each method's defining property on cases computed by hand or independently."""
import copy
import math

import numpy as np
import pytest
import torch
from gymnasium import spaces
from pettingzoo import ParallelEnv

from oapo_lite import __main__ as cli
from oapo_lite.envs import make_vec
from oapo_lite.neural import seps
from oapo_lite.neural.a2c_family import A2C, nstep_returns, seac_loss
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.nets import Actors
from oapo_lite.neural.results import learning
from oapo_lite.neural.rollout import collect
from oapo_lite.neural.runstate import load_checkpoint
from oapo_lite.neural.train import train

torch.set_num_threads(1)


def test_seac_weights_and_loss_on_a_tiny_batch_match_a_direct_computation():
    """Two seats, two samples each, learner = seat 0, lambda = 0.5, every number by hand."""
    p_learner = [[0.5, 0.25], [0.2, 0.8]]  # pi_0(a_k | o_k), row k = seat
    p_behaviour = [[0.5, 0.25], [0.4, 0.2]]  # pi_k(a_k | o_k); row 0 is the learner's own
    value = [[1.0, 0.0], [0.5, 2.0]]  # V_0(o_k)
    ret = [[2.0, 1.0], [1.5, 1.0]]  # R_k
    ent = [[0.6, 0.4], [9.0, 9.0]]  # the others' entropies must not count
    lam, ent_coef = 0.5, 0.01
    # direct: w_01 = (0.2 / 0.4, 0.8 / 0.2) = (0.5, 4)
    w = [0.2 / 0.4, 0.8 / 0.2]
    policy = -(math.log(0.5) * 1.0 + math.log(0.25) * 1.0) / 2 \
        + lam * -(w[0] * math.log(0.2) * 1.0 + w[1] * math.log(0.8) * -1.0) / 2
    val = (1.0 ** 2 + 1.0 ** 2) / 2 + lam * (w[0] * 1.0 ** 2 + w[1] * 1.0 ** 2) / 2
    expected = policy + 0.5 * val - ent_coef * (0.6 + 0.4) / 2

    logp = torch.tensor(p_learner).log().requires_grad_()
    loss, parts = seac_loss(logp, torch.tensor(p_behaviour).log(), torch.tensor(value), torch.tensor(ret),
                            torch.tensor(ent), torch.tensor([True, False]), lam, ent_coef)
    assert torch.allclose(parts["weights"][1], torch.tensor(w))
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    # the weights are detached: d loss / d log pi(a_1|o_1) is -lambda w A / B, not more
    loss.backward()
    assert logp.grad[1, 1].item() == pytest.approx(-lam * w[1] * -1.0 / 2, rel=1e-6)


def test_nstep_returns_match_a_hand_computation():
    reward = torch.tensor([[1.0], [0.0], [2.0]])
    done = torch.tensor([[False], [True], [False]])
    R = nstep_returns(reward, done, torch.tensor([10.0]), gamma=0.5)
    # t=2: 2 + 0.5 * 10 = 7; t=1 ends the episode: 0; t=0: 1 + 0.5 * 0 = 1
    assert R.squeeze(1).tolist() == [1.0, 0.0, 7.0]


def _batch(n_envs=4, seed=0):
    env = make_vec("black_blue_red", n_envs, 50)
    actors = Actors(3, env.obs_dim, env.n_actions, (16,), False, torch.Generator().manual_seed(seed))
    batch, step = collect(env, env.reset(), actors, [0, 1, 2], 5, torch.Generator().manual_seed(seed + 1))
    assert np.array_equal(batch.next_obs.numpy(), step.obs)  # the rollout carries where it ended
    return env, actors, batch, torch.from_numpy(step.obs)


def _learner(actors, obs_dim, lam):
    return A2C(actors, obs_dim, (16,), lam, 0.99, 3e-4, 1e-3, 0.5, 0.01, torch.Generator().manual_seed(5))


def _reference_a2c_step(a2c: A2C, batch, next_obs, owner):
    """Plain A2C written out sample by sample: net c's loss pools the samples of the seats it
    controls; returns by a loop over time; one Adam step per net after clipping."""
    n, B = batch.act.shape
    T, N = batch.reward.shape
    obs = batch.inputs.obs[batch.inputs.index]  # (n, B, d)
    for opt in a2c.opts:
        opt.zero_grad()
    for c in sorted(set(owner)):
        seats = [k for k in range(n) if owner[k] == c]
        terms = []
        for k in seats:
            with torch.no_grad():
                running = a2c.critics[owner[k]](next_obs[:, k])
            R = torch.empty(T, N)
            for t in reversed(range(T)):
                done = batch.terminated[t] | batch.truncated[t]
                running = batch.reward[t] + 0.99 * torch.where(done, 0.0, running)
                R[t] = running
            logits = a2c.actors(obs[k][None], [c], batch.inputs.avail[batch.inputs.index[k]][None])[0]
            logp = logits.gather(-1, batch.act[k][:, None]).squeeze(-1)
            entropy = -(logits.exp() * logits).sum(-1)
            adv = R.reshape(-1) - a2c.critics[c](obs[k])
            terms.append(-logp * adv.detach() + 0.5 * adv.pow(2) - 0.01 * entropy)
        torch.cat(terms).mean().backward()
    for c in sorted(set(owner)):
        torch.nn.utils.clip_grad_norm_(a2c.params(c), 0.5)
        a2c.opts[c].step()


@pytest.mark.parametrize("owner", [[0, 1, 2], [0, 0, 0], [0, 1, 0]])
def test_lambda_zero_is_plain_a2c_independent_shared_or_grouped(owner):
    """lambda = 0: SEAC is independent A2C (owner = identity), SePS with k = 1 is parameter
    sharing (every seat on net 0) and with k = n no sharing; a grouping pools each group."""
    env, actors, batch, next_obs = _batch()
    a2c = _learner(actors, env.obs_dim, 0.0)
    ref = copy.deepcopy(a2c)
    a2c.step(batch, owner)
    _reference_a2c_step(ref, batch, next_obs, owner)
    for c in range(3):
        for p, q in zip(a2c.params(c), ref.params(c)):
            assert torch.allclose(p, q, atol=1e-6), (c, (p - q).abs().max())
    untouched = _learner(copy.deepcopy(_batch()[1]), env.obs_dim, 0.0)
    for c in set(range(3)) - set(owner):  # a net that controls no seat never moves
        assert all(torch.equal(p, q) for p, q in zip(a2c.params(c), untouched.params(c)))


def test_davies_bouldin_and_kmeans_on_points_computed_by_hand():
    x = np.array([[0.0], [2.0], [10.0], [12.0]])
    # clusters {0, 2} and {10, 12}: scatter 1 each, centroids 10 apart -> (1 + 1) / 10
    assert seps.davies_bouldin(x, np.array([0, 0, 1, 1])) == pytest.approx(0.2)
    # {0}, {2, 10, 12}: scatters 0 and 4, centroids 8 apart -> both ratios 0.5
    assert seps.davies_bouldin(x, np.array([0, 1, 1, 1])) == pytest.approx(0.5)
    rng = np.random.default_rng(0)
    assert seps.kmeans(x, 2, rng).tolist() == [0, 0, 1, 1]
    assert seps.kmeans(x[[2, 0, 3, 1]], 2, rng).tolist() == [0, 1, 0, 1]  # agent 0's cluster is 0
    with pytest.raises(ValueError, match="k = 5 clusters is invalid for 4 points"):
        seps.kmeans(x, 5, rng)


def test_the_number_of_groups_is_the_best_davies_bouldin_over_2_to_n_minus_1():
    rng = np.random.default_rng(0)
    # two far-apart agents and an identical pair: k = 3 puts the pair together (index ~0.007),
    # k = 2 must merge one of the far ones into a group (index ~0.5)
    z = np.array([[0.0, 0.0], [5.0, 5.0], [-5.0, 5.0], [-5.0, 5.1]])
    labels, scores = seps.choose_groups(z, None, rng)
    assert labels.tolist() == [0, 1, 2, 2] and sorted(scores) == [2, 3] and scores[3] < scores[2]
    assert scores[3] == pytest.approx(seps.davies_bouldin(z, labels))
    pairs = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [5.0, 5.1]])
    assert seps.choose_groups(pairs, 2, rng)[0].tolist() == [0, 0, 1, 1]  # a given k is used as is
    assert seps.choose_groups(pairs[:2], None, rng)[0].tolist() == [0, 1]  # no k in 2..n-1: no sharing
    assert seps.group_names([1, 1, 0, 1], ["black", "blue", "red", "x"]) == "black+blue+x | red"


class Ring(ParallelEnv):
    """Four agents on a ring of 6 cells, all starting on cell 0. Action 1 moves an agent by its
    type's stride ('a': +1, 'b': -2, 'c': +3); action 0 stays. Team reward: the share of agents
    on cell 3. ``agents`` names them, so their first letters choose the types."""

    metadata = {"name": "ring_v0"}
    CELLS, LENGTH = 6, 8

    STRIDE = {"a": 1, "b": -2, "c": 3}

    def __init__(self, agents=("a0", "b0", "a1", "b1"), continuous=False, obs_dims=None):
        self.possible_agents = list(agents)
        dims = obs_dims or [self.CELLS] * 4
        self._obs = {k: spaces.Box(0, 1, (d,), np.float32) for k, d in zip(self.possible_agents, dims)}
        self.continuous = continuous
        self._act = spaces.Box(-1, 1, (1,), np.float32) if continuous else spaces.Discrete(2)

    def observation_space(self, agent):
        return self._obs[agent]

    def action_space(self, agent):
        return self._act

    def _observe(self):
        return {k: np.eye(self._obs[k].shape[0], dtype=np.float32)[self.pos[k]] for k in self.agents}

    def reset(self, seed=None, options=None):
        self.agents, self.t = list(self.possible_agents), 0
        self.pos = dict.fromkeys(self.agents, 0)
        return self._observe(), {k: {} for k in self.agents}

    def step(self, actions):
        self.t += 1
        for k, a in actions.items():
            move = float(np.ravel(a)[0]) > 0 if self.continuous else a == 1
            self.pos[k] = (self.pos[k] + self.STRIDE[k[0]] * move) % self.CELLS
        reward = float(np.mean([p == 3 for p in self.pos.values()]))
        agents, done = self.agents, self.t >= self.LENGTH
        obs = self._observe()
        if done:
            self.agents = []
        return obs, dict.fromkeys(agents, reward), dict.fromkeys(agents, False), dict.fromkeys(agents, done), \
            {k: {} for k in agents}


RING = dict(algo="seps", env_fn=Ring, n_envs=8, steps=40 * 30, seps_pretrain_steps=40 * 20, eval_every=10,
            eval_episodes=4)
# the VAE needs some data: 4,000 env steps give 16,000 transitions (1,250 VAE steps)
RING_VAE = {**RING, "steps": 40 * 105, "seps_pretrain_steps": 40 * 100, "eval_every": 50}


def for_algo(algo: str, /, **fields) -> dict:
    """``fields`` with ``algo``, less SePS's own fields for SEAC (a config refuses a value in a
    field its algorithm does not read)."""
    return {**{k: v for k, v in fields.items() if algo == "seps" or not k.startswith("seps_")}, "algo": algo}


def test_seps_groups_two_identical_agents_and_keeps_two_different_ones_apart(tmp_path):
    """Agents a and b move differently from each other and from the identical c0, c1: the
    Davies-Bouldin choice (k in 2..3) is k = 3, the c's share a network."""
    rows = train(TrainConfig(**{**RING_VAE, "env_fn": lambda: Ring(("a", "c0", "b", "c1"))}), tmp_path,
                 resume=False, progress=False)
    assert rows["seps_groups"].iloc[0] != rows["seps_groups"].iloc[0]  # NaN: no update before the first row
    assert rows["seps_groups"].iloc[1] == "a+c0+b+c1"  # pre-training: one shared network
    assert rows["seps_groups"].iloc[-1] == "a | c0+c1 | b"
    learner = load_checkpoint(tmp_path)["learner"]
    assert learner["owner"] == [0, 1, 2, 1] and sorted(learner["db_scores"]) == [2, 3]
    z = learner["embeddings"]
    assert np.linalg.norm(z[1] - z[3]) < min(np.linalg.norm(z[0] - z[1]), np.linalg.norm(z[2] - z[1])) / 2


def test_seps_with_two_groups_given_pairs_the_identical_agents(tmp_path):
    """Two types of two identical agents each, k = 2 given: the types are the groups."""
    rows = train(TrainConfig(**{**RING_VAE, "seps_clusters": 2}), tmp_path, resume=False, progress=False)
    assert rows["seps_groups"].iloc[-1] == "a0+a1 | b0+b1"


def test_seps_with_one_group_is_parameter_sharing_and_with_n_groups_no_sharing(tmp_path):
    """k = 1: the switch after pre-training changes nothing, so the run equals one whose
    pre-training ends at another time (the VAE draws from its own generators). k = n: every
    agent alone, each network a copy of the pre-trained one at the switch."""
    one_a = train(TrainConfig(**{**RING, "seps_clusters": 1}), tmp_path / "a", resume=False, progress=False)
    one_b = train(TrainConfig(**{**RING, "seps_clusters": 1, "seps_pretrain_steps": 40 * 5}), tmp_path / "b",
                  resume=False, progress=False)
    assert one_a["seps_groups"].iloc[-1] == "a0+b0+a1+b1"
    assert one_a["eval_return"].tolist() == one_b["eval_return"].tolist()
    ck_a, ck_b = load_checkpoint(tmp_path / "a"), load_checkpoint(tmp_path / "b")
    assert all(torch.equal(ck_a["actors"][k], ck_b["actors"][k]) for k in ck_a["actors"])

    cfg = TrainConfig(**{**RING, "seps_clusters": 4, "steps": 40 * 20, "seps_pretrain_steps": 40 * 20 - 40})
    rows = train(cfg, tmp_path / "n", resume=False, progress=False)
    assert rows["seps_groups"].iloc[-1] == "a0 | b0 | a1 | b1"
    # after the switch every net took one A2C step from the same copy, on its own seat only
    actors = load_checkpoint(tmp_path / "n")["actors"]
    first = [actors[f"weights.{k}.0"] for k in range(4)]
    assert all(not torch.equal(first[0], w) for w in first[1:])
    assert all((first[0] - w).abs().max() < 1e-2 for w in first[1:])


@pytest.mark.parametrize("algo, crash_at", [("seac", 7), ("seps", 7), ("seps", 23)])
def test_resuming_seac_and_seps_gives_the_uninterrupted_numbers(tmp_path, algo, crash_at):
    """Crashes before and after SePS's switch (iteration 20); checkpoints every 5 iterations."""
    cfg = TrainConfig(**for_algo(algo, **RING, checkpoint_every=5))
    full = train(cfg, tmp_path / "full", resume=False, progress=False)

    def crash(metrics):
        if metrics["iteration"] == crash_at:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(cfg, tmp_path / "resumed", progress=False, callback=crash)
    resumed = train(cfg, tmp_path / "resumed", progress=False)
    cols = [c for c in learning(full).columns if c != "git_rev"]
    assert full[cols].equals(resumed[cols])
    a, b = load_checkpoint(tmp_path / "full")["actors"], load_checkpoint(tmp_path / "resumed")["actors"]
    assert all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("algo", ["seac", "seps"])
def test_box_actions_train_and_different_spaces_raise(tmp_path, algo):
    rows = train(TrainConfig(**for_algo(algo, **{**RING, "env_fn": lambda: Ring(continuous=True)})), tmp_path / "box",
                 resume=False, progress=False)
    assert np.isfinite(rows["eval_return"]).all()
    with pytest.raises(ValueError, match=r"reuse between agents 'a0' and 'b0' needs equal spaces"):
        train(TrainConfig(**for_algo(algo, **{**RING, "env_fn": lambda: Ring(obs_dims=[6, 7, 6, 7])})),
              tmp_path / "bad", resume=False, progress=False)


@pytest.mark.parametrize("bad, words", [
    (dict(algo="seps", seps_pretrain_steps=1200), ["seps_pretrain_steps", "1200", "< steps = 1200"]),
    (dict(algo="seps", seps_pretrain_steps=10), ["seps_pretrain_steps", "10", ">= n_envs * n_step = 40"]),
    (dict(algo="seac", seac_lambda=-1.0), ["seac_lambda", "-1.0", ">= 0"]),
    (dict(algo="seps", seps_clusters=0), ["seps_clusters", "0", "None or an integer >= 1"]),
])
def test_bad_seac_seps_values_raise_naming_the_value(bad, words):
    with pytest.raises(ValueError) as err:
        TrainConfig(**for_algo(bad["algo"], **{**RING, **bad}))
    for word in words:
        assert word in str(err.value)


@pytest.mark.parametrize("bad, words", [
    (dict(algo="seps", seps_clusters=5), ["seps_clusters = 5", "4 agents", "1..4"]),
    (dict(algo="seac", bootstrap_truncation=True), ["bootstrap_truncation = True", "None or False"]),
    (dict(algo="seac", networks="one"), ["networks = 'one'", "allowed: None"]),
])
def test_settings_seac_and_seps_cannot_use_raise_at_the_start(tmp_path, bad, words):
    with pytest.raises(ValueError) as err:
        train(TrainConfig(**for_algo(bad["algo"], **{**RING, **bad})), tmp_path, resume=False, progress=False)
    for word in words:
        assert word in str(err.value)


def test_the_cli_trains_seac_and_seps_on_a_maze(tmp_path, capsys):
    for algo in ("seac", "seps"):
        seps = ["--seps-pretrain-steps", "400", "--seps-clusters", "none"] if algo == "seps" else []
        assert cli.main(["train", "--algo", algo, "--env", "black_red", "--n-envs", "8", "--steps", "800", *seps,
                         "--out", str(tmp_path), "--no-progress"]) == 0
        assert f"{algo} on black_red, seed 0: 800 env steps" in capsys.readouterr().out
    (seps_run,) = tmp_path.glob("seps-black_red-s0-*")
    rows = __import__("pandas").read_csv(seps_run / "results.csv")
    assert rows["seps_groups"].iloc[-1] == "red | black"  # two agents: no k in 2..n-1, no sharing


@pytest.mark.parametrize("algo", ["seac", "seps"])
def test_action_masks_are_respected(tmp_path, algo):
    from test_train import Toy  # asserts that no masked action is ever sent

    rows = train(TrainConfig(**for_algo(algo, env_fn=lambda: Toy(masked="obs"), n_envs=4, steps=400,
                                        seps_pretrain_steps=200, eval_every=5, eval_episodes=2)),
                 tmp_path, resume=False, progress=False)
    assert np.isfinite(rows["eval_return"]).all()


@pytest.mark.parametrize("algo", ["seac", "seps"])
def test_a2c_learns_the_corridor(tmp_path, algo):
    """Both agents walk right 3 cells (optimum 0.97). A2C at lr 3e-4 is slower than the PPO
    family (which reaches 95% in 4,800 steps): 24,000 steps take it from ~0.06 to >= 0.7."""
    from test_train import CORRIDOR

    rows = train(TrainConfig(**for_algo(algo, env=CORRIDOR, n_envs=16, max_steps=10, steps=80 * 300, eval_every=30,
                                        eval_episodes=16, seps_pretrain_steps=80 * 50)),
                 tmp_path, resume=False, progress=False)
    assert rows["frac_opt"].iloc[0] < 0.2
    assert rows["frac_opt"].iloc[-5:].max() >= 0.7
