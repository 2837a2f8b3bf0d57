"""Google Research Football (``gfootball``) academy scenarios behind the ``VecEnv`` interface (``envs.vec``).

As in HARL's GRF setup (PKU-MARL/HARL): one controlled left-team player per agent, ``simple115v2``
observations, ``scoring,checkpoints`` rewards, the team reward (the mean of the players'
rewards, which the two reward terms make equal) for everyone. The global state is every
agent's observation, concatenated. ``episode_success`` is 1 when the left team scored.

Copies run in worker processes (one per core, each stepping its share of the copies), so
the engine's C++ stepping of both halves happens at the same time; the main process only
sends actions and stacks the answers. Copy k's engine is seeded with
``copy_seed(seed, k)`` (``game_engine_random_seed``); the engine re-seeds itself from that
seed on every reset, so an episode depends on the seed and the actions alone.
"""
from __future__ import annotations

import contextlib
import importlib.util
import io
import math
import multiprocessing as mp
import os
import pickle
import warnings
import weakref

import numpy as np

from .vec import VecStep, check_copies

# scenario -> number of controlled left players (= agents), HARL's choice
SCENARIOS = {
    "academy_pass_and_shoot_with_keeper": 2,
    "academy_3_vs_1_with_keeper": 3,
    "academy_counterattack_easy": 4,
    "academy_counterattack_hard": 4,
}
OBS_DIM = 115  # simple115v2
GAME_DURATION = 400  # every scenario above sets the engine's game_duration to 400 steps
N_ACTIONS = 19  # gfootball's default action set
INSTALL_HINT = ("Google Research Football is not installed in this Python; install it with `make grf` "
                "(system libraries, then gfootball==2.10.2 built from source, ~7 min; see requirements-grf.txt)")


def installed() -> bool:
    return importlib.util.find_spec("gfootball") is not None


def install_hint() -> str | None:
    """None when gfootball is installed, else how to install it (see ``registry``)."""
    return None if installed() else INSTALL_HINT


class NotInstalled(ImportError):
    """gfootball is missing: the message says how to install it."""


def check(name: str) -> None:
    """Raise ``ValueError`` for an unknown scenario (cheap: gfootball is not imported, and
    configs of GRF runs can be listed without it)."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown GRF scenario {name!r}; scenarios are {sorted(SCENARIOS)}")


def copy_seed(seed: int, k: int) -> int:
    """The engine seed of copy k of a run with ``seed`` (31 bits, as the engine takes an int)."""
    return int(np.random.SeedSequence([seed, k]).generate_state(1)[0] >> 1)


def _make_engine(name: str, seed: int):
    # gym 0.25's import-time notice and old-step-API warnings concern gfootball's wrappers, not us
    with contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import gfootball.env as football_env

        return football_env.create_environment(
            env_name=name, representation="simple115v2", rewards="scoring,checkpoints", stacked=False,
            number_of_left_players_agent_controls=SCENARIOS[name],
            other_config_options={"game_engine_random_seed": seed})


class _Copies:
    """Some copies of one scenario with auto-reset, stepped one after another (inside a worker)."""

    def __init__(self, name: str, seeds: list[int], max_steps: int):
        self.envs = [_make_engine(name, s) for s in seeds]
        self.max_steps = max_steps
        self.t = np.zeros(len(seeds), np.int64)
        self.returns = np.zeros(len(seeds), np.float64)
        self.scored = np.zeros(len(seeds), bool)

    def reset(self) -> np.ndarray:
        self.t[:], self.returns[:], self.scored[:] = 0, 0.0, False
        return np.stack([env.reset() for env in self.envs]).astype(np.float32)

    def step(self, actions: np.ndarray, which: np.ndarray) -> tuple:
        """(obs, final_obs, reward, terminated, truncated, episode_return, episode_success), one row per
        copy; only the copies in ``which`` step, the others' rows are zeros and NaN (nothing ended)."""
        k = len(self.envs)
        obs, final_obs = np.zeros((2, k, actions.shape[1], OBS_DIM), np.float32)
        reward = np.zeros(k, np.float32)
        terminated, truncated = np.zeros(k, bool), np.zeros(k, bool)
        ep_return, ep_success = np.full(k, np.nan, np.float32), np.full(k, np.nan, np.float32)
        for e in np.flatnonzero(which):
            env = self.envs[e]
            o, r, done, info = env.step(actions[e].tolist())
            reward[e] = np.mean(r)
            self.t[e] += 1
            self.returns[e] += reward[e]
            self.scored[e] |= info["score_reward"] > 0
            # the engine ends an academy episode on a goal, a lost ball, the ball out of play
            # or its own time limit (game_duration); only the time limit is a truncation
            terminated[e] = done and self.t[e] < GAME_DURATION
            truncated[e] = not terminated[e] and (done or self.t[e] >= self.max_steps)
            final_obs[e] = o
            if terminated[e] or truncated[e]:
                ep_return[e], ep_success[e] = self.returns[e], self.scored[e]
                self.t[e], self.returns[e], self.scored[e] = 0, 0.0, False
                o = env.reset()
            obs[e] = o
        return obs, final_obs, reward, terminated, truncated, ep_return, ep_success

    def get_state(self) -> dict:
        return {"engines": [env.get_state() for env in self.envs], "t": self.t.copy(),
                "returns": self.returns.copy(), "scored": self.scored.copy()}

    def set_state(self, d: dict) -> None:
        with _engine_pickles_as_data():
            for env, s in zip(self.envs, d["engines"]):
                env.set_state(s)
        self.t, self.returns, self.scored = d["t"].copy(), d["returns"].copy(), d["scored"].copy()


