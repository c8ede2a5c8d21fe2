"""The project's pages: the README is short and its walk-through works, every relative link
resolves, the numbers the docs quote come from a file the workflow writes, and nothing speaks of
how the project was developed."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", REPO / "environment-notes.md", *sorted((REPO / "docs").glob("*.md"))]
# what a reader of the project sees: code, comments, docstrings, tests, config, docs
SPOKEN = ["src", "workflow", "config", "benchmarks", "tests", "docs", "profiles", "data",
          "README.md", "environment-notes.md", "Snakefile", "Makefile", "pyproject.toml", ".ci"]
HISTORY = re.compile(r"\bsessions?\b|\bissues?\s*#?\d+|\bsprint\b", re.IGNORECASE)
# pytest's own word for a fixture that lives for the whole test run
ALLOWED = re.compile(r"""scope=["']session["']""")
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")


def _files(names):
    for name in names:
        path = REPO / name
        if path.is_file():
            yield path
        elif path.is_dir():
            yield from (p for p in sorted(path.rglob("*")) if p.is_file() and "__pycache__" not in p.parts
                        and p.suffix in {".py", ".smk", ".md", ".yaml", ".yml", ".rst", ".cpp", ".sh", ".toml", ".csv", ".txt", ""})


def test_nothing_speaks_of_how_the_project_was_developed():
    """No "Nth session", no "issue N": a reader has neither. (The same words as the check
    `grep -rniE "session|issue [0-9]"` looks for, plus "sessions", "issue #N" and "sprint".)"""
    found = []
    for path in _files(SPOKEN):
        if path == Path(__file__):
            continue
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if HISTORY.search(ALLOWED.sub("", line)):
                found.append(f"{path.relative_to(REPO)}:{number}: {line.strip()[:120]}")
    assert not found, "\n".join(found[:40])


OUTSIDE = re.compile(r"\bSPEC\.md\b|\bSPEC section\b|\.\./shared\b")


def test_nothing_cites_a_file_the_repository_does_not_hold():
    """The project speaks of itself only: no specification or shared folder a reader does not have."""
    found = [f"{path.relative_to(REPO)}:{number}" for path in _files(SPOKEN) if path != Path(__file__)
             for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1) if OUTSIDE.search(line)]
    assert not found, found
    assert OUTSIDE.search("pinned down in SPEC.md") and OUTSIDE.search("see ../shared/paper") and not OUTSIDE.search("SPEC.json")


def test_the_history_check_can_fail():
    for line in ("the eighteenth session's machine", "(issue 26)", "Issue #31 step 2", "two sessions ago"):
        assert HISTORY.search(line), line
    for line in ('@pytest.fixture(scope="session")', "the issue's target", "tissue 3"):
        assert not HISTORY.search(ALLOWED.sub("", line)), line


def _slug(heading: str) -> str:
    """The anchor a Markdown forge gives a heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    return re.sub(r"\s", "-", re.sub(r"[^\w\- ]", "", text))


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
    return {_slug(line.lstrip("#")) for line in text.splitlines() if line.startswith("#")}


def _declared_outputs() -> str:
    """The workflow's text: a link into results/ must name a file a rule writes."""
    return "\n".join(p.read_text() for p in [REPO / "Snakefile", *sorted((REPO / "workflow" / "rules").glob("*.smk"))])


def broken_links(pages: list[Path], repo: Path = REPO) -> list[str]:
    rules = _declared_outputs()
    broken = []
    for page in pages:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
        for match in LINK.finditer(text):
            target = match.group(1) or match.group(2)
            if re.match(r"^[a-z]+:", target):
                continue
            path_part, _, anchor = target.partition("#")
            resolved = (page.parent / path_part).resolve() if path_part else page
            try:
                relative = resolved.relative_to(repo)
            except ValueError:
                broken.append(f"{page.name}: {target} (outside the repository)")
                continue
            if relative.parts and relative.parts[0] == "results":
                # generated: the link must name a file the workflow writes (or a folder of them)
                if str(relative) not in rules and not any(str(relative) + "/" in line for line in rules.splitlines()):
                    broken.append(f"{page.name}: {target} (no rule writes it)")
                continue
            if not resolved.exists():
                broken.append(f"{page.name}: {target} (missing)")
            elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
                broken.append(f"{page.name}: {target} (no such heading)")
    return broken


