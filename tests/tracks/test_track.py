"""Tests of the Track API and of the four shipped circuits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shipped_circuits import copy_circuit

from sofar_env.tracks import TRACK_NAMES, Track, TrackFormatError

REFERENCE_LENGTHS = {"LagunaSeca": 3558.0, "Monza": 5760.0, "Indianapolis": 4057.0, "Kentucky": 2361.0}
OVALS = ("Indianapolis", "Kentucky")


@pytest.fixture(scope="module")
def tracks() -> dict[str, Track]:
    return {name: Track.load(name) for name in TRACK_NAMES}


def edge_distance(points: np.ndarray, poly: np.ndarray, chunk: int = 200) -> np.ndarray:
    """Exact distance from points to a closed polyline (independent brute force)."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    e = b - a
    ee = np.sum(e * e, axis=1)
    out = []
    for lo in range(0, len(points), chunk):
        p = points[lo : lo + chunk, None, :]
        t = np.clip(np.sum((p - a) * e, axis=2) / ee, 0.0, 1.0)
        d = p - (a + t[..., None] * e)
        out.append(np.sqrt(np.min(np.sum(d * d, axis=2), axis=1)))
    return np.concatenate(out)


def edge_distance_lower_bound(points: np.ndarray, poly: np.ndarray, exact_below: float) -> np.ndarray:
    """A lower bound of the distance to a closed polyline that is exact wherever
    the distance is below ``exact_below``; the bound nearest-vertex distance minus
    half the longest segment is used elsewhere (fast and still rigorous)."""
    from scipy.spatial import cKDTree

    half = 0.5 * float(np.max(np.hypot(*(np.roll(poly, -1, axis=0) - poly).T)))
    tree = cKDTree(poly)
    d0, _ = tree.query(points)
    out = d0 - half
    near = np.flatnonzero(out < exact_below)
    # The closest segment has an end point within d0 + half of the point.
    k = 32
    dk, ik = tree.query(points[near], k=k)
    complete = dk[:, -1] > d0[near] + half
    m = len(poly)
    for row, p in enumerate(points[near]):
        if complete[row]:
            cand = np.unique(np.concatenate([ik[row], (ik[row] - 1) % m]))
            seg = np.column_stack([cand, (cand + 1) % m])
            a, b = poly[seg[:, 0]], poly[seg[:, 1]]
            e = b - a
            t = np.clip(np.sum((p - a) * e, axis=1) / np.sum(e * e, axis=1), 0.0, 1.0)
            out[near[row]] = np.min(np.hypot(*(p - a - t[:, None] * e).T))
        else:
            out[near[row]] = edge_distance(p[None, :], poly)[0]
    return out


# ------------------------------------------------------------------ loading


def test_load_names_and_aliases(tracks):
    assert set(TRACK_NAMES) == {"LagunaSeca", "Monza", "Indianapolis", "Kentucky"}
    for alias, name in (("LS", "LagunaSeca"), ("ims", "Indianapolis"), ("Ks", "Kentucky"), ("MONZA", "Monza"),
                        ("lagunaseca", "LagunaSeca")):
        assert Track.load(alias).name == name
    for name, track in tracks.items():
        assert track.name == name
        assert track.meta["format_version"] == 1
        assert track.xy.shape == (len(track.s), 2)
        assert track.left_edge.shape[1] == 2 and track.right_edge.shape[1] == 2
        assert track.max_speed == pytest.approx(float(track.v.max()))
        assert track.max_speed <= track.meta["builder"]["top_speed"] + 1e-9


def test_unknown_name_lists_valid_names():
    with pytest.raises(ValueError, match="LagunaSeca") as info:
        Track.load("Nurburgring")
    assert not isinstance(info.value, TrackFormatError)


def test_load_from_folder_path(tmp_path):
    folder = copy_circuit("Kentucky", tmp_path)
    track = Track.load(folder)
    assert track.name == "Kentucky"
    assert Track.load(str(folder)).length == track.length


