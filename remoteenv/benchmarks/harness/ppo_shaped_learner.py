"""The learner of the training-loop benchmark: PPO's shape, in torch.

Agent side (benchmarks only; the process that trains). What a PPO user's loop
asks of the CPUs beside the envs: every vector step a 2x64 tanh MLP actor and
critic infer the actions of the whole batch (a diagonal Gaussian with a
learned log-std, CleanRL's continuous PPO); every ``horizon`` (128) vector
steps GAE over the collected batch and ``epochs`` (4) epochs of SGD (Adam) on
PPO's clipped loss, ``minibatches`` (4) minibatches each: the shape of
CleanRL's PPO for EnvPool. Torch's settings are left as the user's process has them.
The learning itself is real, but the benchmark times it; it does not judge it.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


def _mlp(inputs: int, outputs: int, out_std: float) -> nn.Sequential:
    net = nn.Sequential(nn.Linear(inputs, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, outputs))
    for layer in net:
        if isinstance(layer, nn.Linear):
            nn.init.orthogonal_(layer.weight, 2**0.5)
            nn.init.zeros_(layer.bias)
    last = net[-1]
    assert isinstance(last, nn.Linear)
    nn.init.orthogonal_(last.weight, out_std)
    return net


class PPOShapedLearner:
    """PPO's work for ``num_envs`` worlds of ``obs_dim`` observations and
    ``act_dim`` actions in [-1, 1].

    Call :meth:`act` with each vector step's observations, :meth:`record`
    with what the step returned, and :meth:`update` (with the observations
    after the last step) once :meth:`full` says the rollout of ``horizon``
    vector steps is complete.
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        num_envs: int,
        *,
        horizon: int = 128,
        epochs: int = 4,
        minibatches: int = 4,
        seed: int = 0,
    ) -> None:
        torch.manual_seed(seed)
        self.actor = _mlp(obs_dim, act_dim, 0.01)
        self.critic = _mlp(obs_dim, 1, 1.0)
        self.log_std = nn.Parameter(torch.zeros(act_dim))
        params = [*self.actor.parameters(), *self.critic.parameters(), self.log_std]
        self.optimizer = torch.optim.Adam(params, lr=3e-4, eps=1e-5)
        self.params = params
        self.horizon, self.epochs, self.minibatches = horizon, epochs, minibatches
        self.obs = torch.zeros(horizon, num_envs, obs_dim)
        self.actions = torch.zeros(horizon, num_envs, act_dim)
        self.logprobs = torch.zeros(horizon, num_envs)
        self.values = torch.zeros(horizon, num_envs)
        self.rewards = torch.zeros(horizon, num_envs)
        self.dones = torch.zeros(horizon, num_envs)
        self.t = 0
        self.generator = torch.Generator().manual_seed(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The actions (float32, clipped to [-1, 1]) for this vector step's observations."""
        with torch.no_grad():
            x = torch.as_tensor(obs, dtype=torch.float32)
            mean = self.actor(x)
            std = self.log_std.exp().expand_as(mean)
            action = mean + std * torch.randn(mean.shape, generator=self.generator)
            self.obs[self.t] = x
            self.actions[self.t] = action
            self.logprobs[self.t] = torch.distributions.Normal(mean, std).log_prob(action).sum(-1)
            self.values[self.t] = self.critic(x).squeeze(-1)
        return action.clamp(-1.0, 1.0).numpy()

    def record(self, reward: np.ndarray, terminated: np.ndarray, truncated: np.ndarray) -> None:
        """What the vector step after :meth:`act` returned."""
        self.rewards[self.t] = torch.as_tensor(np.asarray(reward, dtype=np.float32))
        self.dones[self.t] = torch.as_tensor(np.logical_or(terminated, truncated).astype(np.float32))
        self.t += 1

    @property
    def full(self) -> bool:
        """Whether ``horizon`` vector steps are collected (time to :meth:`update`)."""
        return self.t >= self.horizon

    def update(self, last_obs: np.ndarray, gamma: float = 0.99, lam: float = 0.95, clip: float = 0.2) -> float:
        """GAE and ``epochs`` epochs of minibatch SGD on the rollout; returns the last minibatch's loss."""
        with torch.no_grad():
            next_value = self.critic(torch.as_tensor(last_obs, dtype=torch.float32)).squeeze(-1)
            advantages = torch.zeros_like(self.rewards)
            last = torch.zeros_like(next_value)
            for t in reversed(range(self.horizon)):
                following = next_value if t == self.horizon - 1 else self.values[t + 1]
                alive = 1.0 - self.dones[t]
                delta = self.rewards[t] + gamma * following * alive - self.values[t]
                last = delta + gamma * lam * alive * last
                advantages[t] = last
            returns = advantages + self.values
        obs = self.obs.reshape(-1, self.obs.shape[-1])
        actions = self.actions.reshape(-1, self.actions.shape[-1])
        old_logprobs, adv, ret = self.logprobs.reshape(-1), advantages.reshape(-1), returns.reshape(-1)
        size = obs.shape[0]
        minibatch = -(-size // self.minibatches)
        loss = torch.zeros(())
        for _ in range(self.epochs):
            order = torch.randperm(size, generator=self.generator)
            for start in range(0, size, minibatch):
                idx = order[start : start + minibatch]
                mean = self.actor(obs[idx])
                dist = torch.distributions.Normal(mean, self.log_std.exp().expand_as(mean))
                ratio = (dist.log_prob(actions[idx]).sum(-1) - old_logprobs[idx]).exp()
                a = adv[idx]
                a = (a - a.mean()) / (a.std() + 1e-8)
                policy_loss = -torch.min(ratio * a, ratio.clamp(1 - clip, 1 + clip) * a).mean()
                value_loss = 0.5 * (self.critic(obs[idx]).squeeze(-1) - ret[idx]).pow(2).mean()
                loss = policy_loss + 0.5 * value_loss
                self.optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(self.params, 0.5)
                self.optimizer.step()
        self.t = 0
        return float(loss.detach())


__all__ = ["PPOShapedLearner"]
