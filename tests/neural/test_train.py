"""The training loop: algorithm identities, learning, determinism, resume, and the PettingZoo path."""
import copy
import dataclasses
import json
import math
import shutil
import signal
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from gymnasium import spaces
from pettingzoo import ParallelEnv

from oapo_lite import __main__ as cli, reuse
from oapo_lite.algorithms import ALGOS
from oapo_lite.envs import MAPS, MazeParallelEnv, make_vec, parse_maze
from oapo_lite.envs.pettingzoo_vec import PettingZooVec
from oapo_lite.envs.vec import VecStep, seat_spaces
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural import seps
from oapo_lite.neural.nets import Actors, Categorical
from oapo_lite.neural.ppo_family import LearnerBatch, learner_dists, policy_distances, update_actors, update_units
from oapo_lite.neural.results import learning
from oapo_lite.neural.rollout import Inputs, Rollout, collect
from oapo_lite.neural.runstate import load_checkpoint, load_history
from oapo_lite.neural.train import train
from oapo_lite.reuse import check_spaces

import fakes

torch.set_num_threads(1)

# Both agents walk right along one corridor: 3 steps each, optimum 1 - 0.03 = 0.97.
CORRIDOR = """\
agents: red black
start: 1,1 1,1
######
#...*#
######
"""
TINY = dict(env=CORRIDOR, n_envs=16, rollout_len=10, max_steps=10, eval_every=2, eval_episodes=16)
SMALL_BR = dict(env="black_red", n_envs=8, rollout_len=25, steps=600, eval_every=3, eval_episodes=8)


def _run(tmp_path, name, **kw) -> pd.DataFrame:
    return train(TrainConfig(**kw), tmp_path / name, resume=False, progress=False)


def _params(tmp_path, name) -> dict:
    return load_checkpoint(tmp_path / name)["actors"]


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def _assert_same_run(tmp_path, a: str, rows_a: pd.DataFrame, b: str, rows_b: pd.DataFrame) -> None:
    """The same rows, returned and on disk, and the same final parameters."""
    pd.testing.assert_frame_equal(learning(rows_a), learning(rows_b))
    pd.testing.assert_frame_equal(learning(pd.read_csv(tmp_path / a / "results.csv")),
                                  learning(pd.read_csv(tmp_path / b / "results.csv")))
    assert _same(_params(tmp_path, a), _params(tmp_path, b))


@pytest.mark.parametrize("bad, words", [
    (dict(algo="ppo"), ["ppo", "oappo", "mappo"]),
    (dict(env="no_such_map"), ["no_such_map", "black_red"]),
    (dict(sigma=-0.1), ["sigma", "-0.1", ">= 0"]),
    (dict(reuse_lambda=1.5), ["reuse_lambda", "1.5", "[0, 1]"]),
    (dict(kl_reduce="median"), ["median", "max", "mean"]),
    (dict(reuse_mode="all"), ["all", "weights", "sample"]),
    (dict(allowed="XR"), ["XR", "NR", "UR", "RR", "AR"]),
    (dict(steps=10), ["steps", "10", "one iteration"]),
    (dict(n_envs=0), ["n_envs", "0"]),
    (dict(hidden=(64, -1)), ["hidden"]),
    (dict(backtrack=1.0), ["backtrack", "(0, 1)"]),
])
def test_bad_config_values_raise_naming_the_value_and_the_allowed_set(bad, words):
    with pytest.raises(ValueError) as err:
        TrainConfig(**bad)
    for word in words:
        assert word in str(err.value)


def test_a_wrong_allowed_mask_shape_raises(tmp_path):
    with pytest.raises(ValueError, match=r"allowed mask has shape \(3, 3\)"):
        _run(tmp_path, "bad", algo="oappo", allowed=np.ones((3, 3), bool), **SMALL_BR)


@pytest.mark.parametrize("algo", [a for a in sorted(ALGOS) if not ALGOS[a].a2c])  # A2C: test_seac_seps.py
def test_a_short_run_on_a_corridor_reaches_the_oracle_optimum(tmp_path, algo):
    rows = _run(tmp_path, algo, algo=algo, steps=160 * 30, **TINY)
    assert rows["frac_opt"].iloc[0] < 0.5  # the untrained policy is far from it
    assert rows["frac_opt"].iloc[-1] >= 0.95
    assert rows["eval_success"].iloc[-1] == 1.0


def test_the_same_config_and_seed_give_identical_results(tmp_path):
    a = _run(tmp_path, "a", algo="oappo", **SMALL_BR)
    b = _run(tmp_path, "b", algo="oappo", **SMALL_BR)
    pd.testing.assert_frame_equal(learning(a), learning(b))
    assert _same(_params(tmp_path, "a"), _params(tmp_path, "b"))
    c = _run(tmp_path, "c", algo="oappo", seed=1, **SMALL_BR)
    assert not _same(_params(tmp_path, "a"), _params(tmp_path, "c"))


@pytest.mark.parametrize("algo", ["oappo", "oatrpo"])  # Adam states, and hand-made steps
def test_resuming_after_a_crash_gives_the_uninterrupted_numbers(tmp_path, algo):
    cfg = TrainConfig(algo=algo, steps=160 * 7, checkpoint_every=2, **TINY)
    full = train(cfg, tmp_path / "full", progress=False)

    def crash(metrics):
        if metrics["iteration"] == 5:  # the last checkpoint is from iteration 4
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(cfg, tmp_path / "resumed", progress=False, callback=crash)
    assert load_checkpoint(tmp_path / "resumed")["iteration"] == 4
    _assert_same_run(tmp_path, "full", full, "resumed", train(cfg, tmp_path / "resumed", progress=False))
    with pytest.raises(ValueError, match="different config"):
        train(TrainConfig(algo=algo, steps=160 * 7, checkpoint_every=2, **{**TINY, "reuse_lambda": 0.5}),
              tmp_path / "full", progress=False)


KILLED = """
import json, os, signal, sys
from oapo_lite.neural.config import TrainConfig
from oapo_lite.neural.train import train
fields, out, at = json.loads(sys.argv[1]), sys.argv[2], int(sys.argv[3])
train(TrainConfig(**fields), out, progress=False,
      callback=lambda m: m["iteration"] == at and os.kill(os.getpid(), signal.SIGKILL))
"""