def test_missing_folder(tmp_path):
    with pytest.raises(TrackFormatError, match="no_such_dir"):
        Track.load(tmp_path / "no_such_dir")


# ---------------------------------------------------------------- geometry


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_lap_length_close_to_reference(tracks, name):
    track = tracks[name]
    assert abs(track.length - REFERENCE_LENGTHS[name]) / REFERENCE_LENGTHS[name] < 0.02
    closed = np.vstack([track.xy, track.xy[:1]])
    polyline = float(np.sum(np.hypot(*np.diff(closed, axis=0).T)))
    assert polyline == pytest.approx(track.length, rel=1e-4)
    assert track.s[0] == 0.0 and np.all(np.diff(track.s) > 0) and track.s[-1] < track.length


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_raceline_clearance_to_edges(tracks, name):
    track = tracks[name]
    required = max(1.0, track.meta["builder"]["clearance"] - 0.01)
    ds = track.length / len(track.s)
    s = np.concatenate([track.s, track.s + 0.5 * ds])
    x, y = track.to_cartesian(s, np.zeros_like(s))
    pts = np.column_stack([x, y])
    d_left = edge_distance_lower_bound(pts, track.left_edge, required + 1.0)
    d_right = edge_distance_lower_bound(pts, track.right_edge, required + 1.0)
    assert d_left.min() >= required, (name, d_left.min())
    assert d_right.min() >= required, (name, d_right.min())
    assert track.meta["min_clearance_m"] == pytest.approx(min(d_left.min(), d_right.min()), abs=2e-3)
    # the stored widths are measured along the normal, so never below the distance
    sub = slice(None, None, 13)
    assert np.all(track.w_left[sub] >= edge_distance(track.xy[sub], track.left_edge) - 1e-5)
    assert np.all(track.w_right[sub] >= edge_distance(track.xy[sub], track.right_edge) - 1e-5)


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_edges_on_their_side(tracks, name):
    track = tracks[name]
    _, n_left = track.to_frenet(track.left_edge[:, 0], track.left_edge[:, 1])
    _, n_right = track.to_frenet(track.right_edge[:, 0], track.right_edge[:, 1])
    assert np.all(n_left > 0) and np.all(n_right < 0)


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_speed_profile_limits(tracks, name):
    track = tracks[name]
    b = track.meta["builder"]
    v, kappa = track.v, track.kappa
    assert np.all(v > 0) and np.all(v <= b["top_speed"] + 1e-9)
    assert np.max(v * v * np.abs(kappa)) <= b["a_lat_max"] + 1e-6
    ds = np.diff(np.append(track.s, track.length))
    accel = (np.roll(v, -1) ** 2 - v**2) / (2.0 * ds)  # includes the wrap-around step
    assert accel.max() <= b["a_accel_max"] + 1e-6
    assert accel.min() >= -b["a_brake_max"] - 1e-6
    lap = float(np.sum(2.0 * ds / (v + np.roll(v, -1))))
    assert lap == pytest.approx(track.meta["lap_time_s"], abs=1e-3)


def test_driving_direction_and_curvature_sign(tracks):
    for name, track in tracks.items():
        ds = np.diff(np.append(track.s, track.length))
        total_turn = float(np.sum(track.kappa * ds))
        expected = -2 * math.pi if name == "Monza" else 2 * math.pi
        assert total_turn == pytest.approx(expected, abs=0.05), name
        assert track.meta["driving_direction"] == ("clockwise" if name == "Monza" else "counter-clockwise")
        # heading change agrees with the curvature sign
        psi = np.unwrap(track.heading(track.s))
        assert psi[-1] - psi[0] == pytest.approx(expected, abs=0.05)


def test_curvature_matches_spline(tracks):
    track = tracks["LagunaSeca"]
    s = track.s[::7]
    # stored kappa comes from the spline before the positions were rounded to 1 um
    assert np.allclose(track.curvature(s), track.spline_curvature(s), atol=1e-5)
    assert np.allclose(track.heading(track.s), track.psi, atol=1e-6)


