"""The "first ten minutes" timings come from one measured file, quoted (never retyped) by the README, the
documentation site and the scripts' help."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("first_ten_minutes", ROOT / "eval" / "first_ten_minutes.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_the_readme_quotes_the_measured_table() -> None:
    script = _script()
    measured = (ROOT / "results" / "first_ten_minutes.md").read_text(encoding="utf-8")
    title, _, table = measured.partition("\n\n")
    assert title == "# The first ten minutes" and "Measured by `python eval/first_ten_minutes.py` on " in table
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    quoted = readme[readme.index(script.BEGIN) + len(script.BEGIN):readme.index(script.END)]
    assert quoted == "\n" + table
    assert f"```python\n{script.SNIPPET}```" in readme  # step 3 runs the README's snippet as written


def test_the_site_and_the_help_refer_to_the_file() -> None:
    index = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    assert "<!-- include: results/first_ten_minutes.md level=2 -->" in index
    assert not re.search(r"~\s?\d+ s|\d+ to \d+ minutes", index)  # no hand-typed timings
    pasta = (ROOT / "train" / "pasta.py").read_text(encoding="utf-8")
    assert "results/first_ten_minutes.md" in pasta and "1 to 2 minutes" not in pasta
    assert "~15" not in (ROOT / "eval" / "table.py").read_text(encoding="utf-8")


def test_render_and_readme_update() -> None:
    script = _script()
    rows = script.steps(Path("/tmp/x"), ray=True)
    for s, seconds in zip(rows, (31.0, 6.5, 12.0, 14.0, 52.0, 130.0, 8.0, 44.0)):
        s.seconds = seconds
    info = {"cpu": "Some CPU", "cores": "2 of 2 cores usable, 8 GiB memory", "python": "3.11.7", "system": "Linux 6"}
    text = script.render(rows, info, ("1.0, 1.0, 1.0", "2.0, 1.5, 1.2"), "200 s, overtakes 32, success True",
                         "2026-01-01", 52.0 / 14.0)
    assert "| 5 | a quick training run | `python train/pasta.py --quick`" in text and "| 2.2 min |" in text
    assert "Some CPU, 2 of 2 cores usable" in text and "3.7x the time" in text
    assert "`200 s, overtakes 32, success True`" in text
    readme = f"intro\n{script.BEGIN}\nold\n{script.END}\nrest\n"
    assert script.update_readme(readme, text) == f"intro\n{script.BEGIN}\n{text}{script.END}\nrest\n"
