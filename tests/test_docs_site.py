"""The docs site builds with warnings as errors, and its measured figures come from benchmarks/results/*.json."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
REQUIRED = {"id", "title", "figure", "command", "date", "machine", "commit", "transcribed"}


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


hooks = _load("docs_hooks", ROOT / "docs" / "hooks.py")
results_lib = _load("bench_results", ROOT / "benchmarks" / "_results.py")


@pytest.mark.timeout(300)  # about 15 s on an idle 2-core machine; the limit only guards against a hang
def test_the_site_builds_with_warnings_as_errors(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "-f",
            str(ROOT / "mkdocs.yml"),
            "-d",
            str(tmp_path / "site"),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0 and "WARNING" not in proc.stderr, proc.stderr[-3000:]
    site = tmp_path / "site"
    reference = (site / "reference" / "polyrob" / "index.html").read_text()
    assert "polyrob.model.robots.load_robot" in reference and "polyrob.synthesis.musyn" in reference
    fleet = (site / "fleet" / "index.html").read_text()
    # the fleet's table is generated from benchmarks/results/fleet.json, with its command and date
    assert "<table>" in fleet and "0.6874" in fleet and "Measured with" in fleet
    assert "&lt;!-- results" not in fleet and "<!-- results" not in fleet


def _records():
    for path in sorted(RESULTS.glob("*.json")):
        for record in json.loads(path.read_text())["records"]:
            yield path.stem, record


def test_every_results_record_says_what_command_when_where_and_which_commit():
    records = list(_records())
    assert len(records) >= 10
    for name, r in records:
        assert REQUIRED <= set(r), (name, r.get("id"), REQUIRED - set(r))
        assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", r["date"]), (name, r["id"])
        assert r["commit"] or r.get("documented_at"), (name, r["id"])
        if r["transcribed"]:
            assert r["source"].startswith("transcribed from "), (name, r["id"])
    ids = [(n, r["id"]) for n, r in records]
    assert len(ids) == len(set(ids))


def test_every_results_marker_of_the_docs_names_an_existing_record():
    known = {(n, r["id"]) for n, r in _records()}
    files = {n for n, _ in known}
    marks = []
    for page in (ROOT / "docs").rglob("*.md"):
        marks += hooks._RESULTS_MARK.findall(page.read_text())
    assert marks
    for name, record_id in marks:
        assert name in files and (not record_id or (name, record_id) in known), (name, record_id)


def test_a_record_becomes_its_table_and_one_line_of_provenance(tmp_path, monkeypatch):
    monkeypatch.setattr(hooks, "RESULTS", tmp_path)
    record = {
        "id": "r1",
        "title": "T",
        "figure": "CERTIFIED, mu <= 0.9",
        "command": "python benchmarks/x.py",
        "date": "2026-11-27",
        "machine": "2-core x86_64",
        "commit": "abc1234",
        "transcribed": True,
        "table": {"columns": ["robot", "mu"], "rows": [["ur5", "0.66|0.67"]]},
    }
    (tmp_path / "x.json").write_text(json.dumps({"benchmark": "x", "records": [record]}))
    text = hooks.on_page_markdown("a\n<!-- results: x r1 -->\nb", None, None, None)
    assert "| robot | mu |\n| --- | --- |\n| ur5 | 0.66\\|0.67 |" in text
    assert (
        "*Measured with `python benchmarks/x.py`, 2026-11-27, 2-core x86_64 (transcribed from the earlier docs).*"
        in text
    )
    assert "abc1234" not in text  # the commit stays in the JSON
    with pytest.raises(KeyError, match="no record with id 'r2'"):
        hooks.results_markdown("x", "r2")


def test_a_benchmark_appends_a_record_with_its_date_machine_and_commit(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "argv", [str(ROOT / "benchmarks" / "main_job.py"), "--repeat", "1"])
    record = results_lib.new_record("main-job", "The main job", "CERTIFIED", data={"runs": []})
    assert record["command"] == "python benchmarks/main_job.py --repeat 1" and record["transcribed"] is False
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", record["date"]) and "core" in record["machine"]
    assert record["commit"] is None or re.fullmatch(r"[0-9a-f]{7,40}(\+dirty)?", record["commit"])
    path = tmp_path / "main_job.json"
    results_lib.append_record(path, "main_job", "benchmarks/main_job.py", record)
    results_lib.append_record(path, "main_job", "benchmarks/main_job.py", dict(record, id="second"))
    doc = json.loads(path.read_text())
    assert doc["benchmark"] == "main_job" and [r["id"] for r in doc["records"]] == ["main-job", "second"]


def test_the_benchmarks_turn_their_json_into_records(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    fleet, main_job = (
        _load("bench_fleet", ROOT / "benchmarks" / "fleet.py"),
        _load("bench_main", ROOT / "benchmarks" / "main_job.py"),
    )
    row = dict(
        robot="ur5", model="inner-gain", parameters=2, status="CERTIFIED", mu_upper=0.66521, alpha=32.0, order=12
    )
    row.update(validation="settled, inside", bound_s=108.2, total_s=183.4, certified=True, error=None)
    row.update(mu_upper_grid=0.6601, reason=None, uncertainty="links ±10 % (all by one factor); no payload")
    row.update(inner_layer="computed-torque", structure="pid", bandwidth=31.24, moving=None)
    failed = dict(row, robot="TwoDofs", model=None, status=None, mu_upper=None, alpha=None, order=None, certified=False)
    failed.update(validation=None, bound_s=None, total_s=5.0, error="PerformanceLimit: >= 1", mu_upper_grid=None)
    failed.update(reason="performance limit 1.3 at the weights used", uncertainty=None, inner_layer="none")
    failed.update(structure=None, bandwidth=None)
    moving = {"computed": True, "certified": True, "status": "CERTIFIED", "gamma": 0.9123}
    record = fleet.fleet_record({"robots": [dict(row, moving=moving), failed], "batch_seconds": 1154.4})
    assert record["figure"] == "1 of 2 robots CERTIFIED; 1154 s" and record["id"].startswith("batch-")
    columns = record["table"]["columns"]
    assert columns[:3] == ["robot", "uncertainty", "inner layer"] and columns[-1] == "what stands in the way"
    assert columns[5:8] == ["frozen μ at every frequency", "μ on the grid", "moving robot"]
    assert columns[8:10] == ["controller", "bandwidth rad/s"]
    assert record["table"]["rows"] == [
        ["ur5", "links ±10 % (all by one factor); no payload", "computed-torque", "inner-gain (2)", "CERTIFIED",
         "0.6652", "0.6601", "CERTIFIED (<= 0.9123)", "per-joint PID", "31.2", "32", "settled, inside", "108", "183",
         "–"],
        ["TwoDofs", "–", "none", "–", "FAILED: PerformanceLimit: >= 1", "–", "–", "–", "–", "–",
         "–", "–", "–", "5", "performance limit 1.3 at the weights used"],
    ]  # fmt: skip
    no_pid = fleet.fleet_record({"robots": [dict(row, structure="full")], "batch_seconds": 1.0})
    assert no_pid["table"]["rows"][0][7:9] == ["not asked (--moving)", "full, order 12"]
    asked = fleet.fleet_record({"robots": [row], "batch_seconds": 1.0, "settings": {"moving": True}})
    assert asked["table"]["rows"][0][7] == "–"
    runs = [
        {
            "command": "run --json --quiet",
            "seconds": 69.0,
            "status": "CERTIFIED",
            "bound": 0.9449,
            "controller_order": 8,
        },
        {"command": "run --json --quiet -o out", "seconds": 89.0},
    ]
    record = main_job.main_job_record({"runs": runs})
    assert record["figure"] == "CERTIFIED, mu <= 0.9449, controller of order 8; 69 s, 89 s (with -o)"


def test_the_how_to_commands_parse_as_written():
    """Every `polyrob` command of the how-to pages' ```bash blocks parses with the CLI (SystemExit(2) otherwise)."""
    import shlex

    from polyrob.cli import build_parser

    commands = []
    for page in sorted((ROOT / "docs" / "howto").glob("*.md")):
        for block in re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.S):
            for line in block.splitlines():
                line = line.split("  #")[0].strip()
                commands += [p.strip() for p in line.split("&&") if p.strip().startswith("polyrob ")]
    assert len(commands) >= 20
    for command in commands:
        assert callable(build_parser().parse_args(shlex.split(command)[1:]).func), command


