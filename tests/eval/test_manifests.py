"""experiments/*.toml: every manifest resolves; committed rows carry their manifest's hash; back-filled
tables are re-made bit for bit; run writes NAME.manifest.json; back-filling changes nothing but the column."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from sofar_agents.evaluation import manifest as mf
from sofar_agents.evaluation.configs import episode_config_hash, read_config_json

from .episode_csv import FIRST_FORMAT

ROOT = Path(__file__).resolve().parents[2]
MANIFESTS = mf.manifest_paths(ROOT / "experiments")
BACKFILLED = ("table1_sofar_1", "paper_stack_table1", "paper_stack_seed21", "paper_stack_seed42", "table2_sofar_1",
              "interactive_table1_sofar_1", "interactive_dense_table2_sofar_1", "interactive_dense_seed21",
              "interactive_dense_seed42", "dynamic_table1_sofar_1", "dynamic_seed21", "multi_agent_sofar_1",
              "multi_agent_seed21", "interactive_dense_pareto",
              "interactive_dense_pareto_seed42", "interactive_dense_budget_pareto",
              "interactive_dense_budget_pareto_seed42", "reference_numerics_interventions",
              "end_rows_interventions_recover_gamma05", "end_rows_interventions_recover", "end_rows_interventions_ends",
              "end_rows_sofar", "end_rows_sofar_ends", "end_rows_sofar_recover", "end_rows_sofar_seed21",
              "end_rows_sofar_recover_seed21", "paper_stack_table2", "paper_stack_perturbation", "dynamic_perturbation",
              "dynamic_pasta_low_seed0", "dynamic_pasta_low_seed21")
"""Committed tables written before the hash column whose rows were shown to be re-made by the current code
(``python eval/manifest.py verify NAME --rows 2 --backfill``) and so carry their manifest's hash."""
UNHASHED: dict[str, str] = {}
"""Committed tables that keep rows without a hash, and why (``experiments/README.md``): every other table with a
manifest carries its manifest's hash."""
HASHED_BY_REPLAY: dict[str, str] = {"paper_stack_avx2": "results/training_envs/then_bf41b6a_paper_stack.npz"}
"""Tables recorded on another CPU, whose rows re-make there only (the platform drift they measure), so that a re-make
here cannot show their configuration: their hash was given after seeded steps of their controller and world,
recorded on this CPU under the commit that made the rows (the file named), were identical to the bit to the current
code's under the manifest's controller (``eval/training_env.py``; ``experiments/README.md`` says so)."""
EXTRA_STRATEGIES: dict[str, set[str]] = {
    name: {"PPO (SB3)"} for name in ("interactive_dense_morl_pareto", "interactive_dense_morl_pareto_seed10300",
                                     "dynamic_morl_pareto_seed10300", "dynamic_morl_pareto_seed10500",
                                     "interactive_dense_morl_pareto_seed10500",
                                     "interactive_dense_morl_pareto_seed10300_sofar_6",
                                     "interactive_dense_morl_pareto_seed10500_sofar_6",
                                     "dynamic_morl_pareto_seed10300_sofar_6", "dynamic_morl_pareto_seed10500_sofar_6",
                                     "interactive_dense_morl_pareto_seed10300_sofar_13",
                                     "interactive_dense_morl_pareto_seed10500_sofar_13",
                                     "dynamic_morl_pareto_seed10300_sofar_13", "dynamic_morl_pareto_seed10500_sofar_13",
                                     "dynamic_morl_pareto_seed22500_sofar_17_sigmoid",
                                     "interactive_dense_morl_pareto_seed22500_sofar_17_sigmoid_seed91",
                                     "interactive_dense_morl_pareto_seed22500_world2_sofar_17",
                                     "interactive_dense_morl_pareto_seed25100_world2_sofar_17",
                                     "dynamic_morl_pareto_seed22500_world2_sofar_17",
                                     "dynamic_morl_pareto_seed25100_world2_sofar_17",
                                     "dynamic_morl_pareto_seed26900_world2_sofar_17_reference")
}
"""Rows of a pareto file that are not its manifest's episodes (same configuration hash; the SB3 zip that made them is
not committed), documented in the manifest."""


