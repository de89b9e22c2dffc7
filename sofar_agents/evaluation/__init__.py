"""The paper's evaluation: episodes, resumable sweeps, aggregation and the tables and figures.

The logic behind ``eval/table.py`` (Tables I and II), ``eval/latency.py`` (Table III)
and ``eval/figures.py`` (Fig. 5); the scripts only parse arguments. One module per job:

* :mod:`~sofar_agents.evaluation.protocol`: strategies, episode tasks, paired seeds,
  the task lists of Tables I and II (what to run);
* :mod:`~sofar_agents.evaluation.episode`: one episode in one environment (``make_env``,
  ``run_episode``);
* :mod:`~sofar_agents.evaluation.sweep`: many episodes on the executor (:mod:`sofar_agents.executor`: this
  process, worker processes, or Ray actors locally or on a cluster with ``backend="ray"``), resumed from the CSV
  (``run_sweep``);
* :mod:`~sofar_agents.evaluation.results`: the episode record and the episode/trace CSV
  files (columns, reading, appending, resume keys);
* :mod:`~sofar_agents.evaluation.tables`: totals per group and the Markdown of Tables I/II;
* :mod:`~sofar_agents.evaluation.experiments`: Tables I and II end to end (``run_table1``,
  ``run_miqp_ablation``);
* :mod:`~sofar_agents.evaluation.configs`: the resolved configuration behind the rows: its hash per row,
  ``config.json`` per results folder, the check that one strategy label holds one configuration;
* :mod:`~sofar_agents.evaluation.manifest`: experiments as manifests (``experiments/NAME.toml``:
  ``run_manifest``, ``check_manifest``; ``eval/manifest.py``);
* :mod:`~sofar_agents.evaluation.pareto`: success against overtaking of fixed gammas and of a
  preference-conditioned policy, fronts and their hypervolumes (``run_pareto``; ``eval/pareto.py``; several
  seed sets of one front pooled: ``pooled_pareto``, ``eval/pareto.py --pool``);
* :mod:`~sofar_agents.evaluation.pareto_bootstrap`: how far a difference of two fronts' hypervolumes is from the
  noise of their episodes, by a paired bootstrap (``bootstrap_hypervolume``; ``eval/pareto.py --bootstrap``);
* :mod:`~sofar_agents.evaluation.pareto_seeds`: a training recipe's front over several training seeds on the same
  episodes, against the fixed gammas (``training_seed_fronts``; ``eval/pareto.py --training-seeds``);
* :mod:`~sofar_agents.evaluation.headroom`: what an adaptive gamma could gain over the best fixed one,
  by oracles over the fixed-gamma rows of Table I (``headroom``; ``eval/headroom.py``);
* :mod:`~sofar_agents.evaluation.interventions`: the within-race part of that question: each failure of a
  fixed gamma replayed with gamma switched just before it, against placebo switches (``run_interventions``,
  ``replay_interventions``: resumable from ``interventions.csv``; ``eval/interventions.py``);
* :mod:`~sofar_agents.evaluation.paired`: two strategies compared on the same seeded episodes, with an
  exact McNemar test (``paired_comparison``; ``eval/paired.py``);
* :mod:`~sofar_agents.evaluation.latency`: Table III (``measure_latency``);
* :mod:`~sofar_agents.evaluation.figures`: Fig. 5 (``plot_gamma_figures``);
* :mod:`~sofar_agents.evaluation.training_curves`: learning curves from TensorBoard logs
  (``read_scalars``, ``plot_training_curves``; ``eval/plot_training.py``).

Every public name is re-exported here: ``from sofar_agents import evaluation as ev``
then ``ev.run_table1(...)``.
"""

from sofar_agents.evaluation.configs import (check_one_config, episode_config, episode_config_hash, read_config_json,
                                             write_config_json)
from sofar_agents.evaluation.episode import make_env, run_episode, slack_active
from sofar_agents.evaluation.experiments import TableReport, run_miqp_ablation, run_table1
from sofar_agents.evaluation.figures import plot_gamma_figures
from sofar_agents.evaluation.headroom import (HeadroomRow, fixed_gamma_rows, format_flips, format_headroom, headroom,
                                              outcome_flips)
from sofar_agents.evaluation.interventions import (Intervention, InterventionResult,
                                                   default_interventions, failed_episodes, format_interventions,
                                                   replay_interventions, run_interventions, summarize_interventions)