def test_the_generated_tables_show_no_commit_hash():
    """The commit stays in the record's fields; what a page shows (title, figure, table, conditions) names none."""
    for path in sorted(RESULTS.glob("*.json")):
        text = hooks.results_markdown(path.stem)
        hashes = [h for h in re.findall(r"\b[0-9a-f]{7,40}\b", text) if re.search(r"\d", h) and re.search(r"[a-f]", h)]
        assert hashes == [], (path.name, hashes)


# A measured time in a table cell: a number followed by " s", "min" or "GB" ("2.9 s", "4 min 59 s", "3.1 GB").
MEASURED_TIME = re.compile(r"\d\s?(?:s|min|GB)\b")
# The tables the docs may write by hand: definitions (what a status, field, option or stage means), never a
# measurement.  A new hand-written table must be a results record shown by a marker, or a definition added here.
DEFINITION_TABLES = {
    ("synthesis.md", "| channel | signal, unit | weight | what `‖·‖ < 1` means |"),
    ("synthesis.md", "| plant input `u` | `W_f` | exact? |"),
    ("api.md", "| function | returns |"),
    ("api.md", "| name | what it holds |"),
    ("certificates.md", "| status | meaning |"),
    ("certificates.md", "| field | what it says |"),
    ("certificates.md", "| | μ with constant parameters | quadratic stability / performance |"),
    ("certificates.md", "| certificate | what it covers | set | status when proved < 1 | code |"),
    ("howto/your_robot.md", "| you have | give |"),
    ("howto/your_robot.md", "| option | meaning |"),
    ("index.md", "| you want to | read |"),
    ("method.md", "| stage | computed by | what it guarantees |"),
    ("mu.md", "| figure | what it is |"),
    ("paper_2r.md", "| model | what it is | Coriolis matrix |"),
    ("reference/results.md", "| field | meaning |"),
    ("robots.md", "| URDF joint | what polyrob does |"),
    ("uncertainty.md", "| model | parameters (paper_2r) | what moves together | applies to |"),
}


