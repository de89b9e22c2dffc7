"""The package's own exception types (no dependencies, so any module may import them).

* :class:`ConfigError` (a ``ValueError``): an invalid or unknown configuration key or value, raised when
  a configuration is built (``gymnasium.make``, :func:`~sofar_env.config.make_env_config`, a config
  dataclass), never while an episode runs. The message names the key with its path (``race.dt``,
  ``stack.mpc.qp_eps_abs``) and what it must be.
* :class:`ResetNeeded` (a ``RuntimeError``): ``step()`` (or ``render()``) with no episode running, i.e.
  before the first successful ``reset()`` or after the episode ended. Nothing is changed by the call.
"""

from __future__ import annotations

__all__ = ["ConfigError", "ResetNeeded"]


class ConfigError(ValueError):
    """An invalid or unknown configuration key or value; the message names the key and its path."""


class ResetNeeded(RuntimeError):
    """No episode is running (none started yet, the last reset failed, or the episode ended): call reset()."""