def test_relative_links_resolve():
    assert not broken_links(PAGES), "\n".join(broken_links(PAGES))


def test_the_link_checker_can_fail(tmp_path):
    (tmp_path / "docs").mkdir()
    page = tmp_path / "docs" / "page.md"
    (tmp_path / "docs" / "there.md").write_text("# A heading\n")
    page.write_text("[ok](there.md#a-heading) [gone](missing.md) [anchor](there.md#nope) "
                    "[generated](../results/not/a/target.csv) [web](https://example.org)\n")
    assert [line.split(" (")[1] for line in broken_links([page], tmp_path)] == [
        "missing)", "no such heading)", "no rule writes it)"]


def test_the_readme_introduces_in_at_most_250_lines():
    readme = (REPO / "README.md").read_text()
    assert len(readme.splitlines()) <= 250
    # the two set-up commands, and .ci/run calls the test one
    assert "make all" in readme and "make test" in readme
    assert "make test" in (REPO / ".ci" / "run").read_text()
    for page in ("docs/method.md", "docs/results.md", "docs/decisions.md"):
        assert page in readme, page


def test_no_measured_number_is_typed_into_readme_method_or_results():
    """README, docs/method.md and docs/results.md quote measurements through results/summary.md:
    a number with a unit of time, or a percentage error, typed into them goes stale. (Formulas,
    config defaults and sizes are not measurements. docs/decisions.md is the dated record of what
    was measured and not adopted, each number with its machine and date.)"""
    measured = re.compile(r"\b\d+(\.\d+)?\s?(ms|min)\b|\b\d+\.\d+\s?s\b|\b\d+(\.\d+)?x faster|\b\d+\.\d+ ?%")
    found = []
    for name in ("README.md", "docs/method.md", "docs/results.md"):
        text = (REPO / name).read_text()
        found += [f"{name}: {m.group(0)}" for m in measured.finditer(text)]
    assert not found, found


def test_summary_renders_this_runs_tables(tmp_path):
    """results/summary.md quotes the tables it is given, value for value, with the machine and date."""
    import json

    from ifenn.studies.tables.summary import render_summary

    results = tmp_path / "results"
    (results / "tables").mkdir(parents=True)
    (results / "benchmarks").mkdir()
    table = pd.DataFrame({"scene": ["snt1", "snt1"], "run": ["a", "b"], "wall_s": [12.345678, 3.0],
                          "force_l2_rel_error": [0.123456, 0.0], "extra": [1, 2]})
    table.to_csv(results / "tables" / "speed_accuracy.csv", index=False)
    (results / "benchmarks" / "machine_speed.json").write_text(json.dumps(
        {"mumps_factor_solve_s": 0.2, "kept_factor_apply_ms": 7.5, "host": "box", "machine": "x86_64", "date": "2026-01-02",
         "reference": {"mumps_factor_solve_s": 0.14, "kept_factor_apply_ms": 6.9}}))
    text = render_summary({"speed_accuracy": results / "tables" / "speed_accuracy.csv"},
                          results / "benchmarks" / "machine_speed.json", ["quick.yaml"], date="2026-01-02")
    assert "12.35" in text and "0.1235" in text and "extra" not in text
    assert "(tables/speed_accuracy.csv)" in text
    assert "0.2 s" in text and "7.5 ms" in text and "2026-01-02" in text and "`quick.yaml`" in text
    assert "Not produced by this run's config" in text and "`accuracy`" in text
    with pytest.raises(ValueError, match="no summary section"):
        render_summary({"nonsense": results / "tables" / "speed_accuracy.csv"})


def readme_specimen() -> dict:
    """The README's worked example of a new specimen, as a config dict."""
    import yaml

    text = (REPO / "README.md").read_text()
    marker = text.index("<!-- example-specimen")
    block = re.search(r"```yaml\n(.*?)```", text[marker:], flags=re.DOTALL)
    return yaml.safe_load(block.group(1))