def _tables(markdown: str):
    """``(line number, rows)`` of every Markdown table outside code fences (a header row, then ``|---``)."""
    lines, in_code, k = markdown.splitlines(), False, 0
    while k < len(lines):
        if lines[k].startswith("```"):
            in_code = not in_code
        elif not in_code and lines[k].startswith("|") and k + 1 < len(lines) and re.match(r"\|\s*:?-{3}", lines[k + 1]):
            start = k
            while k < len(lines) and lines[k].startswith("|"):
                k += 1
            yield start + 1, lines[start:k]
            continue
        k += 1


def _hand_written_tables():
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for line, rows in _tables(page.read_text()):
            yield page.relative_to(ROOT / "docs").as_posix(), line, rows


def test_the_table_reader_finds_a_measured_time_only_in_tables():
    page = "a 0.5 s delay in prose\n\n| run | time |\n| --- | ---: |\n| x | 4 min 59 s |\n\n```\n| a | 9 s |\n|---|---|\n```\n"
    found = list(_tables(page))
    assert [line for line, _ in found] == [3]
    assert [row for _, rows in found for row in rows if MEASURED_TIME.search(row)] == ["| x | 4 min 59 s |"]
    assert not MEASURED_TIME.search("| ur5 | 5.63 rad/s | sigma 3 |")
    # the generated tables do carry measured times, so the rule below is not vacuous
    generated = "\n".join(hooks.results_markdown(path.stem) for path in sorted(RESULTS.glob("*.json")))
    assert any(MEASURED_TIME.search(row) for _, rows in _tables(generated) for row in rows)


def test_no_hand_written_table_of_the_docs_holds_a_measured_time():
    """A table with timings (or sizes) is a measurement: it comes from benchmarks/results/*.json via a marker."""
    offending = [
        f"{page}:{line}: {row[:80]}"
        for page, line, rows in _hand_written_tables()
        for row in rows
        if MEASURED_TIME.search(row)
    ]
    assert offending == [], "move these tables into a results record and show them with <!-- results: NAME ID -->"