def test_a_killed_run_resumes_to_every_results_column_of_the_uninterrupted_run(tmp_path):
    """A run SIGKILLed after iteration 5 (its last checkpoint is iteration 4's) and resumed
    writes the uninterrupted run's results in every column (config, revision, evaluations,
    learner metrics, the machine) but the CPU and wall seconds each run was measured to take."""
    fields = dict(algo="oappo", steps=160 * 7, checkpoint_every=2, **TINY)
    full = train(TrainConfig(**fields), tmp_path / "full", progress=False)
    killed = subprocess.run([sys.executable, "-c", KILLED, json.dumps(fields), str(tmp_path / "resumed"), "5"],
                            cwd=Path(cli.__file__).parents[1])
    assert killed.returncode == -signal.SIGKILL and load_checkpoint(tmp_path / "resumed")["iteration"] == 4
    resumed = train(TrainConfig(**fields), tmp_path / "resumed", progress=False)
    assert list(full.columns) == list(resumed.columns) and {"cpu_s", "wall_s"} < set(full.columns) - set(learning(full))
    for a, b in ((full, resumed), (pd.read_csv(tmp_path / "full" / "results.csv"),
                                   pd.read_csv(tmp_path / "resumed" / "results.csv"))):
        pd.testing.assert_frame_equal(learning(a), learning(b))
    assert _same(_params(tmp_path, "full"), _params(tmp_path, "resumed"))


def test_resuming_with_more_steps_gives_the_rows_of_the_longer_run(tmp_path):
    """5 iterations end off the evaluation grid (every 2); extended to 10 the run must not keep
    that row, and must equal a run of 10 from the start."""
    short = TrainConfig(algo="oappo", steps=160 * 5, **TINY)
    long = dataclasses.replace(short, steps=160 * 10)
    assert list(train(short, tmp_path / "run", progress=False)["iteration"]) == [0, 2, 4, 5]
    extended = train(long, tmp_path / "run", progress=False)
    full = train(long, tmp_path / "full", progress=False)
    assert list(extended["iteration"]) == [0, 2, 4, 6, 8, 10]
    _assert_same_run(tmp_path, "full", full, "run", extended)
    with pytest.raises(ValueError, match=r"past steps = 800 \(5 iterations\); resuming needs steps >= 1600"):
        train(short, tmp_path / "run", progress=False)


@pytest.mark.parametrize("damage, words", [
    (lambda ck: ck["config"].pop("kl_reduce"), "no config fields ['kl_reduce']"),
    (lambda ck: ck["learner"].pop("critic_opt"), "no entry 'critic_opt'"),
    (lambda ck: ck["step"].pop("active"), "environment step has no fields ['active']"),
    (lambda ck: ck["learner"].pop("np_rng"), "no entry 'np_rng'"),
])
def test_an_older_checkpoint_without_a_new_field_gives_a_clear_error(tmp_path, damage, words):
    cfg = TrainConfig(algo="oappo", steps=160 * 2, **TINY)
    train(cfg, tmp_path, progress=False)
    ck = load_checkpoint(tmp_path)
    damage(ck)
    torch.save(ck, tmp_path / "checkpoint.pt")
    with pytest.raises(ValueError) as err:
        train(dataclasses.replace(cfg, steps=160 * 3), tmp_path, progress=False)
    assert words in str(err.value) and "resume=False" in str(err.value)


def _before_issue_35(ck: dict) -> None:
    """A checkpoint in the layout before issue 35: the A2C family's state under "a2c", the PPO
    family's keys at the top level."""
    state = ck.pop("learner")
    if "a2c" in state:
        ck["a2c"] = state
    else:
        ck.update(state)


@pytest.mark.parametrize("algo", ["oappo", "seps"])
def test_a_checkpoint_in_the_layout_before_issue_35_resumes_bit_for_bit(tmp_path, algo):
    """Older checkpoints still load: the run resumed from one ends where the run resumed from the
    current layout ends (SePS after its pre-training, with its groups)."""
    shape = dict(TINY, seps_pretrain_steps=160) if algo == "seps" else TINY
    cfg = TrainConfig(algo=algo, steps=160 * 2, **shape)
    longer = dataclasses.replace(cfg, steps=160 * 3)
    train(cfg, tmp_path / "now", progress=False)
    shutil.copytree(tmp_path / "now", tmp_path / "before")
    ck = load_checkpoint(tmp_path / "before")
    _before_issue_35(ck)
    torch.save(ck, tmp_path / "before" / "checkpoint.pt")
    ends = [train(longer, tmp_path / name, progress=False) for name in ("now", "before")]
    pd.testing.assert_frame_equal(*map(learning, ends))
    assert _same(_params(tmp_path, "now"), _params(tmp_path, "before"))


def test_a_checkpoint_written_before_issue_54_resumes_bit_for_bit(tmp_path, monkeypatch):
    """A checkpoint of the layout before issue 54 held two objects: the envs' last step as a
    ``VecStep`` and SePS's pre-training buffer as a ``seps.Buffer`` (pickled before issue 35 as
    ``oapo_lite.seps.Buffer``). Both are read as data, and the run resumed from it ends where
    the run resumed from the current layout ends."""
    cfg = TrainConfig(algo="seps", steps=160 * 4, seps_pretrain_steps=160 * 3, checkpoint_every=2, **TINY)
    fakes.interrupt(cfg, tmp_path / "now", at=3)  # its checkpoint is iteration 2's, in the pre-training
    moved = types.ModuleType("oapo_lite.seps")
    moved.Buffer = type("Buffer", (), {"__module__": "oapo_lite.seps"})
    monkeypatch.setitem(sys.modules, "oapo_lite.seps", moved)
    for name, buffer_type in (("before_54", seps.Buffer), ("before_35", moved.Buffer)):
        shutil.copytree(tmp_path / "now", tmp_path / name)
        ck = load_checkpoint(tmp_path / name)
        ck["step"] = VecStep(**ck["step"])
        parts, ck["learner"]["buffer"] = ck["learner"]["buffer"], buffer_type()
        ck["learner"]["buffer"].parts = parts
        torch.save(ck, tmp_path / name / "checkpoint.pt")
        objects = torch.serialization.get_unsafe_globals_in_checkpoint(tmp_path / name / "checkpoint.pt")
        assert {"oapo_lite.envs.vec.VecStep", f"{buffer_type.__module__}.Buffer"} <= set(objects)
    monkeypatch.delitem(sys.modules, "oapo_lite.seps")
    for name in ("before_54", "before_35"):
        read = load_checkpoint(tmp_path / name)
        assert type(read["step"]) is dict and type(read["learner"]["buffer"]) is list
    ends = [train(cfg, tmp_path / name, progress=False) for name in ("now", "before_54", "before_35")]
    assert ends[0]["seps_groups"].iloc[-1] != ends[0]["seps_groups"].iloc[1]  # regrouped after the resume
    for name, end in zip(("before_54", "before_35"), ends[1:]):
        pd.testing.assert_frame_equal(learning(ends[0]), learning(end))
        assert _same(_params(tmp_path, "now"), _params(tmp_path, name))


