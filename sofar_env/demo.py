"""A race with the overtaking stack at a fixed gamma: an animation and a safety summary.

Usage::

    python -m sofar_env.demo [--track LagunaSeca] [--seconds 60] [--gamma 0.5] [--rho 0.3]
                             [--opponents 4] [--seed 0] [--out sofar_demo.gif] [--no-video] [--no-progress]

Defaults: a 60 s race on Laguna Seca against 4 opponents at pace ratio 0.3, gamma 0.5,
written to ``sofar_demo.gif`` in the current directory (an ``.mp4`` path is written
with imageio's ffmpeg plugin when the ``imageio-ffmpeg`` package is installed, else the
demo falls back to a GIF next to it). The summary reports overtakes, the closest
approach (distance between the cars' reference points and the gap between their
footprints), the smallest barrier value, how often the MPC used barrier slack,
collisions, off-tracks, laps, the median MPC / MIQP solve times and the solver failures.
A progress bar (stderr) follows the race and the writing of the animation; the per-step kernels are
compiled (first run after installing) or loaded before it starts (:mod:`sofar_env.compile`), so that its
estimate of the remaining time and the summary's wall time leave the compilation out.
"""

from __future__ import annotations

import argparse
import importlib.util
import logging
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from .env import SOfARRaceEnv
from .geometry import footprint_corners, rectangles_intersect

__all__ = ["DemoSummary", "footprint_gap", "run_demo", "main"]

_SLACK_ACTIVE = 1e-3

logger = logging.getLogger(__name__)


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (P, S) from points p (P, 2) to segments a-b (S, 2)."""
    ab = b - a
    ap = p[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("psd,sd->ps", ap, ab) / np.einsum("sd,sd->s", ab, ab), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=-1)


def footprint_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest distance [m] between two rectangles given by their corners (4, 2); 0 when they intersect."""
    if bool(rectangles_intersect(a, b)):
        return 0.0
    ea, eb = np.roll(a, -1, axis=0), np.roll(b, -1, axis=0)
    return float(min(_point_segment_distance(a, b, eb).min(), _point_segment_distance(b, a, ea).min()))


@dataclass
class DemoSummary:
    """What happened in one demo race."""

    track: str
    sim_time_s: float
    steps: int
    overtakes: int
    closest_centre_m: float
    closest_footprint_gap_m: float
    min_barrier: float
    slack_active_pct: float
    collisions: int
    off_tracks: int
    laps: float
    mpc_median_ms: float
    miqp_median_ms: float
    mpc_failures: int
    miqp_failures: int
    wall_time_s: float
    video: str | None

    def format(self) -> str:
        lines = [
            f"SOfAR demo on {self.track}: {self.sim_time_s:.1f} s simulated ({self.steps} steps, "
            f"{self.wall_time_s:.1f} s wall)",
            f"  overtakes            {self.overtakes}",
            f"  closest approach     {self.closest_centre_m:.2f} m between centres, "
            f"{self.closest_footprint_gap_m:.2f} m between footprints",
            f"  smallest barrier h   {self.min_barrier:.3f}",
            f"  barrier slack > 1e-3 {self.slack_active_pct:.1f} % of steps",
            f"  collisions           {self.collisions}",
            f"  off-tracks           {self.off_tracks}",
            f"  laps                 {self.laps:.3f}",
            f"  MPC  median          {self.mpc_median_ms:.2f} ms ({self.mpc_failures} failures)",
            f"  MIQP median          {self.miqp_median_ms:.2f} ms ({self.miqp_failures} failures)",
        ]
        if self.video:
            lines.append(f"  animation            {self.video}")
        return "\n".join(lines)


def _closest(race) -> tuple[float, float]:
    """(centre distance, footprint gap) of the ego to the nearest obstacle now [m]."""
    x, y, psi = race.obstacle_poses(0)
    if x.size == 0:
        return math.inf, math.inf
    d = np.hypot(x - race.states[0, 0], y - race.states[0, 1])
    p = race.config.vehicle
    ego = footprint_corners(race.states[0, 0], race.states[0, 1], race.states[0, 2], p)
    near = np.flatnonzero(d <= max(30.0, float(d.min())))  # the footprint gap is at most the centre distance
    gap = min(footprint_gap(ego, footprint_corners(x[i], y[i], psi[i], p)) for i in near)
    return float(d.min()), gap