# ------------------------------------------------------------------ Frenet


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_frenet_round_trip(tracks, name):
    track = tracks[name]
    rng = np.random.default_rng(7)
    s = rng.uniform(0.0, track.length, 4000)
    if name in OVALS:
        n = rng.uniform(-15.0, 15.0, s.shape)
    else:
        n = rng.uniform(-track.width_right(s), track.width_left(s))
    x, y = track.to_cartesian(s, n)
    s2, n2 = track.to_frenet(x, y)
    assert np.max(np.abs(track.gap(s2, s))) < 1e-3
    assert np.max(np.abs(n2 - n)) < 1e-3
    x3, y3 = track.to_cartesian(s2, n2)
    assert np.max(np.hypot(x3 - x, y3 - y)) < 1e-3
    # with a nearby hint
    s4, n4 = track.to_frenet(x, y, s_hint=track.wrap(s + rng.uniform(-5.0, 5.0, s.shape)))
    assert np.max(np.abs(track.gap(s4, s))) < 1e-3 and np.max(np.abs(n4 - n)) < 1e-3


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_cartesian_round_trip_random_points(tracks, name):
    track = tracks[name]
    rng = np.random.default_rng(11)
    base = track.xy[rng.integers(0, len(track.s), 3000)]
    pts = base + rng.uniform(-15.0, 15.0, base.shape)
    s, n = track.to_frenet(pts[:, 0], pts[:, 1])
    assert np.all((s >= 0) & (s < track.length))
    x, y = track.to_cartesian(s, n)
    assert np.max(np.hypot(x - pts[:, 0], y - pts[:, 1])) < 1e-3


def test_scalar_calls_return_floats_and_match_vectors(tracks):
    track = tracks["Monza"]
    s0, n0 = 1234.5, 2.5
    x, y = track.to_cartesian(s0, n0)
    assert isinstance(x, float) and isinstance(y, float)
    for hint in (None, s0 + 4.0, s0 - 30.0):
        s, n = track.to_frenet(x, y, hint)
        assert isinstance(s, float) and isinstance(n, float)
        assert abs(s - s0) < 1e-6 and abs(n - n0) < 1e-6
    for fn in (track.curvature, track.width_left, track.width_right, track.speed, track.heading, track.wrap):
        value = fn(s0)
        assert isinstance(value, float)
        assert value == pytest.approx(float(fn(np.array([s0]))[0]), abs=1e-12)
    assert isinstance(track.gap(10.0, 20.0), float)
    assert track.normal(s0).shape == (2,)
    assert track.normal(np.array([[1.0, 2.0, 3.0]])).shape == (1, 3, 2)
    assert np.allclose(track.normal(s0), track.normal(np.array([s0]))[0])
    # arrays of other shapes are kept
    grid = np.full((3, 4), s0)
    xs, ys = track.to_cartesian(grid, 0.0)
    assert xs.shape == (3, 4)
    ss, nn = track.to_frenet(xs, ys)
    assert ss.shape == (3, 4) and np.allclose(ss, s0)


def test_normal_points_left(tracks):
    track = tracks["LagunaSeca"]
    s = np.linspace(0.0, track.length, 50, endpoint=False)
    psi = track.heading(s)
    nrm = track.normal(s)
    assert np.allclose(nrm, np.column_stack([-np.sin(psi), np.cos(psi)]), atol=1e-12)
    x0, y0 = track.to_cartesian(s, 0.0)
    x1, y1 = track.to_cartesian(s, 1.0)
    cross = np.cos(psi) * (y1 - y0) - np.sin(psi) * (x1 - x0)
    assert np.allclose(cross, 1.0)


