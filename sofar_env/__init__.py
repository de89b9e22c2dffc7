"""SOfAR: safe overtaking for autonomous racing.

Importing the package registers the Gymnasium environments ``SOfAR-<Track>-v0``
(see :mod:`sofar_env.registration`) and nothing heavier: the controllers (CasADi),
rendering (matplotlib / PIL) and the PettingZoo adapter are imported on first use.
"""

from .registration import ENV_IDS, register_envs

__version__ = "0.1.0"
__all__ = ["ENV_IDS", "parallel_env", "__version__"]

register_envs()


def parallel_env(**kwargs):
    """PettingZoo ``ParallelEnv`` in which every car runs its own overtaking stack.

    See :func:`sofar_env.multi_agent.parallel_env` for the arguments.
    """
    from .multi_agent import parallel_env as _parallel_env

    return _parallel_env(**kwargs)
