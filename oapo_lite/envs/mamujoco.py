"""Multi-agent MuJoCo (gymnasium-robotics' MaMuJoCo) as an env engine: ``mamujoco:<robot>-<partition>``.

A robot's joints are split among agents (``HalfCheetah-2x3``: two agents, three joints
each); every agent observes its own joints and their neighbours (``agent_obsk = 1``), the
global state is the single-agent MuJoCo observation, and the team reward is the robot's
reward. Actions are continuous (Box): the diagonal Gaussian policy drives them, and
``PettingZooVec`` clips them to the space's bounds before they reach the engine.

``HOMOGENEOUS`` partitions give every agent the same observation and action spaces, which
reusing experience needs (OAPPO, MAPPO, SEAC); the others train with HAPPO / HATRPO / IPPO
only (the training loop raises otherwise). gymnasium-robotics and mujoco are pinned in
``environment.txt``; the engine is imported only when an env is made.
"""
from __future__ import annotations

import contextlib
import copy
import io
import os
import sys

import numpy as np

from .pettingzoo_vec import PettingZooVec
from .vec import VecStep

# name -> equal spaces for every agent (checked against the engine by the tests)
PARTITIONS: dict[str, bool] = {
    "HalfCheetah-1x6": True,  # one agent with all six joints: single-agent HalfCheetah through the same engine
    "HalfCheetah-2x3": True,
    "HalfCheetah-6x1": False,
    "Ant-2x4": True,
    "Ant-2x4d": True,
    "Ant-4x2": True,
    "Walker2d-2x3": True,
    "Swimmer-2x1": True,
    "Hopper-3x1": False,
}
HOMOGENEOUS = tuple(name for name, equal in PARTITIONS.items() if equal)


def check(name: str) -> None:
    """Raise ``ValueError`` naming the allowed robot-partition names (the engine is not imported)."""
    if name not in PARTITIONS:
        raise ValueError(f"unknown MaMuJoCo robot-partition {name!r}; allowed: {sorted(PARTITIONS)} "
                         f"(homogeneous, i.e. equal spaces for reuse: {sorted(HOMOGENEOUS)})")


_compiling = False  # while a model compiles, ``_warn`` keeps quiet (``_quiet_compile``)


@contextlib.contextmanager
def _quiet_compile():
    """Silence MuJoCo for a moment, from C (file descriptor 2) and through ``_warn``: MuJoCo 4
    warns, on every compile, that gymnasium's HalfCheetah and Ant models use the deprecated
    attribute 'settotalmass'; nothing a user can act on, and it would interleave with notebook
    output."""
    global _compiling
    sys.stderr.flush()
    saved = os.dup(2)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 2)
    _compiling = True
    try:
        yield
    finally:
        _compiling = False
        os.dup2(saved, 2)
        os.close(saved)


def _warn(message: str) -> None:
    """MuJoCo's warnings, on stderr: its own handler also appends them to MUJOCO_LOG.TXT in the
    working folder, wherever a run or a notebook is started (a file in the user's checkout)."""
    if not _compiling:
        print(f"MuJoCo warning: {message}", file=sys.stderr, flush=True)


def env_fn(name: str, max_steps: int):
    """A factory of one MaMuJoCo ``ParallelEnv`` whose own time limit is ``max_steps``."""
    check(name)
    try:
        with contextlib.redirect_stderr(io.StringIO()):  # an import-time notice about Adroit hand envs
            from gymnasium_robotics import mamujoco_v1
    except ImportError as err:
        raise ImportError(f"mamujoco:{name} needs gymnasium-robotics and mujoco; install the pins "
                          f"of environment.txt (pip install -r environment.txt): {err}") from None
    import mujoco

    if mujoco.get_mju_user_warning() is None:  # a handler set by the user is theirs
        mujoco.set_mju_user_warning(_warn)
    robot, partition = name.split("-")
    partition = None if partition.startswith("1x") else partition  # the engine's one-agent configuration

    def make():
        with _quiet_compile():
            return mamujoco_v1.parallel_env(robot, partition, max_episode_steps=max_steps)

    make.__name__ = f"mamujoco:{name}"
    return make