def _cli():
    spec = importlib.util.spec_from_file_location("manifest_cli", ROOT / "eval" / "manifest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_main_tables_have_manifests() -> None:
    names = {p.stem for p in MANIFESTS}
    assert {"table1", "paper_stack_table1", "reference_numerics_table1", "reference_numerics_sweep",
            "reference_numerics_sweep_no_phantoms", *BACKFILLED, *UNHASHED} <= names


@pytest.mark.parametrize("path", MANIFESTS, ids=lambda p: p.stem)
def test_every_manifest_resolves_and_committed_hashes_match(path: Path) -> None:
    m = mf.load_manifest(path)
    assert m.config_hash == episode_config_hash(m.stack, m.scenario, m.duration) or m.kind == "multi-agent"
    assert m.strategies(ROOT)  # its policy (if any) is there
    check = mf.check_manifest(m, ROOT)
    assert check.status != "mismatch", check.line()
    if check.status == "ok":
        assert set(check.hashes) == {m.config_hash}
        configs = read_config_json(ROOT / m.out)
        assert m.config_hash in configs, f"{m.out}/config.json lacks {m.config_hash}"
    if m.name in BACKFILLED:
        assert check.status == "ok", check.line()


@pytest.mark.parametrize("name", HASHED_BY_REPLAY)
def test_a_table_hashed_by_replay_still_replays_under_its_manifest_s_controller(name: str) -> None:
    m = mf.load_manifest(ROOT / "experiments" / f"{name}.toml")
    then = np.load(ROOT / HASHED_BY_REPLAY[name])
    meta = json.loads(str(then["meta"]))
    assert meta["env_kwargs"].get("stack") == m.stack and meta["env_kwargs"].get("scenario", "paper") == m.scenario
    spec = importlib.util.spec_from_file_location("training_env_manifests", ROOT / "eval" / "training_env.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    steps = 25
    now = script.record_single(meta["env_id"], meta["env_kwargs"], 1, steps)
    for key, n in (("ep0|obs", steps + 1), ("ep0|reward", steps), ("ep0|done", steps)):
        assert np.array_equal(then[key][:n], now[key]), key
    assert f"`{name}`" in (ROOT / "experiments" / "README.md").read_text(encoding="utf-8")


def test_the_reference_numerics_manifests_are_its_script_s_settings() -> None:
    spec = importlib.util.spec_from_file_location("refnum_cli", ROOT / "eval" / "reference_numerics.py")
    refnum = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(refnum)
    sweep = mf.load_manifest(ROOT / "experiments" / "reference_numerics_sweep.toml")
    control = mf.load_manifest(ROOT / "experiments" / "reference_numerics_sweep_no_phantoms.toml")
    args = refnum.parse_args(["sweep"])
    for m, stack, gammas in ((sweep, refnum.STACK, refnum.SWEEP_GAMMAS),
                             (control, refnum.CONTROL, refnum.CONTROL_GAMMAS)):
        assert (m.stack, m.gammas, m.seed, m.episodes, m.duration, m.adaptive) == (
            stack, tuple(gammas), args.seed, args.episodes, args.duration, False)
        assert m.out == f"results/reference_numerics/sweep/{stack}"
    table = mf.load_manifest(ROOT / "experiments" / "reference_numerics_table1.toml")
    assert (table.stack, table.seed, table.adaptive, table.out) == (refnum.STACK, 0, True,
                                                                   "results/reference_numerics/table1")
    assert table.policy == "results/reference_numerics/pasta/pasta_final.json"  # trained under the controller
    assert (ROOT / table.policy).exists()


@pytest.mark.parametrize("path", MANIFESTS, ids=lambda p: p.stem)
def test_every_committed_table_carries_the_hash_its_manifest_resolves_to(path: Path) -> None:
    """Each committed table with a manifest: every row carries the hash the manifest resolves to on this code
    (defaults that move change the hash and fail here), unless it is one of the documented unhashed tables."""
    m = mf.load_manifest(path)
    rows = mf.raw_rows(ROOT / m.out / m.csv_name, m.kind)
    assert rows, f"{m.name}: no committed rows in {m.out}/{m.csv_name}"
    hashes = {r["config_hash"] for r in rows}
    if m.name in UNHASHED:
        assert hashes == {""}, (m.name, hashes)
        assert f"`{m.name}`" in (ROOT / "experiments" / "README.md").read_text(encoding="utf-8")  # says why
    else:
        assert hashes == {m.config_hash}, (m.name, hashes)
        assert {(r["stack"], r["scenario"]) for r in rows} == {(m.stack, m.scenario)}
    ids = mf.episode_ids(m, ROOT)
    assert ids <= {mf.row_episode(m, r) for r in rows}, f"{m.name}: episodes of the manifest missing from its CSV"
    if m.kind in ("pareto", "interventions", "figures"):  # nothing but the manifest's episodes in these files
        extra = EXTRA_STRATEGIES.get(m.name, set())
        assert {mf.row_episode(m, r) for r in rows if r.get("strategy") not in extra} == ids, m.name


def test_multi_agent_manifest_names_both_policies_as_its_rows_do() -> None:
    m = mf.load_manifest(ROOT / "experiments" / "multi_agent.toml")
    ids = {s.name: s.policy_id for s in m.strategies(ROOT)}
    assert set(ids) == {"adaptive", "gamma=0.30", "gamma=0.50", "self-play"}
    rows = mf.raw_rows(ROOT / m.out / m.csv_name, m.kind)
    assert {(r["strategy"], r["policy_id"]) for r in rows} == set(ids.items())
    assert {mf.row_id(m, r) for r in rows} == mf.episode_ids(m, ROOT)
    with pytest.raises(ValueError, match="self_play"):
        mf.Manifest(name="x", kind="table1", out="x", self_play="y").strategies(ROOT)


def test_first_format_rows_read_and_refuse_a_backfill(tmp_path: Path) -> None:
    """The first format: no stack, scenario, n_opponents or stalled column; read with the values its rows stand
    for, compared only in the columns it has, and never given a hash (its stalled is unknown)."""
    m = mf.load_manifest(ROOT / "experiments" / "table1_seed13.toml")
    copy = tmp_path / "table1_episodes.csv"
    copy.write_text(FIRST_FORMAT)
    rows = mf.raw_rows(copy)
    assert len(rows) == 2 and {(r["stack"], r["scenario"], r["stalled"], r["config_hash"]) for r in rows} == {
        ("sofar-1", "paper", "", "")}  # made by the default of its time, version 1
    with pytest.raises(ValueError, match="no stack column"):
        mf.backfill_hash(copy, m.config_hash)


@pytest.mark.parametrize("name", BACKFILLED)
def test_backfilled_rows_are_remade_bit_for_bit(name: str, tmp_path: Path) -> None:
    m = mf.load_manifest(ROOT / "experiments" / f"{name}.toml")
    rows = sorted(_cli().shortest_rows(m, 1), key=lambda r: mf.row_length(m, r))[:1]  # the shortest episode
    if m.kind == "interventions":  # every replay of the cheapest failed episode
        rows = _cli().shortest_rows(m, 1)
    assert rows and all(r["config_hash"] == m.config_hash for r in rows)
    assert mf.rerun_rows(m, ROOT, rows, tmp_path) == []


def test_run_writes_manifest_json_and_rows_with_the_hash(tmp_path: Path) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text('kind = "table1"\nout = "unused"\ntracks = ["LagunaSeca"]\nrhos = [0.5]\nepisodes = 1\n'
                    'duration = 0.3\ngammas = [0.5]\nadaptive = false\n')
    m = mf.load_manifest(path)
    report = mf.run_manifest(m, ROOT, workers=1, out=tmp_path / "out", progress=False)
    assert [r["config_hash"] for r in report.rows] == [m.config_hash]
    record = json.loads((tmp_path / "out" / "tiny.manifest.json").read_text())
    assert record["config_hash"] == [m.config_hash] and record["manifest"] == "tiny"
    assert record["commit"] and record["wall_time_s"] >= 0 and "cpu" in record["machine"]
    assert m.config_hash in read_config_json(tmp_path / "out")
    assert record["earlier_runs"] == []
    # a resumed run of the same hash keeps the runs it continued
    mf.run_manifest(m, ROOT, workers=1, out=tmp_path / "out", progress=False)
    again = json.loads((tmp_path / "out" / "tiny.manifest.json").read_text())
    assert again["earlier_runs"] == [{k: record[k] for k in ("commit", "wall_time_s", "finished_at")}]
    with pytest.raises(ValueError, match="unknown keys"):
        (tmp_path / "bad.toml").write_text('kind = "table1"\nout = "x"\nepisode = 1\n')
        mf.load_manifest(tmp_path / "bad.toml")


def test_the_run_record_s_commit_is_dirty_only_when_code_differs_from_it(tmp_path: Path) -> None:
    """Result files changed in the checkout (rows a run resumes from, tables made before it) leave the commit clean;
    a changed tracked file elsewhere marks it ``-dirty``."""
    import subprocess

    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(tmp_path), *args], capture_output=True, text=True,
                              check=True).stdout.strip()

    git("init", "-q")
    (tmp_path / "results").mkdir()
    for name in ("results/rows.csv", "code.py"):
        (tmp_path / name).write_text("a\n")
    git("add", "-A")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "first")
    head = git("rev-parse", "HEAD")
    (tmp_path / "results" / "rows.csv").write_text("a\nb\n")
    (tmp_path / "results" / "new.csv").write_text("c\n")
    assert mf._git_commit(tmp_path) == head
    (tmp_path / "code.py").write_text("b\n")
    assert mf._git_commit(tmp_path) == head + "-dirty"
    assert mf._git_commit(tmp_path / "results" / "rows.csv") == "unknown"  # not a checkout


