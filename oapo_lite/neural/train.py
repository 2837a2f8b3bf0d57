"""One training loop for OAPPO, OATRPO, HAPPO, HATRPO, MAPPO and IPPO (Algorithm 1), and for
the experience-sharing baselines SEAC and SePS.

Each iteration collects a vectorised rollout with every seat's policy (``rollout.collect``)
and hands it to the run's learner (``learner.Learner``): for the PPO / TRPO family the joint
advantage from one centralised critic and GAE, the policy distances K and the reuse matrix M
(Eq. 9), the learners updated one after another in a random order, each on the M-weighted
experience of its sources (Eq. 8, or Eq. 7's trust-region step) with the sequential factor,
then the critic; for SEAC / SePS their A2C step. Then the loop evaluates and
checkpoints. ``train(cfg, out_dir)`` returns the evaluation rows as a DataFrame and keeps
``results.csv`` and ``checkpoint.pt`` in ``out_dir``; the per-iteration history lives in the
checkpoint (``runstate.load_history``).
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import torch

from oapo_lite.cli import boolean, writable_folder
from oapo_lite.neural.board import Board
from oapo_lite.neural.config import TrainConfig, derive_seed
from oapo_lite.neural.cost import Meter, clocks, machine
from oapo_lite.neural.learner import WANTS, Observer
from oapo_lite.neural.losses import Diverged
from oapo_lite.neural.results import stored
from oapo_lite.neural.rollout import collect, episode_scores
from oapo_lite.neural.runstate import RunState, git_revision, load_checkpoint, nonfinite, save_results
from oapo_lite.store import Lock


def train(cfg: TrainConfig, out_dir: str | Path, resume: bool = True, progress: bool = True,
          callback: Callable[[dict], None] | None = None, timing: dict | None = None,
          tensorboard: str | Path | None = None, observer: Observer | None = None) -> pd.DataFrame:
    """Train ``cfg`` and return one row per evaluation point (also in ``out_dir/results.csv``).

    ``results.csv`` is written with every checkpoint. With ``resume``, continue from
    ``out_dir/checkpoint.pt`` if present (and write ``results.csv`` again from it); the result
    is then identical to an uninterrupted run. ``callback(metrics)`` is called after every
    iteration. A ``timing`` dict is filled with the seconds spent in env stepping, policy
    forwards during rollouts, learning and evaluation (for the benchmarks). The per-iteration
    metrics are in the checkpoint: ``runstate.load_history(out_dir)``, with each learner's
    diagnostics (approximate KL, clip fraction, entropy), the critic's explained variance and
    every seat's peer share; ``tensorboard`` (a folder) also writes them as TensorBoard
    scalars while the run trains (``board.py``). ``observer`` (``learner.Observer``) receives
    every iteration's ``learner.Update`` with what its ``wants`` asked the learner for.
    """
    if not isinstance(cfg, TrainConfig):
        raise TypeError(f"train's cfg must be a TrainConfig, got {type(cfg).__name__} {cfg!r}; "
                        "e.g. train(TrainConfig(algo='oappo'), 'runs/x')")
    if not isinstance(out_dir, (str, os.PathLike)) or not str(out_dir).strip():
        raise TypeError(f"train's out_dir must be a folder path (a non-empty str or a Path), got "
                        f"{type(out_dir).__name__} {out_dir!r}")
    if tensorboard is not None and (not isinstance(tensorboard, (str, os.PathLike)) or not str(tensorboard).strip()):
        raise TypeError(f"train's tensorboard must be None or a folder path, got {tensorboard!r}")
    if tensorboard is not None:  # checked before the run starts, not where the first scalar is written
        tensorboard = writable_folder(str(tensorboard), "train's tensorboard")
    if callback is not None and not callable(callback):
        raise TypeError(f"train's callback must be None or callable with an iteration's metrics, got {callback!r}")
    if timing is not None and not isinstance(timing, dict):
        raise TypeError(f"train's timing must be None or a dict to fill with seconds per phase, got {timing!r}")
    if observer is not None and not (callable(observer) and set(getattr(observer, "wants", ())) <= WANTS.keys()):
        raise TypeError(f"train's observer must be callable with a wants set within {sorted(WANTS)}, got "
                        f"{observer!r}")
    resume, progress = boolean(resume, "train's resume"), boolean(progress, "train's progress")
    out = Path(out_dir)
    start = clocks()  # building the envs (a JAX compile, GRF's engines) is part of the run's cost
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # bit-reproducible, and two runs can share two cores
    lock = None
    try:
        # the env and learner first: what the config asks of the env (a seat count, a mask's shape)
        # is refused before a run folder exists
        state = RunState.start(cfg)
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OSError(f"cannot create the run folder {out} ({err.strerror}); choose another output folder "
                          "(--out on the command line)") from None
        lock = Lock(out / ".lock")  # two processes on one run: the second waits, then resumes where the first ended
        if not lock.acquire(wait=False):
            print(f"waiting for another process that is training {out}", file=sys.stderr, flush=True)
            lock.acquire()
            start = clocks()  # the wait is not the run's cost
        return _train(state, out, resume, progress, callback, {} if timing is None else timing, tensorboard, start,
                      observer)
    finally:
        torch.set_num_threads(threads)
        if lock is not None:
            lock.release()


def iterate(state: RunState, clock: dict, observer: Observer | None = None) -> dict:
    """One iteration: a rollout from where the last one ended, then the learner's update, asked
    for K where the iteration is evaluated and for what ``observer`` wants. Appends to
    ``state.history`` and returns the metrics that go into the next evaluation row."""
    cfg, it = state.cfg, state.iteration
    batch, state.step = collect(state.env, state.step, state.actors, state.owner, cfg.rollout_steps, state.act_gen)
    for part, seconds in batch.seconds.items():
        clock[part] += seconds
    tic = time.perf_counter()
    if cfg.lr_anneal:  # set every iteration from the config: a resumed run continues the same schedule
        for opt, lr in state.learner.optimisers():
            for group in opt.param_groups:
                group["lr"] = lr * cfg.lr_scale(it)
    wanted = frozenset({"kl"} if cfg.evaluates(it + 1) else ())  # the results rows' kl_matrix
    if observer is not None:
        wanted |= observer.wants
    update = state.learner.learn(batch, it, wanted)
    clock["learn"] += time.perf_counter() - tic
    if observer is not None:
        observer(it + 1, update)
    metrics, detail = stored(update.metrics), stored(update.detail)
    state.iteration = it + 1
    state.history.append({"iteration": it + 1, "step": (it + 1) * cfg.iteration_steps, **metrics, **detail,
                          **({"lr_scale": cfg.lr_scale(it)} if cfg.lr_anneal else {})})
    return metrics


def evaluation_row(state: RunState, metrics: dict, revision: str) -> dict:
    """The results row of the current iteration: the first episode of every evaluation copy,
    stochastic policies, from a generator seeded by (seed, iteration), so that evaluating draws
    nothing from the run's own randomness and a resumed run evaluates alike."""
    cfg, it = state.cfg, state.iteration
    gen = torch.Generator().manual_seed(derive_seed(cfg.seed, 3, it))
    ret, success = episode_scores(state.actors, state.owner, state.eval_env, gen, cfg.max_steps)
    return {**cfg.flat(), "git_rev": revision, "iteration": it, "step": it * cfg.iteration_steps,
            "eval_return": ret, "frac_opt": ret / state.env.optimum, "eval_success": success, **metrics,
            **({"iterations_reusing": iterations_reusing(state.history)} if "peer_share" in metrics else {}),
            **state.structure()}