def test_oappo_without_admissible_reuse_is_bitwise_happo(tmp_path):
    """Eq. 9 with sigma = 0 (no other policy is that close) or lambda = 1 gives M = I."""
    _run(tmp_path, "happo", algo="happo", **SMALL_BR)
    _run(tmp_path, "sigma0", algo="oappo", sigma=0.0, **SMALL_BR)
    _run(tmp_path, "lam1", algo="oappo", reuse_lambda=1.0, **SMALL_BR)
    _run(tmp_path, "reuse", algo="oappo", **SMALL_BR)
    happo = _params(tmp_path, "happo")
    assert _same(happo, _params(tmp_path, "sigma0"))
    assert _same(happo, _params(tmp_path, "lam1"))
    assert not _same(happo, _params(tmp_path, "reuse"))  # reuse does change the update


def test_oappo_warmed_up_for_the_whole_run_is_bitwise_happo_and_reuses_after_its_warm_up(tmp_path):
    """``reuse_warmup`` iterations with M = I: over a whole run, OAPPO is HAPPO bit for bit; with a
    warm-up of 2 of 4 iterations, the first two reuse nothing and the last two do."""
    small = {**SMALL_BR, "steps": 800}  # 4 iterations of 200 steps
    _run(tmp_path, "happo", algo="happo", **small)
    _run(tmp_path, "whole", algo="oappo", reuse_warmup=4, **small)
    assert _same(_params(tmp_path, "happo"), _params(tmp_path, "whole"))
    rows = _run(tmp_path, "half", algo="oappo", reuse_warmup=2, **small)
    assert [h["peer_share"] for h in load_history(tmp_path / "half")] == pytest.approx([0, 0, 0.3, 0.3])
    assert rows["iterations_reusing"].iloc[-1] == 0.5
    assert not _same(_params(tmp_path, "happo"), _params(tmp_path, "half"))
    with pytest.raises(ValueError, match="reuse_warmup"):
        TrainConfig(algo="happo", reuse_warmup=3)


def test_oappo_with_one_shared_network_and_uniform_reuse_is_bitwise_mappo(tmp_path):
    """A shared net is at KL 0 from itself, so Eq. 9 spreads each seat's row evenly: the
    mean over seats is 1/n for every source, MAPPO's matrix."""
    _run(tmp_path, "mappo", algo="mappo", **SMALL_BR)
    rows = _run(tmp_path, "oappo", algo="oappo", networks="one", reuse_lambda=0.5, **SMALL_BR)
    assert _same(_params(tmp_path, "mappo"), _params(tmp_path, "oappo"))
    assert np.array_equal(rows["reuse_matrix"].iloc[-1], [[0.5, 0.5], [0.5, 0.5]])
    on_disk = pd.read_csv(tmp_path / "oappo" / "results.csv")["reuse_matrix"].iloc[-1]
    assert on_disk == "[[0.5, 0.5], [0.5, 0.5]]"  # JSON text in the CSV
    _run(tmp_path, "happo", algo="happo", **SMALL_BR)
    assert not _same(_params(tmp_path, "mappo"), _params(tmp_path, "happo"))


BLACK_BLACK = MAPS["black_red"].replace("agents: red black", "agents: black black")  # one type of seat
LONE_BLACK = MAPS["black_red"].replace("agents: red black\nstart: 7,4 7,4", "agents: black\nstart: 7,4")


def test_networks_per_type_are_per_agent_for_distinct_types_and_mappo_for_one_type(tmp_path):
    """Issue 31's second reading: seats of one type share a net. Black-Red's two seats are of
    two types, so it is today's OAPPO bit for bit; with two black seats it is one shared net,
    at KL 0 from itself, so Eq. 9's rows average to 1/2 per source: MAPPO bit for bit."""
    _run(tmp_path, "oappo", algo="oappo", **SMALL_BR)
    _run(tmp_path, "type", algo="oappo", networks="type", **SMALL_BR)
    assert _same(_params(tmp_path, "oappo"), _params(tmp_path, "type"))
    one_kind = {**SMALL_BR, "env": BLACK_BLACK}
    _run(tmp_path, "mappo", algo="mappo", **one_kind)
    rows = _run(tmp_path, "type1", algo="oappo", networks="type", **one_kind)
    assert _same(_params(tmp_path, "mappo"), _params(tmp_path, "type1"))
    assert (rows["kl_matrix"].iloc[-1] == 0).all()  # one net: every seat at distance 0
    _run(tmp_path, "mappo_br", algo="mappo", **SMALL_BR)  # on Black-Red the types differ: not MAPPO
    assert not _same(_params(tmp_path, "mappo_br"), _params(tmp_path, "type"))


def test_a_shared_network_updated_seat_by_seat(tmp_path):
    """Issue 31's third reading (HARL's HAPPO with a shared actor): where every seat has its
    own net, seat by seat is net by net; with one net and M = I (lambda = 1) OAPPO is the
    shared-actor HAPPO bit for bit, which differs from one update on the seats' mean row;
    with one agent it is MAPPO bit for bit."""
    _run(tmp_path, "happo", algo="happo", **SMALL_BR)
    _run(tmp_path, "happo_seat", algo="happo", update_by="seat", **SMALL_BR)
    assert _same(_params(tmp_path, "happo"), _params(tmp_path, "happo_seat"))
    shared = dict(networks="one", update_by="seat", **SMALL_BR)
    _run(tmp_path, "shared_happo", algo="happo", **shared)
    _run(tmp_path, "shared_oappo", algo="oappo", reuse_lambda=1.0, **shared)
    assert _same(_params(tmp_path, "shared_happo"), _params(tmp_path, "shared_oappo"))
    _run(tmp_path, "shared_once", algo="happo", networks="one", **SMALL_BR)
    assert not _same(_params(tmp_path, "shared_happo"), _params(tmp_path, "shared_once"))
    lone = {**SMALL_BR, "env": LONE_BLACK}
    _run(tmp_path, "lone_mappo", algo="mappo", **lone)
    _run(tmp_path, "lone_seat", algo="oappo", networks="one", update_by="seat", **lone)
    assert _same(_params(tmp_path, "lone_mappo"), _params(tmp_path, "lone_seat"))


