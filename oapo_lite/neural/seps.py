"""SePS, Selective Parameter Sharing (Christianos et al., ICML 2021): which agents share a network.

1. Pre-training: every agent acts with one shared network (trained as usual) and the
   transitions (o, a, o', r, agent id) are stored (``Buffer``).
2. A small VAE embeds the one-hot agent id: encoder id -> 64 -> (mu, log var) of z (z = 10);
   decoder (z, o, a) -> (o', r). Loss: summed squared error + 1e-4 KL(q(z | id) || N(0, I))
   (the paper's ELBO, Section 4), Adam 3e-4, batch 128, 10 epochs (``agent_embeddings``).
3. k-means on the agents' mean embeddings mu(id); k by the lowest Davies-Bouldin index over
   2..N-1 when not given (``choose_groups``). Each cluster then gets its own network.

k-means (Lloyd's algorithm with k-means++ seeding, best of ``n_init`` starts by inertia) and the
Davies-Bouldin index are written here in numpy: a few lines each, and no new dependency.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

Z_FEATURES, HIDDEN, KL_WEIGHT = 10, 64, 1e-4
VAE_LR, VAE_BATCH, VAE_EPOCHS = 3e-4, 128, 10


def kmeans(x: np.ndarray, k: int, rng: np.random.Generator, n_init: int = 10, iters: int = 300) -> np.ndarray:
    """Labels (len(x),) of the k-means partition with the lowest inertia over ``n_init``
    k-means++ starts (Lloyd iterations until the labels stop changing)."""
    x = np.asarray(x, dtype=float)
    if not 1 <= k <= len(x):
        raise ValueError(f"k = {k} clusters is invalid for {len(x)} points; allowed: 1..{len(x)}")
    best, best_inertia = None, np.inf
    for _ in range(n_init):
        centres = x[[rng.integers(len(x))]]
        while len(centres) < k:  # k-means++: the next centre far from the chosen ones
            d2 = ((x[:, None] - centres[None]) ** 2).sum(-1).min(1)
            p = d2 / d2.sum() if d2.sum() > 0 else np.full(len(x), 1 / len(x))
            centres = np.vstack([centres, x[rng.choice(len(x), p=p)]])
        labels = None
        for _ in range(iters):
            new = ((x[:, None] - centres[None]) ** 2).sum(-1).argmin(1)
            if labels is not None and (new == labels).all():
                break
            labels = new
            centres = np.array([x[labels == c].mean(0) if (labels == c).any() else centres[c] for c in range(k)])
        inertia = ((x - centres[labels]) ** 2).sum()
        if inertia < best_inertia - 1e-12:
            best, best_inertia = labels, inertia
    return canonical(best)


def canonical(labels) -> np.ndarray:
    """Cluster numbers in order of first appearance (agent 0's cluster is 0)."""
    labels = np.asarray(labels)
    order = {c: i for i, c in enumerate(dict.fromkeys(labels.tolist()))}
    return np.array([order[c] for c in labels.tolist()])


def davies_bouldin(x: np.ndarray, labels: np.ndarray) -> float:
    """Davies-Bouldin index: mean over clusters i of max_{j != i} (s_i + s_j) / |c_i - c_j|,
    s_i the mean distance of cluster i's points to its centroid c_i. Lower is better."""
    x, labels = np.asarray(x, dtype=float), np.asarray(labels)
    ids = np.unique(labels)
    if len(ids) < 2:
        raise ValueError(f"the Davies-Bouldin index needs >= 2 clusters, got {len(ids)}")
    centres = np.array([x[labels == c].mean(0) for c in ids])
    scatter = np.array([np.linalg.norm(x[labels == c] - centres[i], axis=1).mean() for i, c in enumerate(ids)])
    dist = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (scatter[:, None] + scatter[None]) / dist
    np.fill_diagonal(ratio, -np.inf)
    ratio = np.where(np.isnan(ratio), 0.0, ratio)  # two coincident points: 0 / 0, no spread
    return float(ratio.max(1).mean())


def choose_groups(z: np.ndarray, clusters: int | None, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Cluster the agents' embeddings ``z`` (n, d). With ``clusters`` None, k is the one of
    2..n-1 with the lowest Davies-Bouldin index (k = n would score a degenerate 0); with
    fewer than 3 agents there is no such k and every agent keeps its own network.
    Returns (labels (n,), Davies-Bouldin index of each candidate k)."""
    n = len(z)
    if clusters is not None:
        return kmeans(z, clusters, rng), {}
    if n < 3:
        return np.arange(n), {}
    scores = {k: davies_bouldin(z, kmeans(z, k, rng)) for k in range(2, n)}
    return kmeans(z, min(scores, key=scores.get), rng), scores


class AgentVAE(nn.Module):
    """Encoder one-hot id -> 64 -> 2z (mu, log var); decoder (z, obs, action) -> 64 -> 64 -> (obs', r)."""

    def __init__(self, n_agents: int, obs_dim: int, act_dim: int):
        super().__init__()
        self.encoder = nn.Sequential(nn.Linear(n_agents, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, 2 * Z_FEATURES))
        self.decoder = nn.Sequential(nn.Linear(Z_FEATURES + obs_dim + act_dim, HIDDEN), nn.ReLU(),
                                     nn.Linear(HIDDEN, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, obs_dim + 1))

    def encode(self, agent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.encoder(agent).chunk(2, -1)

    def loss(self, agent, decoder_in, target, gen: torch.Generator) -> torch.Tensor:
        """Summed squared reconstruction error + KL_WEIGHT * KL(N(mu, var) || N(0, I))."""
        mu, logvar = self.encode(agent)
        z = mu + torch.exp(0.5 * logvar) * torch.randn(mu.shape, generator=gen)
        recon = self.decoder(torch.cat([z, decoder_in], -1))
        kl = -0.5 * (1 + logvar - mu.pow(2) - logvar.exp()).sum()
        return (recon - target).pow(2).sum() + KL_WEIGHT * kl


def agent_embeddings(agent: np.ndarray, obs: np.ndarray, act: np.ndarray, next_obs: np.ndarray,
                     reward: np.ndarray, n_agents: int, seed: int) -> np.ndarray:
    """Fit the VAE on the transitions (agent id (M,), obs (M, d), action features (M, A),
    next obs (M, d), reward (M,)) and return the mean embedding mu of each agent (n, z)."""
    with torch.random.fork_rng(devices=[]):  # the VAE's initialisation leaves the caller's RNG alone
        torch.manual_seed(seed)
        vae = AgentVAE(n_agents, obs.shape[1], act.shape[1])
    gen = torch.Generator().manual_seed(seed)
    one_hot = torch.eye(n_agents)
    agent_t = one_hot[torch.as_tensor(agent, dtype=torch.long)]
    decoder_in = torch.cat([torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(act, dtype=torch.float32)], 1)
    target = torch.cat([torch.as_tensor(next_obs, dtype=torch.float32),
                        torch.as_tensor(reward, dtype=torch.float32)[:, None]], 1)
    opt = torch.optim.Adam(vae.parameters(), lr=VAE_LR)
    for _ in range(VAE_EPOCHS):
        for idx in torch.randperm(len(agent_t), generator=gen).split(VAE_BATCH):
            loss = vae.loss(agent_t[idx], decoder_in[idx], target[idx], gen)
            opt.zero_grad()
            loss.backward()
            opt.step()
    with torch.no_grad():
        return vae.encode(one_hot)[0].double().numpy()


def group_names(labels, agents) -> str:
    """'black+blue | red': the members of each group, groups in order of their first agent."""
    labels = canonical(labels)
    return " | ".join("+".join(a for a, c in zip(agents, labels) if c == g) for g in range(labels.max() + 1))


def group_labels(names: str, agents) -> list[int]:
    """``group_names`` read back: the group of every agent, groups numbered in the order named."""
    group = {a: g for g, members in enumerate(names.split(" | ")) for a in members.split("+")}
    return [group[a] for a in agents]


class Buffer:
    """The pre-training transitions (o, a, o', r, agent id), only where the agent acted; ``parts``
    (a list of tuples of numpy arrays) is its state in a checkpoint."""

    def __init__(self, parts: list | None = None):
        if parts is not None and not isinstance(parts, list):
            raise TypeError(f"SePS's buffer holds a list of transition parts, got a {type(parts).__name__}")
        self.parts: list[tuple] = [] if parts is None else parts

    def record(self, obs: torch.Tensor, act: torch.Tensor, next_obs: torch.Tensor, reward: torch.Tensor,
               active: torch.Tensor | None) -> None:
        """obs, next_obs (n, B, d); act (n, B, A) action features; reward (B,); active (n, B) or None."""
        n, B = obs.shape[:2]
        keep = torch.ones(n, B, dtype=torch.bool) if active is None else active
        agent = torch.arange(n)[:, None].expand(n, B)
        self.parts.append(tuple(x[keep].numpy() for x in (agent, obs, act, next_obs, reward.expand(n, B))))

    def arrays(self) -> tuple[np.ndarray, ...]:
        return tuple(np.concatenate(xs) for xs in zip(*self.parts))
