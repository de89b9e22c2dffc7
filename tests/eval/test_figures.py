"""sofar_agents.evaluation.figures: Fig. 5 PNGs from a per-step trace."""

from __future__ import annotations

import numpy as np

from sofar_agents import evaluation as ev


def test_gamma_figures_written(tmp_path):
    rng = np.random.default_rng(0)
    d = np.concatenate([rng.uniform(0.0, 150.0, 500), [np.inf, np.nan]])  # beyond range / no opponent: left out
    trace = {"gamma": np.clip(0.2 + d / 200.0, 0.05, 1.0), "nearest_opponent_m": d}
    paths = ev.plot_gamma_figures(trace, tmp_path / "fig", max_distance=100.0, title="test")
    assert [p.name for p in paths] == ["gamma_hist.png", "distance_vs_gamma.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # too few points for the binned mean: still both figures
    few = {"gamma": np.array([0.5, 0.6]), "nearest_opponent_m": np.array([10.0, 20.0])}
    assert all(p.exists() for p in ev.plot_gamma_figures(few, tmp_path / "few"))


def test_figures_script_refuses_a_folder_of_another_policy(tmp_path, capsys):
    """The trace rows carry no policy id: recording a second policy into the same folder would mix
    their steps in one plot, so the script refuses and names the way out."""
    import importlib.util
    import shutil
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location("eval_figures", root / "eval" / "figures.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = tmp_path / "fig"
    out.mkdir()
    shutil.copy(root / "results" / "paper_stack" / "figures" / "episodes.csv", out / "episodes.csv")
    # the folder holds the paper-stack policy's episodes; ask for the default stack's policy
    assert script.main(["--out", str(out), "--stack", "sofar", "--episodes", "1", "--rhos", "0.3"]) == 2
    err = capsys.readouterr().err
    assert "holds the episodes of another policy" in err and "use another folder" in err
    assert not (out / "trace.csv").exists()  # refused before anything ran


def test_figures_script_records_the_interactive_policy_in_its_world(tmp_path):
    """--scenario interactive: the shipped interactive policy drives episodes of the interactive world (its
    16-value observation), with the field size of --opponents, and both figures are drawn."""
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location("eval_figures", root / "eval" / "figures.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = tmp_path / "fig"
    assert script.main(["--out", str(out), "--scenario", "interactive", "--opponents", "2", "--episodes", "1",
                        "--duration", "2", "--workers", "1"]) == 0
    rows = ev.read_episode_csv(out / "episodes.csv")
    assert [(r["scenario"], int(r["n_opponents"]), r["strategy"]) for r in rows] == [("interactive", 2, "adaptive")]
    assert (out / "gamma_hist.png").exists() and (out / "distance_vs_gamma.png").exists()
    with __import__("pytest").raises(SystemExit) as exc:  # a usage error of the argument type
        script.main(["--out", str(tmp_path / "x"), "--opponents", "-1"])
    assert exc.value.code == 2