def test_update_units_weigh_a_shared_net_by_its_seats_rows():
    W = np.array([[0.6, 0.2, 0.2], [0.1, 0.8, 0.1], [0.0, 0.5, 0.5]])
    by_net = update_units(W, [0, 1, 0], "net")
    assert [(net, own) for net, _, own in by_net] == [(0, [0, 2]), (1, [1])]
    assert np.allclose(by_net[0][1], [0.3, 0.35, 0.35]) and np.array_equal(by_net[1][1], W[1])
    by_seat = update_units(W, [0, 1, 0], "seat")
    assert [(net, own) for net, _, own in by_seat] == [(0, [0]), (1, [1]), (0, [2])]
    assert all(np.array_equal(w, W[k]) for k, (_, w, _) in enumerate(by_seat))


def test_entropy_by_weight_changes_only_what_reuse_weights(tmp_path):
    """The entropy bonus times W[i, i]: nothing changes where W[i, i] = 1 (HAPPO), the update
    does change where Eq. 9 gives others weight (OAPPO, lambda 0.7)."""
    for algo in ("happo", "oappo"):
        _run(tmp_path, algo, algo=algo, **SMALL_BR)
        _run(tmp_path, f"{algo}_w", algo=algo, entropy_by_weight=True, **SMALL_BR)
    assert _same(_params(tmp_path, "happo"), _params(tmp_path, "happo_w"))
    assert not _same(_params(tmp_path, "oappo"), _params(tmp_path, "oappo_w"))


def test_sample_mode_trains_each_learner_on_one_source_drawn_from_m(tmp_path, monkeypatch):
    """Algorithm 1 line 5: in "sample" mode W is one-hot per learner, on a source M allows."""
    import oapo_lite.neural.ppo_family as train_module

    seen = []
    real = train_module.update_actors

    def spy(actors, opts, batch, units, *args):
        seen.append(np.stack([w for _, w, _ in units]))  # one net per seat: the rows of W
        return real(actors, opts, batch, units, *args)

    monkeypatch.setattr(train_module, "update_actors", spy)
    _run(tmp_path, "sample", algo="oappo", reuse_mode="sample", sigma=10.0, reuse_lambda=0.2,
         **{**SMALL_BR, "steps": 2000})
    history = load_history(tmp_path / "sample")
    drawn = np.array([W.argmax(1) for W in seen])
    for W, h in zip(seen, history):
        M = h["reuse_matrix"]
        assert ((W == 0) | (W == 1)).all() and (W.sum(1) == 1).all()
        assert (M[np.arange(2), W.argmax(1)] > 0).all()
    assert (drawn != np.arange(2)).any()  # with reuse_lambda = 0.2 the other seat is drawn sometimes


@pytest.mark.parametrize("algo", ["oappo", "oatrpo"])
def test_the_factor_is_the_product_of_the_updated_agents_ratios(algo):
    """After the sequential pass, rho = prod_i pi_i_new(a_i|o_i) / pi_i_old(a_i|o_i) over every
    learner, each evaluated with its final parameters (which no later learner touches)."""
    cfg = TrainConfig(algo=algo, env="black_blue_red", n_envs=8, rollout_len=20, steps=160, sigma=10.0)
    env = make_vec(cfg.env, cfg.n_envs, cfg.max_steps)
    actors = Actors(3, env.obs_dim, env.n_actions, cfg.hidden, False, torch.Generator().manual_seed(0))
    opts = [torch.optim.Adam(actors.net_params(k), lr=cfg.lr) for k in range(3)]
    batch, _ = collect(env, env.reset(), actors, [0, 1, 2], cfg.rollout_len, torch.Generator().manual_seed(1))
    W = np.full((3, 3), 1 / 3)
    adv = torch.randn(batch.act.shape[1], generator=torch.Generator().manual_seed(2))
    factor, _, _, _ = update_actors(actors, opts, batch, update_units(W, [0, 1, 2], "net"), [2, 0, 1], adv, ALGOS[algo],
                                 cfg, np.random.default_rng(0))
    explicit = torch.ones_like(factor)
    with torch.no_grad():
        for k in range(3):
            src = LearnerBatch(k, [k], [0], torch.ones(1), batch.act[[k]], batch.logp[[k]], torch.ones(1))
            logp_new = actors.head.log_prob(learner_dists(actors, batch.inputs, src)[0], batch.act[k])
            explicit *= torch.exp(logp_new) / torch.exp(batch.logp[k])
    assert not torch.allclose(factor, torch.ones_like(factor))  # the agents did move
    torch.testing.assert_close(factor, explicit, rtol=1e-4, atol=1e-6)


def test_every_accepted_trpo_step_stays_within_delta(tmp_path):
    _run(tmp_path, "trpo", algo="oatrpo", kl_threshold=0.005, **SMALL_BR)
    history = load_history(tmp_path / "trpo")
    kls = [k for h in history for k in h["trpo_kls"] if not math.isnan(k)]
    assert len(kls) >= len(history)  # most learner steps are accepted
    assert max(kls) <= 0.005


def _random_batch(actors: Actors, n: int, B: int, seed: int, obs_dim: int = 4, n_actions: int = 3) -> Rollout:
    """Seat k observes N(3k, 1) vectors, so every seat's observations are its own; actions
    drawn from the seat's policy. Only what the learner updates read is filled in."""
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(n, B, obs_dim, generator=g) + 3.0 * torch.arange(n)[:, None, None]
    avail = torch.ones(n, B, n_actions, dtype=torch.bool)
    with torch.no_grad():
        d = actors(obs, range(n), avail)
    act = Categorical.sample(d, g)
    return Rollout(Inputs.of(obs.numpy(), avail.numpy()), act, Categorical.log_prob(d, act), *[None] * 5)