class _EngineUnpickler(pickle.Unpickler):
    """gfootball's ``set_state`` unpickles a pickle that its ``get_state`` put in the engine's
    snapshot: its own ``EnvState`` (three counters) and the reward wrapper's dict. The snapshot
    comes from a checkpoint, which is data (``runstate``), so nothing else may be built from it."""

    ALLOWED = {("gfootball.env.football_env_core", "EnvState")}

    def find_class(self, module: str, name: str):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"a GRF engine state may hold gfootball's EnvState only, not {module}.{name}")
        return super().find_class(module, name)


@contextlib.contextmanager
def _engine_pickles_as_data():
    """``pickle.loads`` as ``_EngineUnpickler`` meanwhile: gfootball calls it by that name
    (``six.moves.cPickle`` is ``pickle``), inside a worker that does nothing else at the time."""
    loads = pickle.loads
    pickle.loads = lambda data, **_: _EngineUnpickler(io.BytesIO(data)).load()
    try:
        yield
    finally:
        pickle.loads = loads


def _worker(conn, name: str, seeds: list[int], max_steps: int) -> None:
    """Serve (command, argument) requests on ``conn`` until told to close or the parent goes away."""
    try:
        copies = _Copies(name, seeds, max_steps)
        conn.send(("ok", None))
    except Exception as err:  # report it to the parent instead of dying silently
        conn.send(("error", f"{type(err).__name__}: {err}"))
        return
    while True:
        try:
            cmd, arg = conn.recv()
        except EOFError:
            return
        if cmd == "close":
            return
        try:
            conn.send(("ok", getattr(copies, cmd)(*arg)))
        except Exception as err:
            conn.send(("error", f"{type(err).__name__}: {err}"))


def _close(procs, conns) -> None:
    for conn in conns:
        try:
            conn.send(("close", ()))
        except (BrokenPipeError, OSError):
            pass
    for p in procs:
        p.join(timeout=5)
        if p.is_alive():
            p.kill()


