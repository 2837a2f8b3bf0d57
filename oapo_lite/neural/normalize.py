"""Running normalisation of what the learners see (``TrainConfig.normalize``), as
stable-baselines3's ``VecNormalize``: every seat's observations and the critic's state are
centred and scaled by the running mean and variance of what the training copies have shown so
far, and clipped at +-10; the team reward is divided by the running standard deviation of the
discounted return, and clipped at +-10. The evaluation copies read the training copies' statistics
without moving them, and their episode returns stay in the env's own units, as every results
row reports them.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from oapo_lite.envs.vec import VecEnv, VecStep

CLIP, EPSILON = 10.0, 1e-8


class RunningMoments:
    """Mean and variance of every feature over all samples seen (Chan et al.'s parallel update,
    as stable-baselines3's ``RunningMeanStd``, which starts from a count of 1e-4)."""

    def __init__(self, shape: tuple[int, ...]):
        self.mean, self.var, self.count = np.zeros(shape), np.ones(shape), 1e-4

    def update(self, x: np.ndarray) -> None:
        """``x`` (batch, *shape)."""
        n, mean, var = x.shape[0], x.mean(axis=0), x.var(axis=0)
        delta, total = mean - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + var * n + delta**2 * self.count * n / total) / total
        self.count = total

    def scale(self, x: np.ndarray) -> np.ndarray:
        return np.clip((x - self.mean) / np.sqrt(self.var + EPSILON), -CLIP, CLIP).astype(np.float32)

    def state_dict(self) -> dict:
        return {"mean": self.mean.copy(), "var": self.var.copy(), "count": self.count}

    def load_state_dict(self, d: dict) -> None:
        self.mean, self.var, self.count = d["mean"].copy(), d["var"].copy(), d["count"]


@dataclasses.dataclass
class Moments:
    """The statistics the training and evaluation copies share: per seat and observation feature,
    per state feature, and of the discounted return."""

    obs: RunningMoments
    state: RunningMoments
    ret: RunningMoments

    @classmethod
    def of(cls, env: VecEnv) -> "Moments":
        return cls(RunningMoments((env.n_agents, env.obs_dim)), RunningMoments((env.state_dim,)), RunningMoments(()))


class Normalized:
    """``env`` as its learners see it under running normalisation (the module docstring): the
    training copies (``train``) update ``moments`` with what they show and scale their rewards;
    evaluation copies only read the moments. Everything else is ``env``'s."""

    def __init__(self, env: VecEnv, moments: Moments, gamma: float, train: bool):
        self.env, self.moments, self.gamma, self.train = env, moments, gamma, train
        self.discounted = np.zeros(env.n_envs)  # each copy's running discounted return, for the reward's scale

    def __getattr__(self, name: str):  # the env's spaces, seats, optimum, worker processes, ...
        if name == "step_only":  # stepping some copies alone would skip the normalisation
            raise AttributeError(name)
        return getattr(self.env, name)

    def _seen(self, step: VecStep) -> VecStep:
        m = self.moments
        if self.train:
            m.obs.update(step.obs)
            m.state.update(step.state)
        return dataclasses.replace(step, obs=m.obs.scale(step.obs), final_obs=m.obs.scale(step.final_obs),
                                   state=m.state.scale(step.state), final_state=m.state.scale(step.final_state))

    def reset(self) -> VecStep:
        self.discounted[:] = 0.0
        return self._seen(self.env.reset())

    def step(self, actions: np.ndarray) -> VecStep:
        step = self._seen(self.env.step(actions))
        if not self.train:
            return step
        self.discounted = self.discounted * self.gamma + step.reward
        self.moments.ret.update(self.discounted)
        reward = np.clip(step.reward / np.sqrt(self.moments.ret.var + EPSILON), -CLIP, CLIP).astype(np.float32)
        self.discounted[step.terminated | step.truncated] = 0.0
        return dataclasses.replace(step, reward=reward)

    def get_state(self) -> dict:
        return {"env": self.env.get_state(), "discounted": self.discounted.copy(),
                **{k: getattr(self.moments, k).state_dict() for k in ("obs", "state", "ret")}}

    def set_state(self, state: dict) -> None:
        self.env.set_state(state["env"])
        self.discounted = state["discounted"].copy()
        for k in ("obs", "state", "ret"):
            getattr(self.moments, k).load_state_dict(state[k])
