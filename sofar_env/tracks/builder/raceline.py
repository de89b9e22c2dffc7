"""The raceline: a minimum-curvature QP with a verified edge clearance.

The variable is a lateral shift ``alpha_i`` along the normals of a reference line
(the centreline at ``qp_spacing`` at first). The discrete curvature is linearised
around the reference and the sum of squared curvatures is minimised with OSQP,
subject to ``alpha_i`` keeping the line at least ``clearance + qp_margin`` from
each edge along the normal; ``qp_iterations`` solves, each around the previous
solution. Where the corridor is narrower than twice that margin the line is
centred, within a few centimetres.

The solution is then resampled at the output spacing through a periodic cubic
spline (after a light periodic smoothing), and the clearance is verified with
exact point-to-polyline distances at every sample and half-way between samples,
against both the stored (smoothed) and the source edges. Where it is short, the
bounds are tightened around the nearest QP nodes and the QP is solved again.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ..curve import PeriodicCurve
from .config import BuildConfig
from .polyline import edge_widths, polyline_distance, spline_resample_closed, tangent_normal

__all__ = ["Raceline", "FittedRaceline", "fit_raceline"]

logger = logging.getLogger(__name__)

_NARROW_SLACK = 0.05  # [m] lateral freedom around the centre where the corridor is too narrow


# ------------------------------------------------------------------ the QP


def _solve_qp(P: sparse.csc_matrix, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """min 1/2 x'Px + q'x subject to lo <= x <= hi, solved with OSQP.

    The curvature Hessian is ill-conditioned only in its smooth, nearly
    curvature-free modes (slow lateral drifts along long straights), where ADMM
    converges slowly.  Errors in those modes barely change the curvature, so an
    iteration cap is accepted; the bounds are enforced by clipping and the
    clearance is verified afterwards anyway.
    """
    import osqp  # imported lazily: only the builder needs it

    n = len(q)
    settings = dict(verbose=False, eps_abs=1e-5, eps_rel=1e-5, max_iter=20000, adaptive_rho_interval=25)
    major = int(str(getattr(osqp, "__version__", "1")).split(".")[0])
    settings["polishing" if major >= 1 else "polish"] = False
    solver = osqp.OSQP()
    solver.setup(sparse.triu(P, format="csc"), q, sparse.identity(n, format="csc"), lo, hi, **settings)
    try:
        result = solver.solve(raise_error=False)
    except TypeError:  # osqp < 1.0 has no raise_error argument
        result = solver.solve()
    status = str(result.info.status).lower()
    usable = "solved" in status or "maximum iterations" in status
    if not usable or result.x is None or not np.all(np.isfinite(result.x)):
        raise RuntimeError(f"minimum-curvature QP failed: OSQP status {result.info.status!r}")
    logger.info("OSQP: %s after %d iterations", result.info.status, result.info.iter)
    return np.clip(result.x, lo, hi)


def _curvature_jacobian(ref: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, sparse.csc_matrix]:
    """Discrete curvature of the closed polyline ``ref`` and its Jacobian with
    respect to shifts alpha along ``normal``.

    kappa_i = u x w / |u|^3 with u = (P_{i+1} - P_{i-1}) / 2 and
    w = P_{i+1} - 2 P_i + P_{i-1}; the Jacobian is tridiagonal (periodic).
    """
    n = len(ref)
    nxt, prv = np.roll(ref, -1, axis=0), np.roll(ref, 1, axis=0)
    u = 0.5 * (nxt - prv)
    w = nxt - 2.0 * ref + prv
    m2 = np.einsum("ij,ij->i", u, u)
    m = np.sqrt(m2)
    c = u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]
    kappa = c / (m2 * m)
    idx = np.arange(n)
    rows, cols, vals = [], [], []
    # d u / d alpha_j and d w / d alpha_j for j = i-1, i, i+1
    for offset, du_coef, dw_coef in ((-1, -0.5, 1.0), (0, 0.0, -2.0), (1, 0.5, 1.0)):
        j = (idx + offset) % n
        nj = normal[j]
        du = du_coef * nj
        dw = dw_coef * nj
        dc = (du[:, 0] * w[:, 1] - du[:, 1] * w[:, 0]) + (u[:, 0] * dw[:, 1] - u[:, 1] * dw[:, 0])
        dm2 = 2.0 * np.einsum("ij,ij->i", u, du)
        dk = dc / (m2 * m) - 1.5 * c * dm2 / (m2 * m2 * m)
        rows.append(idx)
        cols.append(j)
        vals.append(dk)
    jac = sparse.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    return kappa, jac


def _min_curvature_shift(ref: np.ndarray, lo: np.ndarray, hi: np.ndarray, regularization: float) -> np.ndarray:
    """Shift alpha along the normals of the uniform closed ``ref`` minimising sum kappa_i^2,
    with the curvature linearised around the reference (kappa ~ kappa_ref + J alpha)."""
    n = len(ref)
    _, normal = tangent_normal(ref)
    kappa, jac = _curvature_jacobian(ref, normal)
    h2 = float(np.mean(np.hypot(*(np.roll(ref, -1, axis=0) - ref).T))) ** 2
    A = (h2 * jac).tocsc()  # scaled so that its entries are of order one
    b = h2 * kappa
    P = 2.0 * (A.T @ A + regularization * sparse.identity(n))
    q = 2.0 * (A.T @ b)
    return _solve_qp(P.tocsc(), q, lo, hi)


def _shift_bounds(
    ref: np.ndarray, left: np.ndarray, right: np.ndarray, margin: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Shift bounds along the normals of ``ref`` and the corridor mask that is too narrow."""
    _, normal = tangent_normal(ref)
    wl, wr = edge_widths(ref, normal, left, right)
    lo, hi = -(wr - margin), wl - margin
    narrow = lo > hi
    if narrow.any():
        # centre the line, with a few centimetres of slack so that the QP can
        # still smooth out the small ripples of the edge data
        mid = 0.5 * (wl - wr)
        lo = np.where(narrow, mid - _NARROW_SLACK, lo)
        hi = np.where(narrow, mid + _NARROW_SLACK, hi)
    return lo, hi, normal, narrow