def _resolve_output(path: str) -> str:
    if path.lower().endswith(".gif") or importlib.util.find_spec("imageio_ffmpeg") is not None:
        return path
    fallback = os.path.splitext(path)[0] + ".gif"
    logger.warning("imageio-ffmpeg is not installed: writing %s instead of %s", fallback, path)
    return fallback


def run_demo(track: str = "LagunaSeca", seconds: float = 60.0, gamma: float = 0.5, rho: float = 0.3,
             n_opponents: int = 4, seed: int = 0, out: str | None = "sofar_demo.gif",
             progress: bool = False) -> DemoSummary:
    """Run one race at a fixed gamma; write the animation to ``out`` (None: no video).

    ``progress`` shows a progress bar (tqdm, on stderr) over the control steps and the frames written.
    """
    from tqdm import tqdm

    from .compile import warm_up

    warm_up(["paper"], track=track, multi_agent=False)  # compile before the progress bar and the wall clock
    env = SOfARRaceEnv(track=track, rho=rho, n_opponents=n_opponents, race={"duration": float(seconds)},
                       timing_info=True, render_mode="rgb_array" if out else None)
    bar = tqdm(total=env.config.control_steps, desc="racing and rendering" if out else "racing", unit="step",
               disable=not progress, leave=False)
    frames = []
    t0 = time.perf_counter()
    _, info = env.reset(seed=seed)
    race = env.race
    closest_c, closest_g = _closest(race)
    min_h = info["min_barrier"]
    mpc_ms, miqp_ms, slack_steps = [], [], 0
    collisions = off_tracks = steps = 0
    if out:
        frames.append(env.render())
    action = np.array([gamma], np.float32)
    while True:
        _, _, terminated, truncated, info = env.step(action)
        steps += 1
        c, g = _closest(race)
        closest_c, closest_g = min(closest_c, c), min(closest_g, g)
        min_h = min(min_h, info["min_barrier"])
        mpc_ms.append(info["mpc_time_ms"])
        if info["miqp_time_ms"] > 0.0:
            miqp_ms.append(info["miqp_time_ms"])
        slack_steps += info["barrier_slack"] > _SLACK_ACTIVE
        collisions += info["collision"]
        off_tracks += info["off_track"]
        if out:
            frames.append(env.render())
        bar.update()
        if terminated or truncated:
            break
    bar.close()
    wall = time.perf_counter() - t0
    video = None
    if out:
        from .render import write_animation

        video = write_animation(frames, _resolve_output(out), fps=env.metadata["render_fps"], progress=progress)
    env.close()
    return DemoSummary(
        track=race.track.name, sim_time_s=race.time, steps=steps, overtakes=info["overtakes"],
        closest_centre_m=closest_c, closest_footprint_gap_m=closest_g, min_barrier=min_h,
        slack_active_pct=100.0 * slack_steps / max(steps, 1), collisions=int(collisions),
        off_tracks=int(off_tracks), laps=info["laps"],
        mpc_median_ms=float(np.median(mpc_ms)) if mpc_ms else math.nan,
        miqp_median_ms=float(np.median(miqp_ms)) if miqp_ms else math.nan,
        mpc_failures=info["mpc_failures"], miqp_failures=info["miqp_failures"], wall_time_s=wall, video=video,
    )


def main(argv: list[str] | None = None) -> DemoSummary:
    parser = argparse.ArgumentParser(prog="python -m sofar_env.demo", description=__doc__.splitlines()[0])
    parser.add_argument("--track", default="LagunaSeca", help="circuit name (default LagunaSeca)")
    parser.add_argument("--seconds", type=float, default=60.0, help="race duration [s] (default 60)")
    parser.add_argument("--gamma", type=float, default=0.5, help="fixed barrier decay in [0.05, 1] (default 0.5)")
    parser.add_argument("--rho", type=float, default=0.3, help="opponent pace ratio (default 0.3)")
    parser.add_argument("--opponents", type=int, default=4, help="number of opponents (default 4)")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the start (default 0)")
    parser.add_argument("--out", default="sofar_demo.gif", help="animation file, .gif or .mp4 (default sofar_demo.gif)")
    parser.add_argument("--no-video", action="store_true", help="skip rendering and the animation")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    summary = run_demo(track=args.track, seconds=args.seconds, gamma=args.gamma, rho=args.rho,
                       n_opponents=args.opponents, seed=args.seed, out=None if args.no_video else args.out,
                       progress=not args.no_progress)
    print(summary.format())
    return summary


if __name__ == "__main__":
    main()
