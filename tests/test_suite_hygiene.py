"""The test suite itself: no guard that turns a regression into a skip, and Dask a default dependency."""

import ast
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = sorted(Path(__file__).resolve().parent.rglob("test_*.py"))


def _calls(node: ast.AST, dotted: str) -> bool:
    """Whether ``node`` contains a call of ``dotted`` (e.g. ``pytest.skip``)."""
    owner, _, name = dotted.rpartition(".")
    return any(
        isinstance(call, ast.Call)
        and isinstance(call.func, ast.Attribute)
        and call.func.attr == name
        and isinstance(call.func.value, ast.Name)
        and call.func.value.id == owner
        for call in ast.walk(node)
    )


def test_no_error_is_turned_into_a_skip():
    """``except SomeError: pytest.skip(...)`` hides a regression (a setting that stops existing) as a skip."""
    offenders = []
    for path in TESTS:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ExceptHandler) and any(_calls(stmt, "pytest.skip") for stmt in node.body):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders, offenders


def test_no_module_level_skip_on_a_dependency():
    """A dependency of kalcal that is missing must fail the tests that need it, not skip a whole module."""
    offenders = []
    for path in TESTS:
        for stmt in ast.parse(path.read_text(encoding="utf-8")).body:
            if _calls(stmt, "pytest.importorskip"):
                offenders.append(f"{path.relative_to(ROOT)}:{stmt.lineno}")
    assert not offenders, offenders


def test_dask_is_a_default_dependency():
    """Dask is the scale-out engine (--workers, --scheduler): every install has it."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert any(req.replace(" ", "").startswith("dask[distributed]") for req in project["dependencies"])


def test_every_module_opens_with_one_line_saying_its_job():
    """docs/architecture.md: one job per module, said in its first docstring line (no cap on its length:
    a concept stays in one module rather than being split by size)."""
    package = ROOT / "src" / "kalcal"
    modules = sorted(package.rglob("*.py"))
    assert len(modules) > 50
    for module in modules:
        text = module.read_text()
        docstring = ast.get_docstring(ast.parse(text))
        assert docstring, f"{module}: no docstring"
        assert "\n" not in docstring.split("\n\n")[0], f"{module}: its opening line runs on"


def test_no_merge_conflict_markers_are_left_in_the_text():
    """A conflict resolved in haste leaves ``<<<<<<<`` lines that no other test reads (the docs)."""
    texts = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "src").rglob("*.py"), *TESTS]
    markers = ("<<<<<<< ", ">>>>>>> ", "=======\n")
    offenders = []
    for path in texts:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(keepends=True), start=1):
            if line.startswith(markers) or line == "=======":
                offenders.append(f"{path.relative_to(ROOT)}:{number}")
    assert not offenders, offenders


#: how a measurement diary reads: the machine a number was measured on, its load, the sitting. The numbers
#: and how they were measured belong in benchmarks/README.md; a user doc gives orders of magnitude.
DIARY = r"\b(\d+|one|two|four)-core\b|\bone sitting\b|\bload average\b|\bshared\b[\w\s-]{0,20}\bmachine\b|\buntil this was unified\b"
#: user docs not yet cleared of their measurement diaries (each moves to benchmarks/README.md)
DIARY_PENDING = {"docs/imu-3axis.md", "docs/custom-models.md"}


def test_user_docs_keep_no_measurement_diary():
    """A user doc says what a user needs (what is compiled, a ratio's order of magnitude and where it was
    measured); the machine, its load and the sitting are benchmarks/README.md's."""
    import re

    pattern = re.compile(DIARY, re.IGNORECASE)
    # the phrases removed from docs/nonlinear.md and docs/accel-gps.md are what the pattern finds
    for removed in ("(shared 2-core machine): 10.5 s", "one\nsitting on the shared 2-core machine, its load average near 7",
                    "(Until this was unified, `calibrate` used", "on the same shared\ntwo-core machine before and after"):
        assert pattern.search(removed), removed
    assert not pattern.search("the shared machinery, scenario-free; a 4-state model; two cores in one process")
    docs = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    offenders = [
        f"{path.relative_to(ROOT)}:{text[: match.start()].count(chr(10)) + 1}: {match.group(0)!r}"
        for path in docs if str(path.relative_to(ROOT)) not in DIARY_PENDING
        for text in [path.read_text(encoding="utf-8")] for match in pattern.finditer(text)
    ]
    assert not offenders, "measurement diaries in user docs (move them to benchmarks/README.md):\n" + "\n".join(offenders)
