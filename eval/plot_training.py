"""Learning curves of training runs (TensorBoard logs) as one PNG.

    python eval/plot_training.py runs/pasta                       # -> runs/pasta/training_curves.png
    python eval/plot_training.py runs/pasta runs/pasta_seed2 --labels seed1 seed2 --smoothing 0.6
    python eval/plot_training.py runs/ppo --out ppo.png           # a Stable-Baselines3 run of train/ppo.py

A run is a folder holding TensorBoard event files (found in it or below it, e.g. the
``tb/`` folder train/pasta.py writes) or an event file. The tags are read from the files
and drawn one panel each: per-objective episode returns, the attention weights (one
panel), mu and the conflict ratio, the losses, the episode statistics (success rate,
overtakes, laps, ...) and the mean gamma; for an SB3 run its rollout/ and train/ tags.
The logic lives in sofar_agents.evaluation.training_curves.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sofar_agents.cli import plain_text
from sofar_agents.cli_types import float_in, positive_int
from sofar_agents.evaluation.training_curves import DEFAULT_GROUPS, find_event_dirs, plot_training_curves, read_scalars


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=plain_text(__doc__.split("\n\n", 2)[2]),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", help="run folders (or event files); each is one colour in every panel")
    p.add_argument("--out", default=None, help="PNG to write (default: training_curves.png in the first run folder)")
    p.add_argument("--labels", nargs="+", default=None, help="legend label per run (default: the folder names)")
    p.add_argument("--groups", nargs="+", default=list(DEFAULT_GROUPS),
                   help="tag groups (the prefix before '/') to draw, in this order; absent groups are skipped "
                        f"(default: {' '.join(DEFAULT_GROUPS)}; also regret, return_scale, explained_variance)")
    p.add_argument("--smoothing", type=float_in(0.0, 1.0, high_open=True), default=0.0,
                   help="TensorBoard's exponential smoothing weight in [0, 1) (default: 0, the raw values)")
    p.add_argument("--columns", type=positive_int, default=4, help="panels per row (default: 4)")
    p.add_argument("--title", default="", help="figure title (default: none)")
    return p.parse_args(argv)


def _run_label(path: str) -> str:
    folder = Path(path).expanduser()
    folder = folder.parent if folder.is_file() else folder
    return folder.name if folder.name != "tb" else folder.parent.name


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.labels is not None and len(args.labels) != len(args.runs):
        print(f"error: {len(args.labels)} --labels for {len(args.runs)} runs", file=sys.stderr)
        return 2
    labels = args.labels or [_run_label(r) for r in args.runs]
    runs = {}
    try:
        for label, path in zip(labels, args.runs):
            dirs = find_event_dirs(path)
            for d in dirs:  # a folder with several runs below it: one label per event folder
                name = label if len(dirs) == 1 else f"{label}/{d.relative_to(Path(path).expanduser())}"
                runs[name] = read_scalars(d)
        first = Path(args.runs[0]).expanduser()
        out = Path(args.out) if args.out else (first.parent if first.is_file() else first) / "training_curves.png"
        written = plot_training_curves(runs, out, groups=args.groups, smoothing=args.smoothing,
                                       columns=args.columns, title=args.title)
    except (FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    steps = max((int(c.steps.max()) for curves in runs.values() for c in curves.values() if c.steps.size), default=0)
    print(f"Wrote {written} ({len(runs)} run{'' if len(runs) == 1 else 's'}, up to {steps} environment steps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
