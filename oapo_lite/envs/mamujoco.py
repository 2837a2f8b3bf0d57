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


from .pettingzoo_vec import PettingZooVec

# name -> equal spaces for every agent (checked against the engine by the tests)
PARTITIONS: dict[str, bool] = {
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


@contextlib.contextmanager
def _quiet_c_stderr():
    """Silence file descriptor 2 for a moment: MuJoCo 4 warns from C, on every compile, that
    gymnasium's HalfCheetah model uses the deprecated attribute 'settotalmass'; nothing a
    user can act on, and it would interleave with notebook output."""
    sys.stderr.flush()
    saved = os.dup(2)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 2)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def env_fn(name: str, max_steps: int):
    """A factory of one MaMuJoCo ``ParallelEnv`` whose own time limit is ``max_steps``."""
    check(name)
    try:
        with contextlib.redirect_stderr(io.StringIO()):  # an import-time notice about Adroit hand envs
            from gymnasium_robotics import mamujoco_v1
    except ImportError as err:
        raise ImportError(f"mamujoco:{name} needs gymnasium-robotics and mujoco; install the pins "
                          f"of environment.txt (pip install -r environment.txt): {err}") from None
    robot, partition = name.split("-")

    def make():
        with _quiet_c_stderr():
            return mamujoco_v1.parallel_env(robot, partition, max_episode_steps=max_steps)

    make.__name__ = f"mamujoco:{name}"
    return make


class MaMuJoCoVec(PettingZooVec):
    """``PettingZooVec`` whose checkpoints hold every copy's MuJoCo data, random generator and
    time-limit counter: MaMuJoCo envs keep lambdas and cannot be pickled whole."""

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
    # the whole MjData, not just qpos / qvel: rewards read quantities (body positions) that
    # mj_step leaves one substep stale, and recomputing them would change the next reward
    return {"data": copy.deepcopy(sim.data), "rng": copy.deepcopy(sim.np_random.bit_generator.state),
            "elapsed": limit._elapsed_steps, "agents": list(env.agents)}


def _set_copy_state(env, state: dict) -> None:
    import mujoco

    limit = env.single_agent_env
    sim = limit.unwrapped
    mujoco.mj_copyData(sim.data, sim.model, state["data"])
    sim.np_random.bit_generator.state = copy.deepcopy(state["rng"])
    limit._elapsed_steps, env.agents = state["elapsed"], list(state["agents"])


def make_vec(name: str, n_envs: int, seed: int, max_steps: int) -> MaMuJoCoVec:
    """``n_envs`` copies stepped one after another; copy k is reset with seed ``seed + k``."""
    return MaMuJoCoVec(env_fn(name, max_steps), n_envs, seed=seed, max_steps=max_steps)