def test_the_readme_walkthrough_adds_a_specimen(tmp_path):
    """A reader's walk-through: the README's specimen file, run as it says on the quick profile
    (its element size and load steps, everything else as written), through Snakemake from another
    directory. The physics: the force peaks and the specimen separates; the crack runs straight along
    the notch's line (mode I); the adaptive mesh and the verified IFENN step agree with FEM."""
    import subprocess
    import sys

    import yaml

    from ifenn.config import load_config
    from ifenn.run_files import read_phase_field_maps

    specimen = readme_specimen()
    (scene_name, scene), = specimen["scenes"].items()
    (schedule_name, _), = specimen["schedules"].items()
    quick = load_config(REPO / "config" / "config.yaml", REPO / "config" / "quick.yaml")
    scene["elements"] = quick["scenes"]["snt1"]["elements"]
    specimen["schedules"][schedule_name] = quick["schedules"]["II"]
    (tmp_path / "my-specimen.yaml").write_text(yaml.safe_dump(specimen))
    (fem_run,) = specimen["fem_runs"]
    (adaptive_run,) = specimen["adaptive_runs"]
    (ifenn_run,) = specimen["ifenn_runs"]
    targets = [f"results/figures/fem/{fem_run}_force_displacement.png", f"results/adaptive/{adaptive_run}/history.csv",
               f"results/ifenn/{ifenn_run}/history.csv"]
    result = subprocess.run([sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--cores", "2", *targets,
                             "--configfile", str(REPO / "config" / "quick.yaml"), "my-specimen.yaml"],
                            cwd=tmp_path, capture_output=True, text=True, timeout=3600,
                            env={**__import__("os").environ, "OMP_NUM_THREADS": "1"})
    assert result.returncode == 0, result.stderr[-3000:]
    results = tmp_path / "results"
    fem = pd.read_csv(results / "fem" / fem_run / "history.csv")
    peak = fem.reaction_force.max()
    assert peak > 0 and fem.reaction_force.iloc[-1] < 0.05 * peak, "the specimen separates"
    # the crack cuts the whole ligament, and it starts at the notch tip on the notch's line (farther
    # on, the off-centre notch's crack curves towards the loaded edge)
    maps, attrs = read_phase_field_maps(results / "fem" / fem_run / "fields.h5")
    _, phi = maps[max(maps)]
    h = float(attrs["h_px"])
    x = float(attrs["x0"]) + h * (np.arange(phi.shape[1]) + 0.5)
    y = float(attrs["y0"]) + h * (np.arange(phi.shape[0]) + 0.5)
    (notch,) = scene["notches"]
    tip_x, notch_y = min(notch["start"][0], notch["end"][0]), notch["start"][1]
    assert (phi[:, x < tip_x].max(axis=0) > 0.95).all(), "the crack cuts the ligament"
    near_tip = (x < tip_x) & (x > tip_x - quick["material"]["lc"] / 4)
    crack_y = y[np.argmax(phi[:, near_tip], axis=0)]
    assert np.abs(crack_y - notch_y).max() <= 2 * h, crack_y
    adaptive = pd.read_csv(results / "adaptive" / adaptive_run / "history.csv")
    assert abs(adaptive.reaction_force.max() / peak - 1) < 0.02
    hybrid = pd.read_csv(results / "ifenn" / ifenn_run / "history.csv")
    after = hybrid[hybrid.hybrid_active == 1]
    assert len(after) > 0 and (after.verify_residual_after <= quick["ifenn"]["verification"]["tolerance"] * (1 + 1e-9)).all()
    assert np.abs(hybrid.reaction_force.to_numpy() - fem.reaction_force.to_numpy()).max() < 0.05 * peak


def test_report_captions_are_valid_restructured_text():
    """`snakemake --report` renders each caption with docutils: a stray |x| is a substitution error there."""
    import docutils.core
    import docutils.utils

    bad = []
    for caption in sorted((REPO / "workflow" / "report").glob("*.rst")):
        try:
            docutils.core.publish_string(caption.read_text(), writer_name="null",
                                         settings_overrides={"report_level": 5, "halt_level": 2})
        except docutils.utils.SystemMessage as error:
            bad.append(f"{caption.name}: {error}")
    assert not bad, bad