def test_replay_manifests_are_their_scripts_settings() -> None:
    """The interventions, pareto and floor manifests resolve to the episodes and strategies their folders hold: the
    failed episodes of the base gamma in the sources (every one replayed), and the pareto and floor strategies with
    the policy ids of the rows."""
    for path in MANIFESTS:
        m = mf.load_manifest(path)
        if m.kind == "interventions":
            rows = mf.raw_rows(ROOT / m.out / m.csv_name, m.kind)
            assert {float(r["base_gamma"]) for r in rows} == {m.base_gamma}
            switches = {float(r["gamma"]) for r in rows if r["kind"] == "switch"}
            assert switches <= set(m.gammas or ()) and {r["stack"] for r in rows} == {m.stack}, m.name
        elif m.kind in ("pareto", "floor"):
            extra = EXTRA_STRATEGIES.get(m.name, set())
            rows = [r for r in mf.raw_rows(ROOT / m.out / m.csv_name, m.kind) if r["strategy"] not in extra]
            ids = {s.name: s.policy_id or "" for s in m.strategies(ROOT)}
            assert {r["strategy"] for r in rows} == set(ids), m.name
            assert {(r["strategy"], r["policy_id"]) for r in rows} == set(ids.items()), m.name
    with pytest.raises(ValueError, match="sources"):
        mf.Manifest(name="x", kind="interventions", out="x")