@dataclass
class Raceline:
    """A closed line given as shifts ``alpha`` along the normals of a reference line."""

    ref: np.ndarray
    alpha: np.ndarray
    normal: np.ndarray
    narrow: np.ndarray

    @property
    def points(self) -> np.ndarray:
        """The line's points, ``ref + alpha * normal``."""
        return self.ref + self.alpha[:, None] * self.normal


def _iterate_qp(center: np.ndarray, left: np.ndarray, right: np.ndarray, config: BuildConfig) -> Raceline:
    """``qp_iterations`` QP solves, each linearised around the previous solution (resampled
    at ``qp_spacing``), starting from the centreline."""
    ref = center
    base = config.clearance + config.qp_margin
    result = None
    for it in range(config.qp_iterations):
        margin = np.full(len(ref), base)
        lo, hi, normal, narrow = _shift_bounds(ref, left, right, margin)
        alpha = _min_curvature_shift(ref, lo, hi, config.qp_regularization)
        result = Raceline(ref, alpha, normal, narrow)
        logger.info("QP iteration %d: max |shift| %.3f m", it + 1, float(np.max(np.abs(alpha))))
        if it < config.qp_iterations - 1:
            ref, _ = spline_resample_closed(result.points, config.qp_spacing)
    assert result is not None
    return result


# ------------------------------------------------- sampling and clearance


def _finish(points: np.ndarray, anchor: np.ndarray, config: BuildConfig) -> tuple[np.ndarray, float, PeriodicCurve]:
    """Uniform raceline samples starting near ``anchor`` and their spline."""
    start = int(np.argmin(np.hypot(*(points - anchor).T)))
    samples, length = spline_resample_closed(
        np.roll(points, -start, axis=0), config.spacing, smoothing=config.raceline_smoothing
    )
    s = np.arange(len(samples)) * (length / len(samples))
    return s, length, PeriodicCurve(s, samples, length)


