"""sofar_agents.evaluation.manifest_adopt: a default's table started from a candidate's rows of the same
configuration, relabelled and otherwise byte for byte; the run resumes from them; every mismatch refused with
nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sofar_agents.evaluation import manifest as mf
from sofar_agents.evaluation.manifest_adopt import adopt_rows

ROOT = Path(__file__).resolve().parents[2]


POLICY = "sofar_agents/checkpoints/pasta_lagunaseca_sofar13.json"
MORL_POLICY = "results/interactive_dense/morl_sofar17/pasta_morl_interactive_sofar17_sigmoid.json"


def _manifest(tmp_path: Path, name: str, stack: str, gammas: str, kind: str = "table1", duration: float = 0.3,
              adaptive: bool = False):
    path = tmp_path / f"{name}.toml"
    policy = f'adaptive = true\npolicy = "{POLICY}"\n' if adaptive else "adaptive = false\n"
    path.write_text(f'kind = "{kind}"\nout = "{tmp_path / name}"\nstack = "{stack}"\ntracks = ["LagunaSeca"]\n'
                    f'rhos = [0.5]\nepisodes = 1\nduration = {duration}\ngammas = [{gammas}]\n{policy}')
    return mf.load_manifest(path)


@pytest.fixture(scope="module")
def candidate(tmp_path_factory):
    """A candidate preset's run of two fixed gammas and a policy (``"sofar-17"``, the default's value under its own
    name)."""
    tmp = tmp_path_factory.mktemp("adopt")
    m = _manifest(tmp, "candidate", "sofar-17", "0.05, 0.5", adaptive=True)
    mf.run_manifest(m, ROOT, workers=1, progress=False)
    return tmp, m


def test_adopted_rows_are_the_candidate_s_relabelled_and_the_run_makes_only_the_rest(candidate):
    tmp, source = candidate
    target = _manifest(tmp, "default", "sofar", "0.05, 0.5, 0.95", adaptive=True)
    assert target.config_hash == source.config_hash
    assert adopt_rows(target, source, ROOT) == 2  # the policy's row is left to the run (its policy may differ)
    src = [line for line in (tmp / "candidate" / "table1_episodes.csv").read_text().splitlines()
           if ",adaptive," not in line]
    assert len(src) == 3
    dst = (tmp / "default" / "table1_episodes.csv").read_text().splitlines()
    at = src[0].split(",").index("stack")
    assert dst[0] == src[0] and len(dst) == 3
    for a, b in zip(src[1:], dst[1:]):  # every field as written but the preset's name
        fa, fb = a.split(","), b.split(",")
        assert fb[at] == "sofar" and fa[at] == "sofar-17"
        assert fa[:at] + fa[at + 1:] == fb[:at] + fb[at + 1:]
    record = json.loads((tmp / "default" / "default.manifest.json").read_text())
    assert record["adopted_from"] == "candidate" and record["config_hash"] == [target.config_hash]
    report = mf.run_manifest(target, ROOT, workers=1, progress=False)  # resumes: gamma 0.95 and the policy
    assert sorted(r["strategy"] for r in report.rows) == ["adaptive", "gamma=0.05", "gamma=0.50", "gamma=0.95"]
    after = (tmp / "default" / "table1_episodes.csv").read_text().splitlines()
    assert after[:3] == dst and len(after) == 5
    again = json.loads((tmp / "default" / "default.manifest.json").read_text())
    assert again["earlier_runs"][-1]["adopted_from"] == "candidate"
    assert mf.check_manifest(target, ROOT).status == "ok"
    with pytest.raises(ValueError, match="already"):  # adopting twice would duplicate episodes
        adopt_rows(target, source, ROOT)
    assert (tmp / "default" / "table1_episodes.csv").read_text().splitlines() == after


@pytest.mark.parametrize("stack,kind,duration,match", [
    ("sofar-16", "table1", 0.3, "another configuration"),  # the DAQP backend: another hash
    ("sofar", "table2", 0.3, "one kind"),
    ("sofar", "table1", 0.6, "another configuration"),  # the duration is part of the configuration
])
def test_rows_of_another_configuration_or_kind_are_refused_and_nothing_is_written(candidate, stack, kind, duration,
                                                                                  match):
    tmp, source = candidate
    target = _manifest(tmp, f"refused_{stack}_{kind}_{duration}", stack, "0.05", kind=kind, duration=duration)
    with pytest.raises(ValueError, match=match):
        adopt_rows(target, source, ROOT)
    assert not (tmp / target.name).exists()


def test_a_source_without_rows_or_without_the_target_s_episodes_is_refused(candidate, tmp_path):
    tmp, source = candidate
    empty = _manifest(tmp_path, "empty", "sofar-17", "0.05")
    with pytest.raises(ValueError, match="run it first"):
        adopt_rows(_manifest(tmp_path, "t1", "sofar", "0.05"), empty, ROOT)
    with pytest.raises(ValueError, match="none of the fixed-gamma rows"):
        adopt_rows(_manifest(tmp_path, "t2", "sofar", "0.95"), source, ROOT)
    assert not (tmp_path / "t1").exists() and not (tmp_path / "t2").exists()


def _pareto(tmp_path: Path, name: str, policy: str | None) -> mf.Manifest:
    path = tmp_path / f"{name}.toml"
    agent = f'adaptive = true\npolicy = "{policy}"\nsafety_weights = [0.9]\n' if policy else "adaptive = false\n"
    path.write_text(f'kind = "pareto"\nout = "{tmp_path / name}"\nstack = "sofar-17"\nscenario = "interactive"\n'
                    f'tracks = ["LagunaSeca"]\nrhos = [0.5]\nepisodes = 1\nduration = 0.3\ngammas = [0.05, 0.5]\n'
                    f'{agent}')
    return mf.load_manifest(path)


def test_a_second_policy_s_front_adopts_the_fixed_gammas_of_the_first_and_runs_only_its_own(tmp_path):
    first = _pareto(tmp_path, "first", None)
    mf.run_manifest(first, ROOT, workers=1, progress=False)
    second = _pareto(tmp_path, "second", MORL_POLICY)
    assert adopt_rows(second, first, ROOT) == 2
    adopted = (tmp_path / "second" / second.csv_name).read_text().splitlines()
    assert adopted == (tmp_path / "first" / first.csv_name).read_text().splitlines()  # the same preset's name
    mf.run_manifest(second, ROOT, workers=1, progress=False)
    after = (tmp_path / "second" / second.csv_name).read_text().splitlines()
    assert after[:3] == adopted and len(after) == 4 and after[3].split(",")[1].startswith("pasta w=0.9/")