def test_backfill_inserts_the_column_and_keeps_every_other_byte(tmp_path: Path) -> None:
    path = tmp_path / "t_episodes.csv"
    original = "a,stack,b\r\n1,sofar,2\n3,paper,\r\n"
    path.write_bytes(original.encode())
    assert mf.backfill_hash(path, "0123456789ab") == 2
    assert path.read_bytes() == b"a,stack,config_hash,b\r\n1,sofar,0123456789ab,2\n3,paper,0123456789ab,\r\n"
    with pytest.raises(ValueError, match="already"):
        mf.backfill_hash(path, "0123456789ab")
    assert mf.restamp_hash(path, "0123456789ab", "ba9876543210") == 2
    assert path.read_bytes() == b"a,stack,config_hash,b\r\n1,sofar,ba9876543210,2\n3,paper,ba9876543210,\r\n"
    last = tmp_path / "interventions.csv"
    last.write_bytes(b"a,stack,b\n1,sofar,\n")
    assert mf.backfill_hash(last, "0123456789ab", last=True) == 1
    assert last.read_bytes() == b"a,stack,b,config_hash\n1,sofar,,0123456789ab\n"


def test_a_figures_manifest_records_its_episodes_with_their_trace_and_draws_fig5(tmp_path: Path) -> None:
    """kind figures: the shipped policy's episodes as Table I rows (with the manifest's hash) in episodes.csv, their
    steps in trace.csv, both PNGs, its record NAME.manifest.json; a prefix is refused (the file names are fixed)."""
    m = mf.Manifest(name="fig", kind="figures", out="x", stack="sofar", scenario="interactive", opponents=2,
                    episodes=1, duration=2.0, tracks=("LagunaSeca",), rhos=(0.3,))
    assert m.csv_name == "episodes.csv" and [s.name for s in m.strategies(ROOT)] == ["adaptive"]
    report = mf.run_manifest(m, ROOT, workers=1, out=tmp_path, progress=False)
    assert "steps: gamma mean" in report.markdown
    rows = mf.raw_rows(tmp_path / "episodes.csv")
    assert [(r["strategy"], r["config_hash"], r["n_opponents"]) for r in rows] == [("adaptive", m.config_hash, "2")]
    assert {r["episode"] for r in rows} == {"0"} and mf.episode_ids(m, ROOT) == {mf.row_id(m, r) for r in rows}
    assert (tmp_path / "trace.csv").stat().st_size > 0
    assert (tmp_path / "gamma_hist.png").exists() and (tmp_path / "distance_vs_gamma.png").exists()
    assert json.loads((tmp_path / "fig.manifest.json").read_text())["config_hash"] == [m.config_hash]
    with pytest.raises(ValueError, match="no prefix"):
        mf.Manifest(name="fig", kind="figures", out="x", prefix="fig5")


def _result_csvs(name: str) -> list[Path]:
    return sorted((ROOT / "results").glob(f"**/{name}"))


@pytest.mark.parametrize("path", [p for n in ("*_episodes.csv", "episodes.csv") for p in _result_csvs(n)],
                         ids=lambda p: str(p.relative_to(ROOT / "results")))