def test_sample_mode_oatrpo_keeps_the_acting_policy_within_delta_on_its_own_observations():
    """Each learner drew the other's experience (W one-hot off the diagonal): the surrogate is
    on the other's samples, yet the KL on the learner's own observations stays <= delta."""
    delta = 0.01
    actors = Actors(2, 4, 3, (16,), False, torch.Generator().manual_seed(0))
    with torch.no_grad():  # policies far from uniform: their natural-gradient steps are not tiny
        for k in range(2):
            actors.weights[k][2].mul_(100.0)
    batch = _random_batch(actors, 2, 64, seed=1)
    old = copy.deepcopy(actors)
    W = np.array([[0.0, 1.0], [1.0, 0.0]])
    adv = torch.randn(64, generator=torch.Generator().manual_seed(2))
    _, _, kls, _ = update_actors(actors, [], batch, update_units(W, [0, 1], "net"), [0, 1], adv, ALGOS["oatrpo"],
                              TrainConfig(algo="oatrpo", kl_threshold=delta), np.random.default_rng(0))
    assert not any(math.isnan(k) for k in kls)  # both steps were taken
    with torch.no_grad():
        for k in range(2):
            own = LearnerBatch(k, [k], [0], torch.ones(1), batch.act[[k]], batch.logp[[k]], torch.ones(1))
            kl = Categorical.kl(learner_dists(old, batch.inputs, own), learner_dists(actors, batch.inputs, own))
            assert 1e-4 < kl.mean().item() <= delta * (1 + 1e-5)
    # the weights mode keeps Eq. 7's M-weighted KL as written
    src = LearnerBatch.of(0, np.array([0.7, 0.3]), [0], batch)
    assert torch.equal(src.kl_w, src.w)
    torch.testing.assert_close(LearnerBatch.of(0, W[0], [0], batch).kl_w, torch.ones(2))


@pytest.mark.parametrize("reduce", reuse.KL_REDUCES)
def test_policy_distances_are_kl_of_the_source_from_the_learner_on_the_source_observations(reduce):
    """K[i, j] = reduce over agent j's (active) observations of KL(pi_j || pi_i), pair by pair."""
    actors = Actors(3, 4, 3, (16,), False, torch.Generator().manual_seed(0))
    with torch.no_grad():
        for k in range(3):
            actors.weights[k][2].mul_(30.0)
    batch = _random_batch(actors, 3, 20, seed=1)
    obs = batch.inputs.obs[batch.inputs.index]  # (seat, sample, obs_dim)
    avail = torch.ones(20, 3, dtype=torch.bool)
    active = torch.rand(3, 20, generator=torch.Generator().manual_seed(2)) < 0.5
    for mask in (None, active):
        K = policy_distances(actors, batch.inputs, [0, 1, 2], reduce, mask)
        with torch.no_grad():
            for i in range(3):
                for j in range(3):
                    on = slice(None) if mask is None else mask[j]
                    source, learner = (actors(obs[j][None], [k], avail[None])[0] for k in (j, i))
                    kl = Categorical.kl(source, learner)[on]
                    expected = {"max": kl.max, "mean": kl.mean, "q90": lambda: torch.quantile(kl, 0.9)}[reduce]()
                    assert K[i, j] == pytest.approx(expected.item(), rel=1e-4, abs=1e-7)
        assert abs(K[0, 1] - K[1, 0]) > 1e-3  # not symmetric: the orientation is tested


def test_results_csv_holds_every_config_field_and_the_revision(tmp_path):
    rows = _run(tmp_path, "csv", algo="happo", **SMALL_BR)
    on_disk = pd.read_csv(tmp_path / "csv" / "results.csv")
    for field in TrainConfig.__dataclass_fields__:
        assert field in on_disk.columns
    for column in ("git_rev", "step", "eval_return", "frac_opt", "eval_success", "kl_matrix", "reuse_matrix"):
        assert column in on_disk.columns
    assert list(on_disk["step"]) == [0, 600] and len(rows) == 2
    assert not [p for p in (tmp_path / "csv").iterdir() if "tmp" in p.name]