def _clearances(
    curve: PeriodicCurve, s: np.ndarray, left: np.ndarray, right: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge distances at the samples and half-way between them."""
    ds = curve.length / len(s)
    dense = np.concatenate([s, s + 0.5 * ds])
    x, y, _, _ = curve.eval(curve.wrap(dense))
    pts = np.column_stack([x, y])
    return pts, polyline_distance(pts, left), polyline_distance(pts, right)


@dataclass
class FittedRaceline:
    """The raceline after the clearance check: samples, spline and the checked distances."""

    s: np.ndarray
    """(K,) arc length of the uniform samples, ``s[0] = 0`` (at the sample nearest the anchor) [m]."""
    length: float
    """Closed length of the raceline [m]."""
    curve: PeriodicCurve
    """Periodic cubic spline in s through the samples."""
    check_points: np.ndarray
    """(2K, 2) points where the clearance was checked: the samples, then the mid-points [m]."""
    d_left: np.ndarray
    """(2K,) distance from each check point to the stored left edge [m]."""
    d_right: np.ndarray
    """(2K,) distance from each check point to the stored right edge [m]."""
    narrow: np.ndarray
    """(QP nodes,) bool: where the corridor was too narrow and the line was centred."""


def fit_raceline(
    center: np.ndarray,
    left_s: np.ndarray,
    right_s: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    anchor: np.ndarray,
    name: str,
    config: BuildConfig,
) -> FittedRaceline:
    """Minimum-curvature raceline between the stored edges ``left_s``, ``right_s`` that keeps
    ``config.clearance`` from them and from the source edges ``left``, ``right``.

    ``anchor`` is the point near which ``s = 0`` is placed.

    Raises:
        RuntimeError: if the clearance still fails after ``config.max_repairs`` repairs.
    """
    race = _iterate_qp(center, left_s, right_s, config)

    # Verify the clearance exactly; tighten the bounds where it is short and re-solve.
    ref_tree = cKDTree(race.ref)
    margin = np.full(len(race.ref), config.clearance + config.qp_margin)
    for repair in range(config.max_repairs + 1):
        s, length, curve = _finish(race.points, anchor, config)
        pts, d_left, d_right = _clearances(curve, s, left_s, right_s)
        # enforce the clearance to the stored (smoothed) and to the source edges
        need_l = np.minimum(d_left, polyline_distance(pts, left))
        need_r = np.minimum(d_right, polyline_distance(pts, right))
        _, near = ref_tree.query(pts)
        excused = race.narrow[near]
        short_l = (need_l < config.clearance) & ~excused
        short_r = (need_r < config.clearance) & ~excused
        if not (short_l.any() or short_r.any()):
            break
        if repair == config.max_repairs:
            raise RuntimeError(
                f"{name}: raceline clearance {min(need_l.min(), need_r.min()):.3f} m below "
                f"{config.clearance} m after {config.max_repairs} repairs"
            )
        deficit = np.zeros(len(race.ref))
        for short, dist in ((short_l, need_l), (short_r, need_r)):
            for node, dd in zip(near[short], config.clearance - dist[short]):
                for k in range(-3, 4):
                    j = (node + k) % len(deficit)
                    deficit[j] = max(deficit[j], dd)
        margin = margin + np.where(deficit > 0, deficit + 0.01, 0.0)
        logger.info("clearance repair %d: %d samples short by up to %.3f m", repair + 1,
                    int(short_l.sum() + short_r.sum()), float(deficit.max()))
        lo, hi, normal, narrow = _shift_bounds(race.ref, left_s, right_s, margin)
        race = Raceline(race.ref, _min_curvature_shift(race.ref, lo, hi, config.qp_regularization), normal, narrow | race.narrow)
    return FittedRaceline(s=s, length=length, curve=curve, check_points=pts, d_left=d_left, d_right=d_right,
                          narrow=race.narrow)
