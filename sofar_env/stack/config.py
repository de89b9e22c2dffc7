"""Configuration of the overtaking stack and its named presets, as views of the configuration layer.

:class:`StackConfig` is defined in :mod:`sofar_env.configs.stack` (importable without the solvers); the presets
are the entries of :data:`~sofar_env.configs.registry.STACK_PRESET_REGISTRY`, each a frozen value with its
documentation. :func:`stack_preset` and :data:`STACK_PRESETS` read that registry, so a preset registered there
(:func:`~sofar_env.configs.registry.register_stack_preset`) is one entry and shows here at once.
"""

from __future__ import annotations

from ..configs.registry import STACK_PRESET_REGISTRY, NameView
from ..configs.registry import stack_preset as _stack_preset
from ..configs.stack import StackConfig

__all__ = ["StackConfig", "STACK_PRESETS", "stack_preset"]

STACK_PRESETS = NameView(STACK_PRESET_REGISTRY)
"""Names accepted by :func:`stack_preset` (and by the environments' ``stack=`` key), in registration order:
``"sofar"`` (the default, now ``"sofar-6"``), ``"sofar-1"``, ``"paper"``, ``"sofar-ends"``, ``"sofar-recover"``,
``"sofar-2"``, ``"sofar-3"``, ``"sofar-4"``, ``"sofar-5"``, ``"sofar-6"``, ``"sofar-daqp"``, ``"reference-numerics"``,
``"reference-numerics-no-phantoms"``. A live view of the registry that compares equal to the tuple of these
names."""


def stack_preset(name: str) -> StackConfig:
    """The controller of a named preset (a frozen :class:`StackConfig`; case and surrounding spaces ignored).

    The presets and what each one is: ``STACK_PRESET_REGISTRY[name].doc``
    (:mod:`sofar_env.configs.registry`). ``"sofar"`` is the default of every environment (now ``"sofar-6"``;
``"sofar-1"`` is the default before it, ``StackConfig()``); ``"paper"`` is the
    paper's Algorithm 1 as written (the *controller* meaning of "paper", independent of the world
    ``scenario="paper"`` and the observation layout ``observation="paper"``). Raises ``ValueError`` listing the
    presets for an unknown name.
    """
    return _stack_preset(name)