def test_the_cli_trains_and_prints_a_summary(tmp_path, capsys):
    code = cli.main(["train", "--algo", "happo", "--env", "black_red", "--steps", "400", "--n-envs", "8",
                     "--rollout-len", "25", "--eval-episodes", "4", "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    out = capsys.readouterr().out
    assert "happo on black_red, seed 0: 400 env steps" in out and "of the optimum" in out
    assert len(list(tmp_path.glob("happo-black_red-s0-*/results.csv"))) == 1
    assert cli.main(["train", "--sigma", "-1", "--out", str(tmp_path)]) == 2


def test_pettingzoo_vec_on_the_maze_parallel_env_replays_vecmaze():
    maze = parse_maze("agents: red black\nstart: 1,1 1,1\n#####\n#..*#\n#####\n")
    pz = PettingZooVec(lambda: MazeParallelEnv(maze, max_steps=4), n_envs=5, seed=0)
    vec = make_vec(maze, 5, max_steps=4)
    assert (pz.n_agents, pz.obs_dim, pz.state_dim, pz.n_actions) == (vec.n_agents, vec.obs_dim, vec.state_dim, 5)
    rng = np.random.default_rng(0)
    steps = [(pz.reset(), vec.reset())] + [(pz.step(a), vec.step(a)) for a in rng.integers(0, 5, (40, 5, 2))]
    ended = {"terminated": 0, "truncated": 0}
    for a, b in steps:
        for name in a.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        ended["terminated"] += b.terminated.sum()
        ended["truncated"] += b.truncated.sum()
    assert min(ended.values()) > 0  # both kinds of episode end were compared


def test_training_through_pettingzoo_matches_training_on_vecmaze(tmp_path):
    kw = dict(algo="oappo", n_envs=4, rollout_len=10, steps=80, eval_every=1, eval_episodes=4, max_steps=10,
              bootstrap_truncation=True)
    vec = _run(tmp_path, "vec", env=CORRIDOR, **kw)
    pz = _run(tmp_path, "pz", env_fn=lambda: MazeParallelEnv(parse_maze(CORRIDOR), max_steps=10), **kw)
    assert _same(_params(tmp_path, "vec"), _params(tmp_path, "pz"))
    # the parallel env hands out float32 rewards, the vector core sums them in float64
    np.testing.assert_allclose(vec["eval_return"], pz["eval_return"], rtol=1e-6)
    assert pz["frac_opt"].isna().all()  # no oracle for a foreign environment


class Toy(ParallelEnv):
    """Two agents with chosen spaces; reward = agent a's first action dimension, 5 steps
    (agent b's episode may end earlier)."""

    metadata = {"name": "toy_v0"}

    def __init__(self, obs_dims=(3, 3), continuous=False, masked=None, leave=None):
        self.possible_agents = ["a", "b"]
        self.continuous, self.masked = continuous, masked
        self.leave = leave  # agent b terminates after this many steps, a plays on
        obs = {k: spaces.Box(-1, 1, (d,), np.float32) for k, d in zip(self.possible_agents, obs_dims)}
        if masked == "obs":
            obs = {k: spaces.Dict({"observation": o, "action_mask": spaces.MultiBinary(4)}) for k, o in obs.items()}
        self._obs = obs
        self._act = {k: spaces.Box(-1, 1, (2,), np.float32) if continuous else spaces.Discrete(4)
                     for k in self.possible_agents}

    def observation_space(self, agent):
        return self._obs[agent]

    def action_space(self, agent):
        return self._act[agent]

    def _mask(self):
        return np.array([1, 0, 1, self.t % 2], np.int8)

    def _observe(self):
        out = {}
        for k in self.agents:
            space = self._obs[k]["observation"] if self.masked == "obs" else self._obs[k]
            o = np.full(space.shape, self.t / 5, np.float32)
            out[k] = {"observation": o, "action_mask": self._mask()} if self.masked == "obs" else o
        return out

    def _infos(self, agents):
        return {k: {"action_mask": self._mask()} if self.masked == "info" else {} for k in agents}

    def reset(self, seed=None, options=None):
        self.agents, self.t = list(self.possible_agents), 0
        return self._observe(), self._infos(self.agents)

    def step(self, actions):
        if self.masked:
            assert all(actions[k] != 1 and (actions[k] != 3 or self.t % 2) for k in actions), "masked action taken"
        self.t += 1
        r = float(np.ravel(actions["a"])[0])
        done = self.t >= 5
        agents = self.agents
        obs = self._observe()
        ended = {k: done or (k == "b" and self.t == self.leave) for k in agents}
        self.agents = [k for k in agents if not ended[k]]
        return obs, {k: r for k in agents}, ended, {k: False for k in agents}, self._infos(agents)


def test_reuse_between_agents_with_different_spaces_raises(tmp_path):
    kw = dict(env_fn=lambda: Toy(obs_dims=(3, 5)), n_envs=2, rollout_len=10, steps=20, eval_episodes=2)
    for algo in ("oappo", "mappo"):
        with pytest.raises(ValueError, match=r"reuse between agents 'a' and 'b' needs equal spaces.*Box"):
            _run(tmp_path, algo, algo=algo, **kw)
    # no reuse needed: padded observations, separate nets, it trains
    assert len(_run(tmp_path, "happo", algo="happo", **kw)) == 2
    # reuse forbidden between the two by the allowed mask: fine as well
    assert len(_run(tmp_path, "masked", algo="oappo", allowed="NR", **kw)) == 2


@pytest.mark.parametrize("where", ["obs", "info"])
def test_action_masks_through_pettingzoo_are_respected(tmp_path, where):
    masked = PettingZooVec(lambda: Toy(masked=where), n_envs=2, seed=0)
    step = masked.reset()
    np.testing.assert_array_equal(step.avail[:, 0], [[True, False, True, False]] * 2)
    np.testing.assert_array_equal(masked.step(np.zeros((2, 2), int)).avail[:, 1], [[True, False, True, True]] * 2)
    assert masked.n_actions == 4 and not masked.continuous and masked.obs_dim == 3
    # the Toy env asserts that no masked action is ever sent
    _run(tmp_path, "masked", algo="oappo", env_fn=lambda: Toy(masked=where), n_envs=4, rollout_len=10, steps=200,
         eval_episodes=2)


def test_continuous_actions_through_pettingzoo(tmp_path):
    for algo in ("happo", "oatrpo"):
        rows = _run(tmp_path, f"box_{algo}", algo=algo, env_fn=lambda: Toy(continuous=True), n_envs=4,
                    rollout_len=10, steps=400, eval_episodes=4, eval_every=1)
        assert np.isfinite(rows["eval_return"]).all()


def test_reuse_in_one_direction_between_different_spaces_raises():
    env = PettingZooVec(lambda: Toy(obs_dims=(3, 5)), n_envs=1)
    for one_way in ([[1, 0], [1, 1]], [[1, 1], [0, 1]]):  # b learns from a; a learns from b
        with pytest.raises(ValueError, match="needs equal spaces"):
            check_spaces(env.agents, seat_spaces(env), np.array(one_way, bool))
    check_spaces(env.agents, seat_spaces(env), np.eye(2, dtype=bool))  # own experience only


def test_an_agent_that_leaves_early_is_inactive_until_the_episode_resets():
    vec = PettingZooVec(lambda: Toy(leave=2), n_envs=1)
    steps = [vec.reset()] + [vec.step(np.zeros((1, 2), int)) for _ in range(6)]
    np.testing.assert_array_equal([s.active[0] for s in steps],
                                  [[1, 1], [1, 1], [1, 0], [1, 0], [1, 0], [1, 1], [1, 1]])  # reset after 5
    assert (steps[3].obs[0, 1] == 0).all() and (steps[3].obs[0, 0] != 0).all()
    assert make_vec(CORRIDOR, 3).reset().active.all()


@pytest.mark.parametrize("algo", ["oappo", "oatrpo"])
def test_samples_of_an_agent_that_left_change_neither_k_nor_any_update(tmp_path, algo):
    """Seat b's samples after it left the episode are replaced by other observations, actions
    and behaviour probabilities: K and every learner's update stay the same. Read as active
    (no mask), the same replacement does change them, so the check can fail."""
    env = PettingZooVec(lambda: Toy(leave=2), n_envs=4, seed=0)
    actors = Actors(2, env.obs_dim, env.n_actions, (16,), False, torch.Generator().manual_seed(0))
    gen = torch.Generator().manual_seed(1)
    batch, _ = collect(env, env.reset(), actors, [0, 1], 10, gen)
    gone = ~batch.active
    assert gone[1].any() and not gone[0].any()
    inputs = dataclasses.replace(batch.inputs, index=torch.where(gone, batch.inputs.index[[0, 0]], batch.inputs.index))
    other = dataclasses.replace(batch, inputs=inputs, act=torch.where(gone, (batch.act + 1) % 4, batch.act),
                                logp=torch.where(gone, batch.logp - 1.0, batch.logp))
    adv = torch.randn(batch.act.shape[1], generator=gen)
    cfg = TrainConfig(algo=algo)

    def update(b: Rollout):
        net = copy.deepcopy(actors)
        opts = [] if ALGOS[algo].trust_region else [torch.optim.Adam(net.net_params(k), lr=cfg.lr) for k in range(2)]
        K = policy_distances(net, b.inputs, [0, 1], "mean", b.active)
        update_actors(net, opts, b, update_units(np.full((2, 2), 0.5), [0, 1], "net"), [1, 0], adv, ALGOS[algo], cfg,
                      np.random.default_rng(0))
        return K, net.state_dict()

    (K, params), (K_other, params_other) = update(batch), update(other)
    np.testing.assert_allclose(K, K_other, rtol=1e-6)
    for key in params:
        torch.testing.assert_close(params[key], params_other[key])
    (K, params), (K_other, params_other) = (update(dataclasses.replace(b, active=None)) for b in (batch, other))
    assert not np.allclose(K, K_other) and not _same(params, params_other)
    rows = _run(tmp_path, algo, algo=algo, env_fn=lambda: Toy(leave=2), n_envs=2, rollout_len=10, steps=40,
                eval_episodes=2)
    assert np.isfinite(rows["eval_return"]).all()


# issue 22: the SMAX settings' options (lr_anneal, value_norm), at defaults that change nothing
def test_lr_anneal_falls_linearly_to_zero_and_sets_every_optimiser(tmp_path):
    cfg = TrainConfig(algo="mappo", steps=160 * 4, lr_anneal=True, **TINY)
    assert [cfg.lr_scale(it) for it in range(5)] == [1.0, 0.75, 0.5, 0.25, 0.0]
    assert TrainConfig(algo="mappo", steps=160 * 4, **TINY).lr_scale(3) == 1.0  # off by default
    train(cfg, tmp_path / "run", progress=False)
    assert [h["lr_scale"] for h in load_history(tmp_path / "run")] == [1.0, 0.75, 0.5, 0.25]
    ck = load_checkpoint(tmp_path / "run")  # the optimisers as the last iteration left them: lr / 4
    assert ck["learner"]["actor_opt0"]["param_groups"][0]["lr"] == pytest.approx(cfg.lr / 4)
    assert ck["learner"]["critic_opt"]["param_groups"][0]["lr"] == pytest.approx(cfg.critic_lr / 4)
    assert not _same(_params(tmp_path, "run"),
                     (_run(tmp_path, "const", algo="mappo", steps=160 * 4, **TINY), _params(tmp_path, "const"))[1])
    seac = TrainConfig(algo="seac", steps=80 * 3, lr_anneal=True, **{**TINY, "rollout_len": 5})
    train(seac, tmp_path / "seac", progress=False)
    assert [h["lr_scale"] for h in load_history(tmp_path / "seac")][-1] == pytest.approx(1 / seac.n_iterations)
    opt = load_checkpoint(tmp_path / "seac")["learner"]["a2c"]["opts"][0]
    assert opt["param_groups"][0]["lr"] == pytest.approx(seac.a2c_lr / seac.n_iterations)


@pytest.mark.parametrize("algo", ["oappo", "oatrpo"])
def test_annealed_run_without_value_norm_resumes_to_the_uninterrupted_numbers(tmp_path, algo):
    cfg = TrainConfig(algo=algo, steps=160 * 7, checkpoint_every=2, lr_anneal=True, value_norm=False, **TINY)
    full = train(cfg, tmp_path / "full", progress=False)

    fakes.interrupt(cfg, tmp_path / "resumed", at=5)
    _assert_same_run(tmp_path, "full", full, "resumed", train(cfg, tmp_path / "resumed", progress=False))
    # the schedule depends on steps: an annealed run cannot be extended
    with pytest.raises(ValueError, match="lr_anneal"):
        train(dataclasses.replace(cfg, steps=160 * 9), tmp_path / "full", progress=False)


def test_value_norm_off_regresses_on_raw_returns(tmp_path):
    on = _run(tmp_path, "on", algo="mappo", steps=160 * 3, **TINY)
    off = _run(tmp_path, "off", algo="mappo", steps=160 * 3, value_norm=False, **TINY)
    assert load_checkpoint(tmp_path / "off")["learner"]["value_norm"]["debias"] == 0  # never updated
    assert load_checkpoint(tmp_path / "on")["learner"]["value_norm"]["debias"] > 0
    assert not np.allclose(on["value_loss"].iloc[1:], off["value_loss"].iloc[1:])
    with pytest.raises(ValueError, match="lr_anneal"):
        TrainConfig(lr_anneal=1)


@pytest.mark.parametrize("algo", ["oappo", "happo", "mappo"])
def test_every_iteration_records_its_reuse_and_the_rows_its_share(tmp_path, algo):
    """The history holds every iteration's peer share (M's off-diagonal mass) and each learner's
    nearest distance; an evaluation row holds the share of iterations so far with any reuse."""
    rows = _run(tmp_path, algo, algo=algo, **{**SMALL_BR, "steps": 1200})
    history = load_history(tmp_path / algo)
    assert len(history) == 6
    for h in history:
        assert h["peer_share"] == pytest.approx(reuse.peer_share(h["reuse_matrix"]), abs=1e-6)
        if not np.isnan(h["kl_matrix"]).any():
            np.testing.assert_allclose(h["kl_nearest"], reuse.nearest_peer(h["kl_matrix"]), atol=1e-6)
    share = {"oappo": 0.3, "happo": 0.0, "mappo": 0.5}[algo]  # untrained nets are within sigma of each other
    assert [h["peer_share"] for h in history] == pytest.approx([share] * 6)
    assert rows["iterations_reusing"].isna().iloc[0]  # before any iteration
    assert rows["iterations_reusing"].iloc[1:].tolist() == [float(share > 0)] * 2


@pytest.mark.parametrize("algo", ["happo", "oatrpo"])
def test_feature_norm_trains_its_layernorms_and_resumes_to_the_uninterrupted_numbers(tmp_path, algo):
    """HARL's feature normalisation as an option: its scale and shift are trained (they leave
    1 and 0), are checkpointed, and a resumed run ends as the uninterrupted one."""
    cfg = TrainConfig(algo=algo, steps=160 * 5, checkpoint_every=2, feature_norm=True, **TINY)
    full = train(cfg, tmp_path / "full", progress=False)
    fakes.interrupt(cfg, tmp_path / "resumed", at=3)
    _assert_same_run(tmp_path, "full", full, "resumed", train(cfg, tmp_path / "resumed", progress=False))
    params = _params(tmp_path, "full")
    assert not torch.equal(params["norms.0.0"], torch.ones_like(params["norms.0.0"]))
    assert load_checkpoint(tmp_path / "full")["learner"]["critic"]["net.0.weight"].ndim == 1  # the critic's LayerNorm comes first


# ---------------------------------------------------------------- live diagnostics (issue 34)


def test_update_diagnostics_match_their_closed_forms():
    from oapo_lite.neural.losses import explained_variance, update_diagnostics

    logp_old = torch.log(torch.tensor([0.5, 0.2, 0.4, 0.1]))
    ratio = np.array([1.5, 0.9, 1.0, 0.7])
    logp_new = logp_old + torch.log(torch.tensor(ratio, dtype=torch.float32))
    entropy = torch.tensor([1.0, 2.0, 3.0, 4.0])
    d = update_diagnostics(logp_new, logp_old, entropy, None, clip=0.2)
    assert d["approx_kl"] == pytest.approx(np.mean((ratio - 1) - np.log(ratio)), rel=1e-5)
    assert d["clip_frac"] == 0.5 and d["entropy"] == 2.5  # 1.5 and 0.7 leave [0.8, 1.2]
    unchanged = update_diagnostics(logp_old, logp_old, entropy, torch.tensor([True, True, False, False]), None)
    assert unchanged["approx_kl"] == 0 and np.isnan(unchanged["clip_frac"]) and unchanged["entropy"] == 1.5
    target = torch.tensor([1.0, 2.0, 4.0, 7.0])
    assert explained_variance(target, target) == 1.0
    assert explained_variance(torch.full((4,), target.mean().item()), target) == pytest.approx(0.0, abs=1e-6)
    assert np.isnan(explained_variance(target, torch.ones(4)))


@pytest.mark.parametrize("algo", ["oappo", "oatrpo", "mappo", "seac"])
def test_the_history_carries_each_learners_diagnostics(tmp_path, algo):
    from oapo_lite.neural.runstate import load_history

    cfg = TrainConfig(algo=algo, env="black_red", n_envs=8, steps=1600, eval_every=2, eval_episodes=4,
                      **({} if ALGOS[algo].a2c else dict(rollout_len=25)))
    rows = train(cfg, tmp_path, resume=False, progress=False)
    history = load_history(tmp_path)
    assert len(history) == cfg.n_iterations
    for entry in history:
        nets = sorted(learner["net"] for learner in entry["learners"])
        assert nets == sorted(set(nets)) and len(nets) == (1 if algo == "mappo" else 2)
        for learner in entry["learners"]:
            assert learner["approx_kl"] >= 0 and 0 <= learner["entropy"] <= np.log(5) + 1e-6
            assert np.isnan(learner["clip_frac"]) if algo in ("oatrpo", "seac") else 0 <= learner["clip_frac"] <= 1
        if not ALGOS[algo].a2c:
            assert entry["explained_variance"] <= 1
            assert entry["peer_shares"] == pytest.approx((1 - np.diag(entry["reuse_matrix"])).tolist(), abs=1e-6)
    assert "learners" not in rows.columns  # the results rows keep their columns


def test_tensorboard_scalars_are_the_history_and_change_no_number(tmp_path):
    pytest.importorskip("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from oapo_lite.neural.runstate import load_history

    cfg = TrainConfig(algo="oappo", env="black_red", n_envs=8, rollout_len=25, steps=1600, eval_every=2,
                      eval_episodes=4)
    plain = train(cfg, tmp_path / "plain", resume=False, progress=False)
    watched = train(cfg, tmp_path / "watched", resume=False, progress=False, tensorboard=tmp_path / "tb")
    assert learning(plain).drop(columns="git_rev").equals(learning(watched).drop(columns="git_rev"))
    events = EventAccumulator(str(tmp_path / "tb"))
    events.Reload()
    history = load_history(tmp_path / "watched")
    kl = {e.step: e.value for e in events.Scalars("learner 0/approx_kl")}
    assert kl == pytest.approx({h["step"]: next(x["approx_kl"] for x in h["learners"] if x["net"] == 0)
                                for h in history}, rel=1e-6)
    assert [e.step for e in events.Scalars("evaluation/frac_opt")] == watched["step"].tolist()
    assert {"peer share/red", "peer share/black", "critic/explained_variance"} <= set(events.Tags()["scalars"])
    rate = {e.step: e.value for e in events.Scalars("time/steps_per_second")}
    assert rate == pytest.approx({h["step"]: h["steps_per_s"] for h in history}, rel=1e-6)


def test_every_row_and_iteration_records_what_the_run_has_cost_and_a_resume_adds_to_it(tmp_path):
    from oapo_lite.neural.cost import machine

    cfg = TrainConfig(algo="oappo", steps=160 * 8, checkpoint_every=2, **TINY)
    full = train(cfg, tmp_path / "full", progress=False)
    history = load_history(tmp_path / "full")
    for frame in (full, pd.DataFrame(history)):
        assert (frame["cpu_s"] > 0).all() and frame["cpu_s"].is_monotonic_increasing
        assert (frame["wall_s"] > 0).all() and frame["wall_s"].is_monotonic_increasing
    assert (full[["cpu_model", "cpu_count"]] == list(machine().values())).all().all()
    assert all(h["steps_per_s"] > 0 for h in history)
    # a resumed run adds to the sums it left in its checkpoint
    fakes.interrupt(cfg, tmp_path / "resumed", at=3)
    before = load_checkpoint(tmp_path / "resumed")["cost"]
    resumed = train(cfg, tmp_path / "resumed", progress=False)
    assert resumed["cpu_s"].iloc[-1] > before["cpu_s"] > 0 and resumed["wall_s"].iloc[-1] > before["wall_s"]
    pd.testing.assert_frame_equal(learning(full), learning(resumed))
    # a checkpoint written before costs were recorded: the rest of the run is unmeasured, not undercounted
    fakes.interrupt(cfg, tmp_path / "old", at=3)
    ck = load_checkpoint(tmp_path / "old")
    del ck["cost"]
    torch.save(ck, tmp_path / "old" / "checkpoint.pt")
    old = train(cfg, tmp_path / "old", progress=False)
    assert old["cpu_s"].iloc[:2].notna().all() and old["cpu_s"].iloc[2:].isna().all()
    pd.testing.assert_frame_equal(learning(full), learning(old))