class MaMuJoCoVec(PettingZooVec):
    """``PettingZooVec`` that steps each copy's single-agent MuJoCo env directly, and whose
    checkpoints hold every copy's MuJoCo data as arrays (``_physics``), random generator and
    time-limit counter (MaMuJoCo envs keep lambdas and C objects: no snapshot of the whole).

    MaMuJoCo's own ``step`` rebuilds every agent's observation from the MuJoCo data, joint by
    joint, in Python; yet an agent's observation is a fixed selection of the single-agent
    observation (its ``observation_factorization``, checked by the tests), and every agent gets
    the robot's reward. Stepping the single-agent env and gathering those indices for all
    copies at once gives the same numbers bit for bit (tested against ``PettingZooVec``; a run
    trains identically) at about twice the speed (``benchmarks/mamujoco_speed.py``).
    """

    def __init__(self, env_fn, n_envs: int, seed: int = 0, max_steps: int | None = None):
        super().__init__(env_fn, n_envs, seed=seed, max_steps=max_steps)
        first = self.envs[0]
        # equal spaces, but each agent moves its own body part (back leg, front leg): its own type
        self.agent_types = self.agents
        self._obs_index = [np.asarray(first.observation_factorization[a]) for a in self.agents]
        act = np.array([[part.act_ids for part in parts] for parts in first.agent_action_partitions])
        if act.shape != (self.n_agents, self.n_actions) or sorted(act.ravel()) != list(range(act.size)):
            raise ValueError(f"MaMuJoCo's action partition {act.tolist()} does not split the robot's actions")
        self._act_index = act.ravel()  # agent-major local action k -> the robot's action index
        space = self.spaces[0][1]
        self._low, self._high, self._dtype = space.low, space.high, space.dtype

    def step(self, actions) -> VecStep:
        """``actions`` (N, n, D) floats, clipped to the agents' bounds as ``PettingZooVec`` does."""
        N = self.n_envs
        local = np.clip(np.asarray(actions), self._low, self._high).astype(self._dtype).reshape(N, -1)
        robot = np.empty((N, local.shape[1]), np.float64)  # MaMuJoCo builds a float64 action too
        robot[:, self._act_index] = local
        states = np.empty((N, self.state_dim), np.float64)
        final_states = np.empty_like(states)
        reward = np.zeros(N, np.float32)
        terminated, truncated = np.zeros(N, bool), np.zeros(N, bool)
        ep_return, ep_success = np.full(N, np.nan, np.float32), np.full(N, np.nan, np.float32)
        for e, env in enumerate(self.envs):
            state, r, term, trunc, _ = env.single_agent_env.step(robot[e])
            reward[e] = r
            self._t[e] += 1
            self._returns[e] += r
            terminated[e] = term
            truncated[e] = not term and (trunc or (self.max_steps is not None and self._t[e] >= self.max_steps))
            final_states[e] = state
            if term or truncated[e]:
                ep_return[e] = self._returns[e]
                self._reset_copy(e, None)
                state = env.state()
            states[e] = state
        return VecStep(obs=self._local(states), state=states.astype(np.float32), avail=np.ones(
                           (N, self.n_agents, self.n_actions), bool), reward=reward, terminated=terminated,
                       truncated=truncated, final_obs=self._local(final_states),
                       final_state=final_states.astype(np.float32), episode_return=ep_return,
                       episode_success=ep_success, active=np.ones((N, self.n_agents), bool))

    def _local(self, states: np.ndarray) -> np.ndarray:
        """Every agent's observation of every copy, zero-padded as ``PettingZooVec`` pads."""
        obs = np.zeros((len(states), self.n_agents, self.obs_dim), np.float32)
        for k, index in enumerate(self._obs_index):
            obs[:, k, :len(index)] = states[:, index]
        return obs

    def get_state(self) -> dict:
        return {"copies": [_copy_state(env) for env in self.envs], "t": self._t.copy(),
                "returns": self._returns.copy()}

    def set_state(self, d: dict) -> None:
        for env, state in zip(self.envs, d["copies"], strict=True):
            _set_copy_state(env, state)
        self._t, self._returns = d["t"].copy(), d["returns"].copy()


def _copy_state(env) -> dict:
    limit = env.single_agent_env  # gymnasium.make puts the TimeLimit outermost
    sim = limit.unwrapped
    return {"physics": _physics(sim), "rng": copy.deepcopy(sim.np_random.bit_generator.state),
            "elapsed": limit._elapsed_steps, "agents": list(env.agents)}


def _set_copy_state(env, state: dict) -> None:
    limit = env.single_agent_env
    sim = limit.unwrapped
    _set_physics(sim, state["physics"])
    sim.np_random.bit_generator.state = copy.deepcopy(state["rng"])
    limit._elapsed_steps, env.agents = int(state["elapsed"]), [str(a) for a in state["agents"]]


def _physics(sim) -> dict:
    """A copy's MjData as data: MuJoCo's integration state (time, positions, velocities,
    controls, warm start, ...), and every float array of the data. The integration state alone
    is not enough: rewards read quantities (body positions) that mj_step leaves one substep
    stale, and recomputing them from the state changed Ant's first reward after a restore."""
    import mujoco

    state = np.empty(mujoco.mj_stateSize(sim.model, mujoco.mjtState.mjSTATE_INTEGRATION))
    mujoco.mj_getState(sim.model, sim.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
    return {"state": state, "floats": {name: value.copy() for name, value in _float_arrays(sim.data)}}


def _set_physics(sim, physics: dict) -> None:
    """Write ``_physics``'s output into a copy's MjData. Integer arrays (indices, counts) are
    left to MuJoCo: the next mj_step rebuilds them, and a checkpoint's values never index its
    memory. Arrays sized by the contacts and constraints of the saved moment (efc_*, island_*)
    differ in shape from this data's when their number differs; mj_step rebuilds them before
    reading them, so they are skipped (a resumed Ant and HalfCheetah continue bit for bit)."""
    import mujoco

    floats = dict(_float_arrays(sim.data))
    unknown = sorted(set(physics["floats"]) - set(floats))
    if unknown:
        raise ValueError(f"MuJoCo state has float arrays {unknown} that this MjData lacks")
    mujoco.mj_setState(sim.model, sim.data, np.asarray(physics["state"], np.float64),
                       mujoco.mjtState.mjSTATE_INTEGRATION)
    for name, value in physics["floats"].items():
        if floats[name].shape == np.shape(value):
            floats[name][...] = value


def _float_arrays(data):
    """(name, live view) of every float64 array field of an MjData."""
    for name in dir(data):
        value = None if name.startswith("_") else getattr(data, name)
        if isinstance(value, np.ndarray) and value.dtype == np.float64:
            yield name, value


def make_vec(name: str, n_envs: int, seed: int, max_steps: int) -> MaMuJoCoVec:
    """``n_envs`` copies stepped one after another; copy k is reset with seed ``seed + k``."""
    return MaMuJoCoVec(env_fn(name, max_steps), n_envs, seed=seed, max_steps=max_steps)