from sofar_agents.evaluation.manifest import Manifest, check_manifest, load_manifest, run_manifest
from sofar_agents.evaluation.latency import (PAPER_LATENCY_MS, format_latency, latency_stats, machine_info,
                                             measure_latency, write_json)
from sofar_agents.evaluation.paired import PairedComparison, compare_to, format_paired, label_by_stack, paired_comparison
from sofar_agents.evaluation.pareto import (ParetoPoint, ParetoReport, hypervolume, pareto_front,
                                            pareto_strategies, pooled_pareto, preference_family, run_pareto,
                                            strategy_points)
from sofar_agents.evaluation.pareto_bootstrap import HypervolumeBootstrap, bootstrap_hypervolume, bootstrap_markdown
from sofar_agents.evaluation.pareto_seeds import TrainingSeedFronts, training_seed_fronts, training_seeds_markdown
from sofar_agents.evaluation.protocol import (DEFAULT_DURATION, FIXED_GAMMAS, FULL_TABLE1_STEPS, RHOS,
                                              TRACK_ABBREVIATIONS, TRACKS, EpisodeTask, Strategy,
                                              build_strategies, episode_seed, miqp_ablation_tasks,
                                              resolve_policy_path, table1_tasks)
from sofar_agents.evaluation.results import (EPISODE_COLUMNS, TRACE_COLUMNS, EpisodeResult, read_episode_csv,
                                             pool_seed_sets, read_seed_sets, read_trace_csv, select_rows,
                                             write_markdown)
from sofar_agents.evaluation.sweep import SweepStats, incomplete_message, run_sweep
from sofar_agents.evaluation.training_curves import find_event_dirs, plot_training_curves, read_scalars
from sofar_agents.evaluation.tables import (PAPER_TABLE1_SUCCESS, Summary, aggregate, format_table1,
                                            format_table2, paper_comparison, rank_marks, summarize)

__all__ = [
    "TRACKS",
    "TRACK_ABBREVIATIONS",
    "RHOS",
    "FIXED_GAMMAS",
    "DEFAULT_DURATION",
    "FULL_TABLE1_STEPS",
    "EPISODE_COLUMNS",
    "TRACE_COLUMNS",
    "PAPER_TABLE1_SUCCESS",
    "PAPER_LATENCY_MS",
    "Strategy",
    "ParetoPoint",
    "HeadroomRow",
    "headroom",
    "fixed_gamma_rows",
    "format_headroom",
    "outcome_flips",
    "format_flips",
    "Intervention",
    "InterventionResult",
    "default_interventions",
    "failed_episodes",
    "run_interventions",
    "replay_interventions",
    "summarize_interventions",
    "format_interventions",
    "PairedComparison",
    "paired_comparison",
    "compare_to",
    "format_paired",
    "label_by_stack",
    "ParetoReport",
    "hypervolume",
    "pareto_front",
    "pareto_strategies",
    "pooled_pareto",
    "HypervolumeBootstrap",
    "bootstrap_hypervolume",
    "bootstrap_markdown",
    "TrainingSeedFronts",
    "training_seed_fronts",
    "training_seeds_markdown",
    "preference_family",
    "run_pareto",
    "strategy_points",
    "EpisodeTask",
    "EpisodeResult",
    "Summary",
    "SweepStats",
    "episode_seed",
    "resolve_policy_path",
    "build_strategies",
    "table1_tasks",
    "miqp_ablation_tasks",
    "make_env",
    "run_episode",
    "slack_active",
    "run_sweep",
    "incomplete_message",
    "run_table1",
    "run_miqp_ablation",
    "TableReport",
    "read_episode_csv",
    "pool_seed_sets",
    "read_seed_sets",
    "write_markdown",
    "select_rows",
    "paper_comparison",
    "summarize",
    "aggregate",
    "rank_marks",
    "format_table1",
    "format_table2",
    "latency_stats",
    "measure_latency",
    "format_latency",
    "machine_info",
    "write_json",
    "read_trace_csv",
    "plot_gamma_figures",
    "find_event_dirs",
    "read_scalars",
    "plot_training_curves",
    "episode_config",
    "episode_config_hash",
    "write_config_json",
    "read_config_json",
    "check_one_config",
    "Manifest",
    "load_manifest",
    "run_manifest",
    "check_manifest",
]
