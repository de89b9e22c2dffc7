"""Evaluation of the stage function and its Jacobians at all N+1 stages of a linearisation point.

The linearisation function of :mod:`.model`, mapped over the ``N + 1`` stages, is
compiled to C once (:mod:`sofar_env.control.codegen`, cached on disk; the map itself is
compiled, so a linearisation is one C call without per-stage dispatch through CasADi)
and evaluated with one ``Function.buffer()`` call into pre-allocated numpy arrays. The
outputs A, B, dalat and dh land in one flat buffer (:class:`~.layout.LinearisationLayout`)
from which the QP matrices are gathered.
"""

from __future__ import annotations

import math

import numpy as np

from ..._jit import kernel
from ...vehicle import VehicleParams
from ..codegen import CodegenInfo, compile_function
from .layout import LinearisationLayout
from .model import DUMMY_OPPONENT, OPPONENT_ROWS, definition_name, linearisation_function, predict_into, stage_function
from .types import MPCConfig

__all__ = ["StageLinearisation"]


class StageLinearisation:
    """Inputs and outputs of the linearisation at the stages k = 0..N, as numpy arrays.

    Inputs (written by :meth:`set_opponents` and :meth:`evaluate`): ``x`` (N+1, 5),
    ``u`` (N+1, 2) (the last one 0), ``kappa`` (N+1,), ``dt`` (N+1,) (the last one ``ts``),
    ``o`` (N+1, slots, 3). Outputs: ``f`` (N+1, 5), ``alat`` (N+1,), ``h`` (N+1, slots) and,
    views of the flat buffer ``flat``, ``a`` (N+1, nnz A), ``b`` (N+1, nnz B), ``dalat``
    (N+1, 2), ``dh`` (N+1, slots, 3).

    Copies (``copy.deepcopy``, pickle) carry the configuration and the contents of these arrays, not
    the compiled function and its buffer (C handles): :meth:`__setstate__` builds them again from the
    configuration, loading the library from the disk cache (:mod:`sofar_env.control.codegen`) without
    compiling it.
    """

    _STATE = ("x", "u", "kappa", "o", "f", "flat", "alat", "h")
    """The arrays a copy carries (``a``, ``b``, ``dalat`` and ``dh`` are views of ``flat``)."""

    def __init__(self, cfg: MPCConfig, vehicle: VehicleParams, dts: np.ndarray):
        self._args = (cfg, vehicle, np.array(dts, dtype=float))
        self.slots = slots = max(cfg.max_opponents, 1)  # the stage function has at least one slot
        name = definition_name(vehicle, cfg.barrier, slots, cfg.integrator_substeps)
        self.stage = stage_function(vehicle, cfg.barrier, slots, cfg.integrator_substeps, name + "_stage")
        """The CasADi stage function (also what the IPOPT reference is built from)."""
        lin = linearisation_function(self.stage, name)
        k1 = cfg.horizon + 1
        mapped, info = compile_function(lin.map(f"{name}_x{k1}", "serial", k1, [], []), cfg.cache_dir, cfg.compile)
        self.codegen_info: CodegenInfo = info
        a_sp = lin.sparsity_out(1).get_triplet()
        b_sp = lin.sparsity_out(2).get_triplet()
        self.a_sparsity = (np.asarray(a_sp[0]), np.asarray(a_sp[1]))
        """(rows, cols) of the structural non-zeros of A = df/dx."""
        self.b_sparsity = (np.asarray(b_sp[0]), np.asarray(b_sp[1]))
        """(rows, cols) of the structural non-zeros of B = df/du."""
        nnz_a, nnz_b = len(a_sp[0]), len(b_sp[0])

        self.x = np.zeros((k1, 5))
        self.u = np.zeros((k1, 2))
        self.kappa = np.zeros(k1)
        self.dt = np.concatenate([dts, [cfg.ts]])
        self.o = np.zeros((k1, slots, OPPONENT_ROWS))
        self.o[:] = DUMMY_OPPONENT
        self._dummy = np.asarray(DUMMY_OPPONENT, dtype=float)
        self.f = np.zeros((k1, 5))
        self.layout = lay = LinearisationLayout(
            slots=slots, nnz_a=nnz_a, nnz_b=nnz_b, stages=k1, lat_scale=1.0 / math.sqrt(cfg.lat_acc_slack[1]),
            trk_scale=1.0 / math.sqrt(cfg.track_slack[1]), cbf_scale=1.0 / math.sqrt(cfg.barrier_slack[1]))
        self.flat = np.zeros(lay.size)  # constants + A, B, dalat, dh of all stages (the outputs write into it)
        self.flat[: lay.n_const] = lay.constants()
        self.a = self.flat[lay.off_a:lay.off_b].reshape(k1, nnz_a)
        self.b = self.flat[lay.off_b:lay.off_dal].reshape(k1, nnz_b)
        self.dalat = self.flat[lay.off_dal:lay.off_dh].reshape(k1, 2)
        self.dh = self.flat[lay.off_dh:].reshape(k1, slots, 3)
        self.alat = np.zeros(k1)
        self.h = np.zeros((k1, slots))
        # Function.buffer(): CasADi reads and writes these arrays in place. A fast path, kept because
        # it matters: a plain call with the conversions of the 5 inputs and 7 outputs to and from
        # CasADi matrices takes ~280 us instead of ~20 us per evaluation (measured; ~10 % of an env step).
        buf, self._eval = mapped.buffer()
        for i, arr in enumerate((self.x, self.u, self.kappa, self.dt, self.o)):
            buf.set_arg(i, memoryview(arr))
        for i, arr in enumerate((self.f, self.a, self.b, self.alat, self.dalat, self.h, self.dh)):
            buf.set_res(i, memoryview(arr))
        self._buf = buf  # keeps the buffer (and its pointers into the arrays above) alive

    def __getstate__(self) -> dict:
        """The constructor's arguments and the contents of the input and output arrays."""
        return {"args": self._args, "arrays": {name: getattr(self, name) for name in self._STATE}}

    def __setstate__(self, state: dict) -> None:
        """Build the linearisation again from ``state["args"]`` and fill its arrays with the saved contents."""
        self.__init__(*state["args"])
        for name, values in state["arrays"].items():
            getattr(self, name)[...] = values

    def set_opponents(self, rows: np.ndarray, t: np.ndarray) -> None:
        """Slots 0..M-1: the (M, 3 or 4) ``rows`` predicted at the times ``t``; the others: the dummy."""
        predict_into(rows, t, self.o, self._dummy)

    def evaluate(self, xbar: np.ndarray, ubar: np.ndarray, kappa: np.ndarray) -> None:
        """Evaluate at states ``xbar`` (N+1, 5), inputs ``ubar`` (N, 2), curvatures ``kappa`` (N+1,)."""
        _load(xbar, ubar, kappa, self.x, self.u, self.kappa)
        self._eval()


@kernel
def _load(xbar, ubar, kappa, x, u, kappa_in):
    """The inputs of :meth:`StageLinearisation.evaluate` copied into its buffers (``u[N] = 0``); one compiled
    call instead of four numpy assignments (:mod:`sofar_env._jit`)."""
    x[:] = xbar
    n = ubar.shape[0]
    u[:n] = ubar
    u[n:] = 0.0
    kappa_in[:] = kappa
