"""What OAPPO's reuse costs against HAPPO's, side by side in one process, on 2s3z (Fig. 4's
settings) and HalfCheetah 2x3 (App. A's): CPU seconds per 1,000 env steps of the whole loop and
its ratio to HAPPO's, learning's share of the loop's time, and the sources a learner trains on
(seats with a positive weight in M, per learner and iteration: HAPPO 1).

In Eq. 8's weights mode a learner evaluates and differentiates its network on the samples of
every source it reuses, so its learning grows with that count; the "sample" reading (Algorithm
1's lines 5-6: one source drawn from M per learner and iteration) trains on one seat's samples,
as HAPPO does. HAPPO is measured first and last, so that drift on a shared machine shows.

Each run's update is then split into where its CPU time goes, per 1,000 env steps: the
learners' surrogate forwards (Eq. 8 on every source's samples, with the per-source importance
ratios), their backward passes and Adam steps, K between every pair of networks (Eq. 9), the
rest of the sequential update (each learner's diagnostics and the factor rho) and the critic.
The extra over HAPPO's column is what reuse costs in that part.

    .venv/bin/python benchmarks/reuse_cost.py [--envs smax:2s3z mamujoco:HalfCheetah-2x3] [--periods 1]
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import tempfile
import time

import numpy as np

from oapo_lite.neural import ppo_family
from oapo_lite.neural.runstate import load_history
from oapo_lite.neural.train import train
from oapo_lite.study.catalogue import figures

from loops import cut_short, warm_up

FIGURE = {"smax:2s3z": "fig4_smax", "mamujoco:HalfCheetah-2x3": "figA_mamujoco"}
READINGS = {  # label of the figure's curve, and what changes from it
    "happo": ("happo", {}),
    "oappo a net per agent": ("oappo", {}),
    "oappo a net per type": ("oappo type", {}),
    "oappo one net, seat by seat": ("oappo one seat", {}),
    "oappo a net per agent, always (sigma inf)": ("oappo", {"sigma": float("inf")}),
    "oappo a net per agent, sampled source": ("oappo", {"reuse_mode": "sample"}),
    "happo again": ("happo", {}),
}


# the update's parts, as (name, module, function): each is timed where the update calls it; a
# part named after another is inside it, and is taken out of it
PARTS = (("the update", ppo_family.PPOFamilyLearner, "learn"), ("surrogate forwards", ppo_family, "ppo_loss"),
         ("of which the ratios", ppo_family, "off_agent_objective"), ("learners' updates", ppo_family, "update_actors"),
         ("K (Eq. 9)", ppo_family, "pairwise_distances"), ("critic", ppo_family, "update_critic"),
         ("advantage", ppo_family, "advantages"))


@contextlib.contextmanager
def timed_parts():
    """CPU seconds spent in each of ``PARTS`` (a dict filled while the block runs)."""
    spent = dict.fromkeys((name for name, _, _ in PARTS), 0.0)
    originals = [(module, fn, getattr(module, fn)) for _, module, fn in PARTS]

    def timer(name, f):
        def wrapped(*args, **kwargs):
            tic = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                spent[name] += time.process_time() - tic
        return wrapped

    for (name, module, fn), (_, _, f) in zip(PARTS, originals):
        setattr(module, fn, timer(name, f))
    try:
        yield spent
    finally:
        for module, fn, f in originals:
            setattr(module, fn, f)


def breakdown(spent: dict) -> dict:
    """The update's CPU seconds split into parts that do not overlap (``PARTS``)."""
    ratios = spent["of which the ratios"]
    forwards = spent["surrogate forwards"] - ratios
    rest = spent["learners' updates"] - spent["surrogate forwards"]
    named = {"surrogate forwards": forwards, "importance ratios": ratios,
             "backward passes, Adam, diagnostics, factor": rest, "K (Eq. 9)": spent["K (Eq. 9)"],
             "critic and advantage": spent["critic"] + spent["advantage"]}
    return {**named, "the rest of the update": spent["the update"] - sum(named.values())}


def measure(cfg) -> dict:
    """CPU seconds per 1,000 env steps of ``train(cfg)`` (this process), of its learning and of
    its update's parts (``breakdown``), and the sources a learner trains on, per learner and
    iteration."""
    with tempfile.TemporaryDirectory() as out:
        train(dataclasses.replace(cfg, steps=cfg.iteration_steps), out + "/warm", progress=False)  # builds the env
        timing = {}
        with timed_parts() as spent:
            tic, wall = time.process_time(), time.perf_counter()
            train(cfg, out + "/run", progress=False, timing=timing)
            cpu, wall = time.process_time() - tic, time.perf_counter() - wall
        history = load_history(out + "/run")
    sources = [np.count_nonzero(np.asarray(h["reuse_matrix"]) > 0, axis=1).mean() for h in history
               if "reuse_matrix" in h]
    per_k = 1000 / cfg.steps
    return {"loop": per_k * cpu, "learn": timing["learn"] / wall,
            "parts": {k: per_k * v for k, v in breakdown(spent).items()},
            "sources": float(np.mean(sources)) if sources and cfg.reuse_mode == "weights" else np.nan}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=list(FIGURE))
    parser.add_argument("--periods", type=int, default=1, help="evaluation periods per run")
    args = parser.parse_args()
    warm_up()
    for env in args.envs:
        print(f"\n{env}: CPU seconds per 1,000 env steps of the whole loop (the env built before), against "
              "HAPPO's first run; below each, the update's parts (CPU-s per 1,000 steps, and the extra over HAPPO's)")
        base = None
        for name, (label, change) in READINGS.items():
            if label not in {r.label for r in figures.runs_of(FIGURE[env], "cpu")}:
                continue
            cfg = cut_short(FIGURE[env], "cpu", label, env, 1)
            cfg = dataclasses.replace(cfg, steps=args.periods * cfg.eval_every * cfg.iteration_steps, **change)
            m = measure(cfg)
            base = base or m
            sources = "one drawn from M" if np.isnan(m["sources"]) else f"{m['sources']:.2f}"
            print(f"  {name:44s} {m['loop']:.3f} CPU-s ({m['loop'] / base['loop']:.2f}x HAPPO's), learning "
                  f"{m['learn']:.0%} of the loop's time, sources per learner {sources}", flush=True)
            parts = (f"{part} {v:.3f} ({v - base['parts'][part]:+.3f})" for part, v in m["parts"].items())
            print("      " + "; ".join(parts), flush=True)


if __name__ == "__main__":
    main()