def test_periodicity_wrap_and_gap(tracks):
    track = tracks["Kentucky"]
    L = track.length
    s = np.array([-1e-13, -5.0, 0.0, 10.0, L - 1e-9, L, 2.5 * L])
    w = track.wrap(s)
    assert np.all((w >= 0) & (w < L))
    assert track.wrap(-1e-17) < L and track.wrap(L) == 0.0
    for fn in (track.curvature, track.width_left, track.width_right, track.speed, track.heading):
        assert np.allclose(fn(s + L), fn(s)) and np.allclose(fn(s - 3 * L), fn(s))
    a = np.array([0.0, 10.0, L - 1.0, 5.0])
    b = np.array([L - 1.0, 0.0, 1.0, 5.0])
    assert np.allclose(track.gap(a, b), [1.0, 10.0, -2.0, 0.0])
    g = track.gap(np.linspace(0, L, 101), 0.3 * L)
    assert np.all((g >= -L / 2) & (g < L / 2))
    assert track.gap(0.0, 0.5 * L) == pytest.approx(-0.5 * L)
    x0, y0 = track.to_cartesian(0.0, 1.0)
    x1, y1 = track.to_cartesian(L, 1.0)
    assert math.hypot(x1 - x0, y1 - y0) < 1e-9


def test_sampled_quantities_wrap_and_gap_match_their_formulas(tracks):
    """Arrays: periodic np.interp of the closed tables; scalars: the lerp on Python floats (the
    scalar path, which differs from np.interp in the last bit at some points)."""
    track = tracks["LagunaSeca"]
    L = track.length
    rng = np.random.default_rng(2)
    s = np.concatenate([rng.uniform(-2 * L, 3 * L, 3000), [0.0, L, -L, 2 * L, -0.0, 1e-300, -1e-300, L / 2, -L / 2],
                        track.s[:20], track.s[:20] + L])
    wrapped = np.mod(s, L)
    wrapped = np.where(wrapped >= L, 0.0, wrapped)
    np.testing.assert_array_equal(track.wrap(s), wrapped)
    half = 0.5 * L
    ref_gap = np.mod(s - 123.0 + half, L)
    np.testing.assert_array_equal(track.gap(s, 123.0), np.where(ref_gap >= L, 0.0, ref_gap) - half)
    knots = np.append(track.s, L)
    i = np.clip(np.searchsorted(knots, wrapped, side="right") - 1, 0, len(track.s) - 1)
    w = (wrapped - knots[i]) / (knots[i + 1] - knots[i])
    for name, column in (("speed", track.v), ("curvature", track.kappa), ("width_left", track.w_left),
                         ("width_right", track.w_right)):
        closed = np.append(column, column[0])
        fn = getattr(track, name)
        np.testing.assert_array_equal(fn(s), np.interp(wrapped, knots, closed))  # arrays: np.interp
        scalar = closed[i] + w * (closed[i + 1] - closed[i])  # scalars: the lerp on Python floats
        np.testing.assert_array_equal([fn(float(v)) for v in s[:400]], scalar[:400])
        np.testing.assert_array_equal([fn(np.float64(v)) for v in s[:50]], scalar[:50])
    for v in s[:400].tolist():
        x, y, psi = track.pose(v, 1.3)
        assert (x, y) == track.to_cartesian(v, 1.3) and psi == track.heading(v)
        assert track.gap(v, 17.5) == float(track.gap(np.array([v]), 17.5)[0])


def test_scalar_projection_agrees_with_the_vectorised_one(tracks):
    track = tracks["Monza"]
    rng = np.random.default_rng(4)
    s0 = rng.uniform(0.0, track.length, 300)
    x, y = track.to_cartesian(s0, rng.uniform(-8.0, 8.0, s0.size))
    hint = track.wrap(s0 + rng.uniform(-10.0, 10.0, s0.size))
    for h in (None, hint):
        s_vec, n_vec = track.to_frenet(x, y, h)
        for k in range(0, s0.size, 7):
            s_k, n_k = track.to_frenet(float(x[k]), float(y[k]), None if h is None else float(h[k]))
            assert abs(track.gap(s_k, float(s_vec[k]))) < 1e-9 and abs(n_k - n_vec[k]) < 1e-9
            assert abs(track.gap(s_k, float(s0[k]))) < 1e-6
