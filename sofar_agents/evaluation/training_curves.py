"""Learning curves of a training run from its TensorBoard event files, drawn to one PNG.

The scalars are read with TensorBoard's own reader (``EventAccumulator``); the tags are
taken from the files, grouped by their prefix (the part before ``/``), so the same code
plots a PASTA run of ``train/pasta.py`` (``episode_return/<objective>``, ``attention/<objective>``,
``pasta/mu``, ``losses/...``, ``charts/...``) and a Stable-Baselines3 run of ``train/ppo.py``
(``rollout/...``, ``train/...``). Each tag gets its own panel (the objectives' returns have very
different scales), except the groups of :data:`SHARED_AXES` (the attention weights, which sum to
one), drawn together. Several runs are drawn into the same panels, one colour each.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["DEFAULT_GROUPS", "SHARED_AXES", "Curve", "find_event_dirs", "read_scalars", "smooth",
           "plot_training_curves"]

DEFAULT_GROUPS: tuple[str, ...] = ("episode_return", "attention", "pasta", "losses", "charts", "actions",
                                   "rollout", "train")
"""Tag groups drawn by default, in this order (groups absent from a run are skipped)."""
SHARED_AXES: frozenset[str] = frozenset({"attention"})
"""Groups whose tags share one panel."""
SKIPPED_TAGS: frozenset[str] = frozenset({"charts/sps", "charts/epochs", "time/fps"})
"""Throughput and bookkeeping tags left out of the default figure."""


@dataclass(frozen=True)
class Curve:
    """One scalar tag of one run."""

    steps: np.ndarray
    """Environment steps of the points (the step TensorBoard logged them at)."""
    values: np.ndarray
    """The logged values."""


def find_event_dirs(path: str | os.PathLike) -> list[Path]:
    """The folders holding TensorBoard event files at or below ``path`` (a run folder, its ``tb/``, or an event file).

    Raises ``FileNotFoundError`` naming ``path`` when there is none.
    """
    root = Path(path).expanduser()
    if root.is_file() and ".tfevents." in root.name:
        return [root.parent]
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such run folder or event file")
    found = sorted({p.parent for p in root.rglob("*.tfevents.*") if p.is_file()})
    if not found:
        raise FileNotFoundError(f"{root}: no TensorBoard event files (events.out.tfevents.*) in it or below it")
    return found


def read_scalars(event_dir: str | os.PathLike) -> dict[str, Curve]:
    """Every scalar tag of the event files in ``event_dir``: tag -> :class:`Curve` (all points kept).

    A step logged twice (a run resumed from an earlier checkpoint into the same folder) keeps its last value.
    """
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(os.fspath(event_dir), size_guidance={"scalars": 0})
    acc.Reload()
    curves = {}
    for tag in acc.Tags().get("scalars", []):
        last = {int(e.step): float(e.value) for e in acc.Scalars(tag)}
        steps = np.array(sorted(last), dtype=np.int64)
        curves[tag] = Curve(steps, np.array([last[s] for s in steps.tolist()], dtype=float))
    return curves


def smooth(values: np.ndarray, weight: float) -> np.ndarray:
    """TensorBoard's exponential moving average with debiasing; ``weight`` in [0, 1), 0 returns the values."""
    if not 0.0 <= weight < 1.0:
        raise ValueError(f"smoothing weight must lie in [0, 1), got {weight!r}")
    values = np.asarray(values, float)
    if weight == 0.0 or values.size == 0:
        return values.copy()
    out = np.empty_like(values)
    acc = 0.0
    for k, v in enumerate(values):
        acc = weight * acc + (1.0 - weight) * v
        out[k] = acc / (1.0 - weight ** (k + 1))
    return out


def _panels(runs: Mapping[str, Mapping[str, Curve]], groups: Sequence[str]) -> list[tuple[str, list[str]]]:
    """(title, tags) per panel, in the order of ``groups`` and of the tags in the first run that has them."""
    tags: list[str] = []
    for curves in runs.values():
        tags.extend(t for t in curves if t not in tags)
    panels = []
    for group in groups:
        members = [t for t in tags if t.split("/", 1)[0] == group and t not in SKIPPED_TAGS]
        if not members:
            continue
        if group in SHARED_AXES:
            panels.append((group, members))
        else:
            panels.extend((t, [t]) for t in members)
    return panels


def plot_training_curves(runs: Mapping[str, Mapping[str, Curve]], out: str | os.PathLike, *,
                         groups: Sequence[str] = DEFAULT_GROUPS, smoothing: float = 0.0, columns: int = 4,
                         title: str = "") -> Path:
    """Draw ``runs`` (label -> tag -> :class:`Curve`, from :func:`read_scalars`) to the PNG ``out``.

    One panel per tag of ``groups`` (the groups of :data:`SHARED_AXES` share one), ``columns`` panels per row,
    environment steps on the x axes. Raises ``ValueError`` when no tag of ``groups`` was logged.
    """
    panels = _panels(runs, groups)
    if not panels:
        logged = sorted({t.split("/", 1)[0] for curves in runs.values() for t in curves})
        raise ValueError(f"none of the groups {', '.join(groups)} was logged; "
                         f"the run has: {', '.join(logged) or 'nothing'}")
    smooth(np.zeros(1), smoothing)  # validate before drawing anything
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    cols = max(1, min(int(columns), len(panels)))
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.4 * rows), dpi=110, squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, (name, tags) in zip(axes.flat, panels):
        for r, (label, curves) in enumerate(runs.items()):
            for k, tag in enumerate(tags):
                if tag not in curves:
                    continue
                c = curves[tag]
                shared = len(tags) > 1
                colour = colours[(k if shared else r) % len(colours)]
                line_label = tag.split("/", 1)[1] if shared else label
                if shared and len(runs) > 1:
                    line_label = f"{label}: {line_label}"
                ax.plot(c.steps, smooth(c.values, smoothing), color=colour, lw=1.2, marker="." if c.steps.size < 20
                        else None, label=line_label, linestyle=("-", "--", ":", "-.")[r % 4] if shared else "-")
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.xaxis.get_offset_text().set_fontsize(7)
        ax.grid(alpha=0.3)
        if len(tags) > 1 or len(runs) > 1:
            ax.legend(fontsize=6, loc="best")
    for k, ax in enumerate(axes.flat):
        if k >= len(panels):
            ax.set_axis_off()
        elif k + cols >= len(panels):  # no panel below it
            ax.set_xlabel("environment steps", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
