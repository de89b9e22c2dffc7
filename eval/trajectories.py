"""Record seeded trajectories and compare two recordings bit for bit.

The invariant of every refactor and speed change: seeded episodes give the same
observations, rewards and info values, to the bit. ``record`` runs a fixed set of
seeded episodes of every registered id (a gamma that changes at every step, the
vector reward) and of the PettingZoo race, and writes all arrays to one ``.npz``;
``compare`` reports the first difference of every array between two files::

    python eval/trajectories.py record --out /tmp/before.npz        # on the old code
    python eval/trajectories.py record --out /tmp/after.npz         # on the new code
    python eval/trajectories.py compare /tmp/before.npz /tmp/after.npz
    python eval/trajectories.py record --worlds paper interactive --out /tmp/both.npz   # also the interactive ids
    python eval/trajectories.py record --variant stack=sofar-1 --out /tmp/v.npz   # also every id with stack=sofar-1

Wall-clock timings are never recorded (``timing_info=False``).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time

import numpy as np

from sofar_agents.cli_types import positive_int
from sofar_env.registration import WORLD_IDS

logger = logging.getLogger("trajectories")

# info values compared (numeric); timings are excluded by construction
_INFO_KEYS = ("laps", "overtakes", "sim_time", "gamma", "collision", "off_track", "nearest_opponent_m",
              "min_barrier", "barrier_slack", "cost", "mpc_failures", "miqp_failures")


def gamma_schedule(step: int, episode: int) -> float:
    """A gamma that sweeps [0.05, 1] and differs per episode (deterministic)."""
    return float(0.05 + 0.95 * (0.5 + 0.5 * np.sin(0.13 * step + 1.7 * episode)))


def _info_row(info: dict) -> list[float]:
    return [float(np.asarray(info.get(k, np.nan), dtype=float).ravel()[0]) if np.size(info.get(k, np.nan)) else np.nan
            for k in _INFO_KEYS]


def record_single(env_id: str, episodes: int, steps: int, extra: dict) -> dict[str, np.ndarray]:
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)

    out: dict[str, np.ndarray] = {}
    env = gym.make(env_id, reward_mode="vector", timing_info=False, **extra)
    for ep in range(episodes):
        obs, info = env.reset(seed=1000 + ep)
        o, r, i = [obs], [], [_info_row(info)]
        for t in range(steps):
            obs, rew, term, trunc, info = env.step(np.array([gamma_schedule(t, ep)], np.float32))
            o.append(obs)
            r.append(rew)
            i.append(_info_row(info))
            if term or trunc:
                break
        key = f"{env_id}{''.join(f'|{k}={v}' for k, v in sorted(extra.items()))}|ep{ep}"
        out[key + "|obs"] = np.asarray(o)
        out[key + "|reward"] = np.asarray(r)
        out[key + "|info"] = np.asarray(i)
    env.close()
    return out


def record_multi(episodes: int, steps: int, extra: dict | None = None) -> dict[str, np.ndarray]:
    from sofar_env.multi_agent import parallel_env

    out: dict[str, np.ndarray] = {}
    extra = extra or {}
    env = parallel_env("LagunaSeca", n_agents=3, reward_mode="vector", timing_info=False,
                       speed_factors=[0.6, 0.75, 0.9], **extra)
    for ep in range(episodes):
        obs, infos = env.reset(seed=2000 + ep)
        rows = []
        for t in range(steps):
            if not env.agents:
                break
            actions = {a: np.array([gamma_schedule(t, ep + k)], np.float32) for k, a in enumerate(env.agents)}
            obs, rew, term, trunc, infos = env.step(actions)
            for a in sorted(obs):
                rows.append(np.concatenate([[t, int(a.split("_")[1])], obs[a], np.atleast_1d(rew[a]),
                                            _info_row(infos[a]), [term[a], trunc[a]]]))
        out[f"multi{''.join(f'|{k}={v}' for k, v in sorted(extra.items()))}|ep{ep}"] = np.asarray(rows, float)
    env.close()
    return out


def record(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    data: dict[str, np.ndarray] = {}
    variants = [{}] + [dict(v.split("=", 1) for v in args.variant)] if args.variant else [{}]
    ids = tuple(env_id for world, world_ids in WORLD_IDS.items() if world in args.worlds for env_id in world_ids)
    for env_id in ids:
        for extra in variants:
            data.update(record_single(env_id, args.episodes, args.steps, extra))
    for extra in variants:
        data.update(record_multi(args.episodes, min(args.steps, 200), extra))
    np.savez_compressed(args.out, **data)
    logger.info("wrote %d arrays to %s in %.1f s", len(data), args.out, time.perf_counter() - t0)
    return 0


def compare(args: argparse.Namespace) -> int:
    a, b = np.load(args.a), np.load(args.b)
    keys_a, keys_b = set(a.files), set(b.files)
    missing = sorted(keys_a ^ keys_b)
    for key in missing:
        logger.error("only in %s: %s", args.a if key in keys_a else args.b, key)
    bad = 0
    for key in sorted(keys_a & keys_b):
        x, y = a[key], b[key]
        if x.shape != y.shape:
            logger.error("%s: shape %s vs %s", key, x.shape, y.shape)
            bad += 1
        elif not np.array_equal(x, y, equal_nan=True):
            row = int(np.argwhere(~((x == y) | (np.isnan(x) & np.isnan(y))))[0][0])
            logger.error("%s: first difference at row %d (max |diff| %.3g)", key, row,
                         float(np.nanmax(np.abs(x - y))))
            bad += 1
    n = len(keys_a & keys_b)
    logger.info("%d of %d common arrays identical to the bit; %d arrays in only one file", n - bad, n, len(missing))
    print(f"{'IDENTICAL' if bad == 0 and not missing else 'DIFFERENT'}: {n} arrays compared, {bad} differ, "
          f"{len(missing)} in only one file")
    return 0 if bad == 0 and not missing else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="record seeded episodes of every registered id")
    rec.add_argument("--out", required=True, help="output .npz file")
    rec.add_argument("--episodes", type=positive_int, default=3, help="episodes per id (default 3)")
    rec.add_argument("--steps", type=positive_int, default=300, help="control steps per episode (default 300)")
    rec.add_argument("--worlds", nargs="+", default=["paper"],
                     choices=tuple(WORLD_IDS),
                     help="record the ids of these worlds (default: paper; interactive-2 and dynamic-2: the v1 ids; the "
                          "PettingZoo race is always recorded)")
    rec.add_argument("--variant", nargs="*", default=[], metavar="KEY=VALUE",
                     help="also record every id, and the PettingZoo race, with these keyword arguments (strings; "
                          "e.g. stack=sofar-1 to compare a controller across a change of the default)")
    cmp_ = sub.add_parser("compare", help="compare two recordings bit for bit")
    cmp_.add_argument("a")
    cmp_.add_argument("b")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    return record(args) if args.command == "record" else compare(args)


if __name__ == "__main__":
    sys.exit(main())
