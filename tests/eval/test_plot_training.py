"""eval/plot_training.py: learning curves from the TensorBoard files of a tiny real run and of written logs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from sofar_agents.evaluation.training_curves import find_event_dirs, plot_training_curves, read_scalars, smooth
from sofar_env.config import OBJECTIVE_NAMES

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "eval" / "plot_training.py"


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def pasta_run(tmp_path_factory) -> Path:
    """A two-update PASTA run on 5 s episodes (a few finished episodes), as train/pasta.py writes it."""
    out = tmp_path_factory.mktemp("pasta") / "run"
    proc = _run("train/pasta.py", "--total-steps", "256", "--n-steps", "128", "--batch-size", "64", "--n-epochs", "1",
                "--env-kwargs", json.dumps({"race": {"duration": 5.0}}), "--seed", "2", "--out", str(out),
                "--no-progress")
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def _write_log(folder: Path, tags: dict[str, list[tuple[int, float]]]) -> None:
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(str(folder))
    for tag, points in tags.items():
        for step, value in points:
            writer.add_scalar(tag, value, step)
    writer.close()


def test_reads_the_tags_of_a_real_run(pasta_run):
    (tb,) = find_event_dirs(pasta_run)  # the run folder: the event files are in its tb/ folder
    assert tb == pasta_run / "tb"
    curves = read_scalars(tb)
    for name in OBJECTIVE_NAMES:
        assert f"episode_return/{name}" in curves and f"attention/{name}" in curves
    mu = curves["pasta/mu"]
    assert mu.steps.tolist() == [128, 256] and np.all(np.isfinite(mu.values))
    attention = np.array([curves[f"attention/{n}"].values for n in OBJECTIVE_NAMES])
    np.testing.assert_allclose(attention.sum(axis=0), 1.0, atol=1e-5)  # the weights of each update sum to one


def test_script_writes_a_png_of_the_real_run(pasta_run):
    proc = _run(str(SCRIPT), str(pasta_run))
    assert proc.returncode == 0, proc.stderr
    png = pasta_run / "training_curves.png"
    assert f"Wrote {png}" in proc.stdout and "up to 256 environment steps" in proc.stdout
    with Image.open(png) as img:
        assert img.format == "PNG" and img.width > 800 and img.height > 800  # a grid of panels
        assert len(img.convert("RGB").getcolors(1 << 20)) > 20  # drawn, not blank


def test_two_runs_and_the_group_selection(tmp_path, pasta_run):
    _write_log(tmp_path / "other" / "tb", {"pasta/mu": [(128, 9.0), (256, 8.0)]})
    out = tmp_path / "both.png"
    proc = _run(str(SCRIPT), str(pasta_run), str(tmp_path / "other"), "--labels", "a", "b", "--groups", "pasta",
                "--out", str(out), "--smoothing", "0.5")
    assert proc.returncode == 0, proc.stderr
    assert out.stat().st_size > 0 and "(2 runs" in proc.stdout


def test_a_step_logged_twice_keeps_its_last_value(tmp_path):
    _write_log(tmp_path, {"losses/value_loss": [(1, 5.0), (2, 4.0)]})
    _write_log(tmp_path, {"losses/value_loss": [(2, 3.0), (3, 2.0)]})  # resumed into the same folder
    curve = read_scalars(tmp_path)["losses/value_loss"]
    assert curve.steps.tolist() == [1, 2, 3] and curve.values.tolist() == [5.0, 3.0, 2.0]


def test_smoothing_is_tensorboards_debiased_ema():
    np.testing.assert_allclose(smooth(np.array([1.0, 2.0, 3.0]), 0.5), [1.0, 5.0 / 3.0, 17.0 / 7.0])
    np.testing.assert_array_equal(smooth(np.array([1.0, 4.0]), 0.0), [1.0, 4.0])
    with pytest.raises(ValueError, match="smoothing weight"):
        smooth(np.array([1.0]), 1.0)


def test_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no TensorBoard event files"):
        find_event_dirs(tmp_path)
    with pytest.raises(FileNotFoundError, match="no such run folder"):
        find_event_dirs(tmp_path / "missing")
    _write_log(tmp_path / "tb", {"rollout/ep_rew_mean": [(1, 0.5)]})
    with pytest.raises(ValueError, match="the run has: rollout"):
        plot_training_curves({"r": read_scalars(tmp_path / "tb")}, tmp_path / "x.png", groups=["pasta"])
    assert not (tmp_path / "x.png").exists()
    proc = _run(str(SCRIPT), str(tmp_path / "missing"))
    assert proc.returncode == 2 and "no such run folder" in proc.stderr