def test_every_hand_written_table_of_the_docs_is_a_definition():
    """Measured tables (μ values, bounds, ratios, times) are generated; only the listed definition tables are not."""
    found = {(page, " ".join(rows[0].split())) for page, _, rows in _hand_written_tables()}
    assert found - DEFINITION_TABLES == set(), "a new hand-written table: generate it, or list it as a definition"


def test_the_benchmarks_record_the_figure_their_json_gives(monkeypatch):
    """mu.py, synthesis.py, validation.py, mu_between.py and box_maximum.py (--results): the record's one-line figure."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    mu = _load("bench_mu", ROOT / "benchmarks" / "mu.py")
    report = {
        "problems": [
            {"problem": "distillation_rp", "methods": {"polyrob_ab13md": {"peak_upper": 5.7726}, "dkpy": "absent"}}
        ],
        "total_seconds": 17.2,
    }
    assert mu.mu_figure(report) == "distillation_rp: polyrob_ab13md 5.773; 17 s in all"
    synthesis = _load("bench_synthesis", ROOT / "benchmarks" / "synthesis.py")
    doc = {"distillation": {"polyrob": {"peak_mu_certified": 1.0123}, "dkpy": "not installed"}, "total_seconds": 961.0}
    assert synthesis.synthesis_figure(doc) == "certified peak mu: distillation polyrob 1.012; 961 s in all"
    validation = _load("bench_validation", ROOT / "benchmarks" / "validation.py")
    out = {
        "mu_continuous_grid": 2.0716,
        "min_rate_tustin": {"min_rate_hz": 67.0149773281274},
        "min_rate_zoh": {"min_rate_hz": None},
        "word_length_at_min_rate": {"min_word_length": 18, "rate_hz": 67.0149773281274},
        "word_length_at_rate": {"min_word_length": 26, "rate_hz": 1000.0},
    }
    assert validation.validation_figure(out) == (
        "continuous mu 2.072; lowest rate tustin 67 Hz, zoh none found; word length 18 bits at 67 Hz, 26 bits at 1000 Hz"
    )
    between = _load("bench_mu_between", ROOT / "benchmarks" / "mu_between.py")
    out = dict(robot="paper_2r", grid_peak_mu_upper=0.78321, verified_every_frequency=True, level=0.79102)
    assert between.between_figure(dict(out, points_added=66)) == (
        "paper_2r: grid peak 0.7832; mu <= 0.791 at every frequency, 66 points added"
    )
    assert between.between_figure(dict(out, verified_every_frequency=False, reason="200 points added")) == (
        "paper_2r: grid peak 0.7832; not verified between the points: 200 points added"
    )
    box = _load("bench_box_maximum", ROOT / "benchmarks" / "box_maximum.py")
    out = dict(fraction_exact_quadratic_pairs=0.927, fraction_exact_all_pairs=0.984, largest_relative_shortfall=0.0091)
    out.update(ms_per_polynomial_exact_faces=0.21, ms_per_polynomial_vertices_ascent=0.002)
    assert box.box_maximum_figure(out) == (
        "exact for 92.7 % of the pairs quadratic in the velocities, 98.4 % of all, at worst 0.91 % below; "
        "0.21 ms per polynomial (faces) against 0.002 ms (vertices and ascent)"
    )


def test_every_results_file_is_shown_on_the_benchmarks_page():
    shown = {name for name, _ in hooks._RESULTS_MARK.findall((ROOT / "docs" / "benchmarks.md").read_text())}
    assert {path.stem for path in RESULTS.glob("*.json")} <= shown


def test_a_star_or_a_pipe_in_a_record_is_text():
    text = hooks.record_markdown(
        {"title": "The paper's K* on the box", "figure": "K* VIOLATED", "command": "c", "date": "d", "machine": "m"}
    )
    assert "**The paper's K\\* on the box**" in text and "Figure: K\\* VIOLATED" in text
    # a code span keeps its pipes and stars as written (Markdown's tables do not split a cell there)
    assert hooks._cell("`|drho/dt| <= 0.1` a|b") == "`|drho/dt| <= 0.1` a\\|b"
    assert hooks._text("`K*` or K*") == "`K*` or K\\*"