def test_every_committed_episode_row_carries_the_hash_its_settings_resolve_to(path: Path) -> None:
    """Every per-episode CSV under results/ (with a manifest or not: the stall diagnoses' seed sets too): each row's
    hash is the one its controller, world and horizon resolve to on this code, so no table holds rows whose
    configuration has moved since; a variant that no preset names (a development run) carries the hash of a
    configuration its folder's config.json holds in full; only the documented unhashed tables have rows without
    one."""
    from sofar_env.stack.config import STACK_PRESETS

    unhashed = {ROOT / mf.load_manifest(ROOT / "experiments" / f"{n}.toml").out for n in UNHASHED}
    rows = mf.raw_rows(path)
    assert rows
    if path.parent in unhashed:
        assert {r["config_hash"] for r in rows} == {""}
        return
    resolved = {(r["stack"], r["scenario"], r["duration"]): r["config_hash"] for r in rows}
    for (stack, scenario, duration), h in resolved.items():
        if stack in STACK_PRESETS:
            assert h == episode_config_hash(stack, scenario, float(duration)), (stack, scenario, duration)
        else:  # read_config_json checks that the entry's content has its hash
            assert h in read_config_json(path.parent), (stack, h)


def test_the_cli_runs_several_manifests_in_one_pass_and_lists_one_controller_s(tmp_path: Path, caplog) -> None:
    cli = _cli()
    for name, stack in (("a", "sofar"), ("b", "paper")):
        (tmp_path / f"{name}.toml").write_text(
            f'kind = "table1"\nout = "{tmp_path / name}"\nstack = "{stack}"\ntracks = ["LagunaSeca"]\nrhos = [0.5]\n'
            'episodes = 1\nduration = 0.3\ngammas = [0.5]\nadaptive = false\n')
    with pytest.raises(SystemExit, match="no manifest"):  # every name is checked before anything runs
        cli.main(["--folder", str(tmp_path), "run", "a", "nosuch", "--workers", "1", "--no-progress"])
    assert not (tmp_path / "a").exists()
    caplog.set_level("INFO")
    assert cli.main(["--folder", str(tmp_path), "run", "a", "b", "--workers", "1", "--no-progress"]) == 0
    for name in ("a", "b"):
        assert len(mf.raw_rows(tmp_path / name / "table1_episodes.csv")) == 1
        assert json.loads((tmp_path / name / f"{name}.manifest.json").read_text())["manifest"] == name
    assert "a: " in caplog.text and "b: " in caplog.text
    caplog.clear()
    assert cli.main(["--folder", str(tmp_path), "list", "--stack", "paper"]) == 0
    assert "b: table1" in caplog.text and "a: table1" not in caplog.text


HEADLINE_WORLD_TABLES = {"interactive_table1": "Interactive", "interactive_seed9900": "Interactive",
                         "interactive_dense_table1": "Interactive", "interactive_dense_table2": "Interactive",
                         "interactive_dense_seed9900": "Interactive", "interactive_dense_figures": "Interactive",
                         "dynamic_table1": "Dynamic", "dynamic_seed9900": "Dynamic"}
"""The default's headline tables of the interactive and dynamic worlds, by the family of ids they describe."""


@pytest.mark.parametrize("name", HEADLINE_WORLD_TABLES)
def test_headline_tables_are_made_in_the_world_of_the_newest_ids_and_keep_the_former_one(name: str) -> None:
    """A headline table describes the world ``gym.make`` gives without a version (the newest id); the table of the
    version before is kept under ``NAME_v0`` with the default pinned, its rows in that world."""
    import gymnasium as gym
    from gymnasium.envs.registration import find_highest_version

    import sofar_env  # noqa: F401  (registers the ids)

    family = f"SOfAR-LagunaSeca-{HEADLINE_WORLD_TABLES[name]}"
    newest = gym.spec(f"{family}-v{find_highest_version(None, family)}")
    m = mf.load_manifest(ROOT / "experiments" / f"{name}.toml")
    assert m.stack == "sofar" and m.scenario == newest.kwargs["scenario"]
    before = mf.load_manifest(ROOT / "experiments" / f"{name}_v0.toml")
    assert before.scenario == gym.spec(f"{family}-v0").kwargs["scenario"] != m.scenario
    assert before.stack != "sofar" and before.kind == m.kind and before.seed == m.seed
    rows = mf.raw_rows(ROOT / before.out / before.csv_name)
    assert {r["scenario"] for r in rows} == {before.scenario} and {r["stack"] for r in rows} == {before.stack}