class GRFVec:
    """``n_envs`` copies of a GRF academy scenario in ``workers`` processes (see the module docstring)."""

    def __init__(self, name: str, n_envs: int, seed: int = 0, max_steps: int = 400, workers: int | None = None):
        check(name)
        if not installed():
            raise NotInstalled(f"env grf:{name}: {INSTALL_HINT}")
        self.n_envs, self.max_steps = check_copies(n_envs, max_steps)
        self.name, self.seed = name, int(seed)
        self.n_agents = SCENARIOS[name]
        self.agents = self.agent_types = agent_types(name)
        self.n_actions, self.obs_dim, self.state_dim = N_ACTIONS, OBS_DIM, self.n_agents * OBS_DIM
        self.continuous = False
        self.time_in_state, self.optimum = False, math.nan  # no clock in the state; no oracle
        workers = min(self.n_envs, workers or os.cpu_count() or 1)
        self._parts = np.array_split(np.arange(self.n_envs), workers)
        ctx = mp.get_context("spawn")  # the engine and torch do not fork safely
        self._conns, self._procs = [], []
        for part in self._parts:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, name, [copy_seed(seed, int(k)) for k in part], max_steps),
                               daemon=True)
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        self._finalizer = weakref.finalize(self, _close, self._procs, self._conns)
        self._gather()  # every worker built its engines (or raised)

    def _gather(self) -> list:
        try:
            answers = [conn.recv() for conn in self._conns]
        except EOFError:
            self.close()
            raise RuntimeError(f"a GRF worker process of {self.name!r} died (exit codes "
                               f"{[p.exitcode for p in self._procs]})") from None
        errors = [msg for status, msg in answers if status == "error"]
        if errors:
            self.close()
            raise RuntimeError(f"GRF worker failed on {self.name!r}: {errors[0]}")
        return [msg for _, msg in answers]

    def _call(self, cmd: str, args_per_worker) -> list:
        for conn, args in zip(self._conns, args_per_worker):
            conn.send((cmd, args))
        return self._gather()

    def close(self) -> None:
        self._finalizer()

    def worker_pids(self) -> list[int]:
        """The processes that step the copies (a run's cost counts their CPU time)."""
        return [p.pid for p in self._procs if p.is_alive()]

    def _static(self) -> tuple[np.ndarray, np.ndarray]:
        """(avail, active): every action is always legal and every player always acts."""
        return np.ones((self.n_envs, self.n_agents, self.n_actions), bool), np.ones((self.n_envs, self.n_agents), bool)

    def reset(self) -> VecStep:
        """Reset every copy (each engine continues its own seeded sequence of episodes)."""
        obs = np.concatenate(self._call("reset", [()] * len(self._parts)))
        avail, active = self._static()
        return VecStep.at_reset(obs, obs.reshape(self.n_envs, -1), avail, active)

    def step(self, actions) -> VecStep:
        """``actions`` (n_envs, n_agents) ints in 0..18."""
        return self.step_only(actions, np.ones(self.n_envs, bool))

    def step_only(self, actions, which) -> VecStep:
        """Step only the copies where ``which`` (n_envs,) bool is true; the rows of the others hold
        zeros and no episode ends there. An evaluation reads the first episode of every copy: the
        copies whose first episode has ended would step on for nothing, at an engine's full cost
        (the next ``reset`` starts every copy's episode afresh, from its seed alone)."""
        a, which = np.asarray(actions), np.asarray(which)
        if a.shape != (self.n_envs, self.n_agents) or not np.issubdtype(a.dtype, np.integer):
            raise ValueError(f"actions must be integers of shape {(self.n_envs, self.n_agents)}, got "
                             f"{a.dtype} {a.shape}")
        if ((a < 0) | (a >= N_ACTIONS)).any():
            raise ValueError(f"actions must lie in 0..{N_ACTIONS - 1}, got {np.unique(a[(a < 0) | (a >= N_ACTIONS)])}")
        if which.shape != (self.n_envs,) or which.dtype != bool:
            raise ValueError(f"which must be booleans of shape {(self.n_envs,)}, got {which.dtype} {which.shape}")
        parts = self._call("step", [(a[p], which[p]) for p in self._parts])
        obs, final_obs, reward, term, trunc, ep_return, ep_success = (np.concatenate(x) for x in zip(*parts))
        avail, active = self._static()
        return VecStep(obs=obs, state=obs.reshape(self.n_envs, -1), avail=avail, reward=reward, terminated=term,
                       truncated=trunc, final_obs=final_obs, final_state=final_obs.reshape(self.n_envs, -1),
                       episode_return=ep_return, episode_success=ep_success, active=active)

    def get_state(self) -> list:
        """Every engine's own snapshot and the episode counters (for checkpoints)."""
        return self._call("get_state", [()] * len(self._parts))

    def set_state(self, d: list) -> None:
        if len(d) != len(self._parts):
            raise ValueError(f"state holds {len(d)} worker parts, this env has {len(self._parts)}")
        self._call("set_state", [(s,) for s in d])


def agent_types(name: str) -> tuple[str, ...]:
    """The agent type of each seat of scenario ``name``, without starting an engine: HARL's players keep
    their own roles, so each seat is its own type (and named for it)."""
    check(name)
    return tuple(f"player_{k}" for k in range(SCENARIOS[name]))


agent_names = agent_types  # a controlled player's name is its type: GRF's players are told apart by place


def make_vec(name: str, n_envs: int, seed: int, max_steps: int) -> GRFVec:
    return GRFVec(name, n_envs, seed, max_steps)
