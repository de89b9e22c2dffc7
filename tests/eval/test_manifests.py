"""experiments/*.toml: every manifest resolves; committed rows carry their manifest's hash; back-filled
tables are re-made bit for bit; run writes manifest.json; back-filling changes nothing but the column."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from sofar_agents.evaluation import manifest as mf
from sofar_agents.evaluation.configs import episode_config_hash, read_config_json

ROOT = Path(__file__).resolve().parents[2]
MANIFESTS = mf.manifest_paths(ROOT / "experiments")
BACKFILLED = ("table1", "paper_stack_table1", "paper_stack_seed21", "paper_stack_seed42")
"""Committed tables written before the hash column whose rows were shown to be re-made by the current code
(``python eval/manifest.py verify NAME --rows 2 --backfill``) and so carry their manifest's hash."""


def _cli():
    spec = importlib.util.spec_from_file_location("manifest_cli", ROOT / "eval" / "manifest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_main_tables_have_manifests() -> None:
    names = {p.stem for p in MANIFESTS}
    assert {"table1", "paper_stack_table1", "reference_numerics_table1", "reference_numerics_sweep",
            "reference_numerics_sweep_no_phantoms"} <= names


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


@pytest.mark.parametrize("name", BACKFILLED)
def test_backfilled_rows_are_remade_bit_for_bit(name: str, tmp_path: Path) -> None:
    m = mf.load_manifest(ROOT / "experiments" / f"{name}.toml")
    rows = sorted(_cli().shortest_rows(m, 1), key=lambda r: int(r["steps"]))[:1]  # the shortest episode
    assert rows and rows[0]["config_hash"] == m.config_hash
    assert mf.rerun_rows(m, ROOT, rows, tmp_path) == []


def test_run_writes_manifest_json_and_rows_with_the_hash(tmp_path: Path) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text('kind = "table1"\nout = "unused"\ntracks = ["LagunaSeca"]\nrhos = [0.5]\nepisodes = 1\n'
                    'duration = 0.3\ngammas = [0.5]\nadaptive = false\n')
    m = mf.load_manifest(path)
    report = mf.run_manifest(m, ROOT, workers=1, out=tmp_path / "out", progress=False)
    assert [r["config_hash"] for r in report.rows] == [m.config_hash]
    record = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert record["config_hash"] == [m.config_hash] and record["manifest"] == "tiny"
    assert record["commit"] and record["wall_time_s"] >= 0 and "cpu" in record["machine"]
    assert m.config_hash in read_config_json(tmp_path / "out")
    with pytest.raises(ValueError, match="unknown keys"):
        (tmp_path / "bad.toml").write_text('kind = "table1"\nout = "x"\nepisode = 1\n')
        mf.load_manifest(tmp_path / "bad.toml")


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