UNMEASURED = {"cpu_s": np.nan, "wall_s": np.nan, "cpu_model": np.nan, "cpu_count": np.nan}


def iterations_reusing(history: list[dict]) -> float:
    """The share of the run's iterations so far in which some learner gave another agent's
    experience a positive weight (peer share > 0): how much of the run reuse operated in, read
    from every iteration, not the evaluated ones alone."""
    return float(np.mean([h["peer_share"] > 0 for h in history]))


def _train(state: RunState, out: Path, resume: bool, progress: bool, callback, clock: dict,
           tensorboard: str | Path | None, start: tuple[float, float], observer: Observer | None) -> pd.DataFrame:
    from tqdm import tqdm  # tqdm.auto warns in notebooks without ipywidgets, even when disabled

    cfg, revision = state.cfg, git_revision()
    if resume and (out / "checkpoint.pt").exists():
        state.load_state_dict(load_checkpoint(out), out / "checkpoint.pt")
        save_results(state.rows, out)  # a results.csv deleted or damaged after the checkpoint comes back
    clock.update(env=0.0, policy=0.0, learn=0.0, eval=0.0)
    board = None if tensorboard is None else Board(tensorboard, state.env.agents)
    meter = None if state.cost is None else Meter(state.cost, (state.env, state.eval_env), start)

    def spent() -> dict:
        """The run's cost so far, and where it was measured (NaN: unmeasured)."""
        return {**meter.read(), **machine()} if meter is not None else UNMEASURED

    def evaluate_now(metrics: dict) -> None:
        tic = time.perf_counter()
        state.rows.append({**evaluation_row(state, metrics, revision), **spent()})
        clock["eval"] += time.perf_counter() - tic
        if board is not None:
            board.evaluation(state.rows[-1])

    try:
        if state.iteration == 0:
            evaluate_now({})
        bar = tqdm(range(state.iteration, cfg.n_iterations), initial=state.iteration, total=cfg.n_iterations,
                   desc=f"{cfg.algo} seed {cfg.seed}", disable=None if progress else True)
        for _ in bar:
            tic = time.perf_counter()
            try:
                metrics = iterate(state, clock, observer)
            except Diverged as err:
                raise _diverged_at(err, state, out) from None
            # env steps per wall second of this iteration (SB3's time/fps, CleanRL's SPS)
            rate = cfg.iteration_steps / max(time.perf_counter() - tic, 1e-9)
            state.history[-1].update({"steps_per_s": rate, **{k: v for k, v in spent().items() if k.endswith("_s")}})
            bar.set_postfix_str(f"{rate:,.0f} env steps/s", refresh=False)
            if cfg.evaluates(state.iteration):
                evaluate_now(metrics)
            if state.iteration % cfg.checkpoint_every == 0 or state.iteration == cfg.n_iterations:
                # results.csv goes with the checkpoint, so the two always agree (and rewriting the
                # growing CSV at every evaluation cost a tenth of a paper-budget run)
                state.save(out)
            if board is not None:
                board.iteration(state.history[-1])
            if callback is not None:
                callback(state.history[-1])
    finally:
        if board is not None:
            board.close()
    return pd.DataFrame(state.rows)


def _diverged_at(err: Diverged, state: RunState, out: Path) -> Diverged:
    """``err`` told with the iteration, the seats of the learner (a net index) and the checkpoint."""
    net, owner, agents = err.net, state.owner, state.env.agents
    if isinstance(net, (int, np.integer)):
        net = f"{net} (seats {[agents[k] for k in range(len(owner)) if owner[k] == net]})"
    path = out / "checkpoint.pt"
    if path.exists():
        ck = load_checkpoint(out)
        bad = nonfinite(ck, ("actors", "learner"))
        last = (f"the last checkpoint {path} (iteration {ck['iteration']}) is left as it was" + (
            f", but it already holds non-finite values ({', '.join(bad[:3])}), so resuming from it diverges again; "
            "start afresh (--no-resume) with other settings" if bad else ""))
    else:
        last = "no checkpoint had been written yet"
    return Diverged(err.quantity, net, f"iteration {state.iteration + 1} of {state.cfg.algo} seed {state.cfg.seed}: ",
                    f"; the run stopped and {last}")
