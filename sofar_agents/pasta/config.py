"""Hyper-parameters of PASTA (:class:`PASTAConfig`), validated on construction.

A field's annotation may carry the argument type of its command-line option
(``Annotated[float, positive_float]``, :mod:`sofar_agents.cli_types`), which ``train/pasta.py``
generates with :func:`sofar_agents.cli.add_dataclass_options`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Annotated, Any

from sofar_agents.cli_types import float_in, nonneg_float, nonneg_int, positive_float, positive_int

__all__ = ["PREFERENCE_SAMPLINGS", "SQUASHINGS", "PASTAConfig"]

_UNIT = float_in(0.0, 1.0)
_DISCOUNT = float_in(0.0, 1.0, low_open=True)
_QUANTILE = float_in(0.5, 1.0)
_KAPPA = float_in(0.0, 1.0, high_open=True)
_FRACTION = float_in(0.0, 1.0, low_open=True)

SQUASHINGS = ("sigmoid", "clip", "sigmoid-clip", "log-sigmoid")
"""Names of the action squashings (``PASTAConfig.action_squashing``, the checkpoint JSON)."""
PREFERENCE_SAMPLINGS = ("dirichlet", "fixed", "trade-off")
"""Names of the training preference distributions (``PASTAConfig.preference_sampling``)."""


@dataclass(frozen=True)
class PASTAConfig:
    """Hyper-parameters of PASTA.

    Defaults follow the reference PASTA implementation and the paper (2 x 256 hidden
    units). Step counts are environment steps; regrets, margins and reward clips are
    in units of the running return scale of their objective (see ``normalize_returns``).
    """

    learning_rate: Annotated[float, positive_float] = 3e-4
    """Adam learning rate shared by the actor and the critic."""
    adam_eps: Annotated[float, positive_float] = 1e-5
    """Adam epsilon."""
    n_steps: Annotated[int, positive_int] = 2048
    """Environment steps collected **per environment** per rollout; one update
    consumes ``n_steps * n_envs`` transitions."""
    batch_size: Annotated[int, positive_int] = 64
    """Minibatch size (transitions) for the PPO epochs."""
    n_epochs: Annotated[int, positive_int] = 10
    """Passes over the rollout per update."""
    clip_range: Annotated[float, positive_float] = 0.2
    """PPO clipping parameter epsilon of the probability ratio."""
    discount: Annotated[float, _DISCOUNT] = 0.99
    """Discount factor of the returns (the RL gamma, not the barrier gamma)."""
    gae_lambda: Annotated[float, _UNIT] = 0.95
    """GAE lambda."""
    vf_coef: Annotated[float, nonneg_float] = 0.5
    """Weight c1 of the value loss (sum over the heads of squared errors of the
    normalised per-objective returns)."""
    ent_coef: float = 0.01
    """Weight c2 of the entropy bonus (entropy of the squashed action distribution)."""
    max_grad_norm: Annotated[float, positive_float] = 0.5
    """Global gradient-norm clip, applied separately to the actor and the critic."""
    target_kl: Annotated[float, positive_float] | None = None
    """If set, stop the epochs of an update early once the approximate KL of a
    minibatch exceeds ``1.5 * target_kl``."""
    normalize_advantage: bool = True
    """Centre each objective's advantages per minibatch and divide all of them by
    one common scale (root-mean of the per-objective variances). A common scale
    keeps the relative size of the objectives: an objective without signal is not
    blown up into unit-variance noise."""
    normalize_returns: bool = True
    """Divide each objective's rewards by a running standard deviation of its
    discounted return (Welford / Chan parallel update over all transitions seen)."""
    reward_clip: Annotated[float, positive_float] | None = 10.0
    """Clip of the normalised rewards (in return standard deviations); None disables."""
    scalarization: str = "stch"
    """``"stch"``: smooth-Tchebycheff attention weights; ``"linear"``: the
    preference itself (alpha = w), i.e. linear scalarisation, for ablations."""
    maintenance: Annotated[float, _UNIT] = 0.15
    """Maintenance rate: share of the attention mixed uniformly over the objectives,
    so that no objective's weight drops below ``maintenance / K``."""
    utopia_margin: Annotated[float, nonneg_float] = 0.1
    """Margin added to every regret (in return standard deviations), i.e. the utopia
    lies slightly beyond the best performance seen. It lets the preference w shape
    the attention even when every objective is at its utopia."""
    utopia_quantile: Annotated[float, _QUANTILE] = 0.9
    """Quantile of the rollout's per-state lambda-returns (per objective) taken as that
    rollout's estimate of the best achievable return. The running utopia is the
    (slowly decaying) maximum of these estimates; 0.5 to 1."""
    utopia_decay: Annotated[float, _UNIT] = 0.01
    """Per-update rate at which the running utopia relaxes towards the current
    estimate when the latter is below it (0 = plain running maximum)."""
    regret_clip: Annotated[float, positive_float] = 10.0
    """Upper clip of the normalised regret (return standard deviations)."""
    mu_max: Annotated[float, positive_float] = 0.3
    """Upper bound and initial value of the smoothing temperature mu. The reference uses 10; at a
    temperature much above the weighted regrets ``w_j * regret_j`` (about 0.03 to 2 here) the attention is
    uniform and the preference input has no effect on the loss, so the default keeps mu between
    ``mu_min`` and 0.3 (docs/decisions/pasta-temperature.md)."""
    mu_min: Annotated[float, positive_float] = 0.05
    """Lower bound of mu, reached at the end of the linear decay."""
    mu_ema: Annotated[float, _UNIT] = 0.05
    """EMA rate with which mu follows its target each update."""
    kappa: Annotated[float, _KAPPA] = 0.4
    """Conflict threshold: above this gradient-conflict ratio the target mu is pushed
    back towards ``mu_max`` in proportion to ``(conflict - kappa) / (1 - kappa)``."""
    mu_decay_steps: int = 1_000_000
    """Length of the linear decay of the target mu, in environment steps counted over
    all envs (as ``num_timesteps``): the target falls from ``mu_max`` to ``mu_min`` over
    this many steps and stays at ``mu_min`` afterwards (the reference's
    ``total_train_steps``). ``train/pasta.py`` sets it to ``--total-steps`` unless given."""
    mu_decay: bool = True
    """Enable the linear decay of the target mu."""
    conflict_boost: bool = True
    """Enable the conflict-driven push of the target mu towards ``mu_max``."""
    fixed_mu: Annotated[float, positive_float] | None = None
    """If set, use this constant mu and disable the controller."""
    pcgrad: bool = False
    """De-conflict the per-objective actor gradients with PCGrad before summing."""
    conflict_every: Annotated[int, positive_int] = 1
    """Measure the gradient conflict on every n-th minibatch (PCGrad, when on, needs
    the per-objective gradients of every minibatch regardless)."""
    hidden_sizes: Annotated[tuple[int, ...], positive_int] = (256, 256)
    """Hidden widths of the actor and of the critic trunk (tanh activations)."""
    critic_head_hidden: int = 64
    """Hidden width of each per-objective value head (0 = a single linear layer)."""
    log_std_init: float = -0.5
    """Initial log standard deviation of the pre-squash Gaussian (state independent); in
    action units with ``action_squashing="clip"`` (e.g. -2.3 for a spread of 0.1 in gamma)."""
    action_squashing: str = "sigmoid"
    """How the Gaussian ``u`` becomes the box action: ``"sigmoid"``, ``a = low + (high - low)
    * sigmoid(u)`` (the bounds only in the limit), ``"clip"``, ``a = clip(u, low, high)``
    with ``u`` in action units (a censored Gaussian: a deterministic policy can sit exactly
    on a bound), ``"sigmoid-clip"``, a sigmoid reaching ``squash_margin`` of the range beyond
    each bound, clipped to the bounds (each bound at a finite ``u``, a sigmoid between them), or
    ``"log-sigmoid"``, ``a = low * (high / low) ** sigmoid(u)``, the sigmoid in log units (as
    fine near the lower bound, relative to the action, as near the upper one; needs ``low > 0``).
    See :mod:`sofar_agents.pasta.distribution`."""
    squash_margin: Annotated[float, _FRACTION] = 0.05
    """``"sigmoid-clip"`` only: how far beyond each bound the sigmoid reaches, as a fraction of
    ``high - low`` (0.05 on the gamma range [0.05, 1]: from 0.0025 to 1.0475; the lower bound at
    ``u = -3.04``)."""
    initial_action: float | None = None
    """If set, the actor's output bias is initialised so that the deterministic action of
    the untrained policy is this value (in action units, strictly inside the bounds), e.g. a
    known-good fixed gamma; ``None`` starts at the middle of the action range."""
    preference_sampling: str = "dirichlet"
    """``"dirichlet"``: draw a preference w per episode from a Dirichlet whose mean is
    the agent's preference; ``"fixed"``: always use the agent's preference; ``"trade-off"``:
    the first two objectives split what the agent's preference leaves them,
    ``w_0 = u (w_0 + w_1)``, ``w_1 = (1 - u) (w_0 + w_1)`` with ``u`` uniform on [0, 1], and
    the other objectives keep their weights. In SOfAR this is the safety-against-overtakes
    path that ``eval/pareto.py`` sweeps (with a preference of ``0.5 0.4 0.1/3 0.1/3 0.1/3``,
    exactly that path), drawn uniformly, ends included: a Dirichlet around the reference
    preference puts about one draw in 13 beyond a safety weight of 0.8 and one in 60 beyond 0.9
    (docs/decisions/pasta-temperature.md)."""
    preference_interval: Annotated[int, nonneg_int] = 0
    """Draw a new preference every this many steps of an episode (0: once per episode, as the reference).
    The switch is a segment boundary for the advantages: the segment's returns bootstrap from the value
    under the preference it was driven with. A rollout must hold many preferences for the actor to learn
    what its preference input means; episodes of the racing worlds are longer than a rollout
    (docs/decisions/pasta-temperature.md). Local rollouts only (``train/pasta.py --backend local``)."""
    dirichlet_concentration: Annotated[float, positive_float] = 1.0
    """Concentration c of the preference Dirichlet, ``Dir(c * K * w)``. With a uniform
    w and c = 1 this is the uniform distribution on the simplex."""

    def __post_init__(self) -> None:
        if self.n_steps < 1 or self.batch_size < 1 or self.n_epochs < 1:
            raise ValueError("n_steps, batch_size and n_epochs must be positive")
        if not 0.0 < self.discount <= 1.0 or not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError("discount must lie in (0, 1] and gae_lambda in [0, 1]")
        if not 0.0 < self.mu_min <= self.mu_max:
            raise ValueError(f"need 0 < mu_min <= mu_max, got {self.mu_min}, {self.mu_max}")
        if not 0.0 <= self.maintenance <= 1.0:
            raise ValueError(f"maintenance must lie in [0, 1], got {self.maintenance}")
        if not 0.0 <= self.kappa < 1.0:
            raise ValueError(f"kappa must lie in [0, 1), got {self.kappa}")
        if self.scalarization not in ("stch", "linear"):
            raise ValueError(f"scalarization must be 'stch' or 'linear', got {self.scalarization!r}")
        if self.action_squashing not in SQUASHINGS:
            raise ValueError(f"action_squashing must be one of {SQUASHINGS}, got {self.action_squashing!r}")
        if isinstance(self.squash_margin, bool) or not isinstance(self.squash_margin, (int, float)) \
                or not 0.0 < self.squash_margin <= 1.0:
            raise ValueError(f"squash_margin must lie in (0, 1], got {self.squash_margin!r}")
        if self.preference_sampling not in PREFERENCE_SAMPLINGS:
            raise ValueError(
                f"preference_sampling must be one of {PREFERENCE_SAMPLINGS}, got {self.preference_sampling!r}"
            )
        if not 0.5 <= self.utopia_quantile <= 1.0:
            raise ValueError(f"utopia_quantile must lie in [0.5, 1], got {self.utopia_quantile}")
        if isinstance(self.preference_interval, bool) or not isinstance(self.preference_interval, int) \
                or self.preference_interval < 0:
            raise ValueError(f"preference_interval must be an integer >= 0, got {self.preference_interval!r}")
        if self.conflict_every < 1:
            raise ValueError("conflict_every must be >= 1")
        object.__setattr__(self, "hidden_sizes", tuple(int(h) for h in self.hidden_sizes))

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable dictionary of the fields."""
        d = dataclasses.asdict(self)
        d["hidden_sizes"] = list(self.hidden_sizes)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PASTAConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"unknown PASTAConfig fields: {sorted(unknown)}")
        d = dict(d)
        if "hidden_sizes" in d:
            d["hidden_sizes"] = tuple(d["hidden_sizes"])
        return cls(**d)
