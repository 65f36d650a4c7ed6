"""Import rules of docs/architecture.md: each part of rbcli imports only the parts below it (one explicit
table, checked on every import statement of every file); physics is pure numerics; the CLI front door
stays light."""

import ast
import functools
import subprocess
import sys
from collections.abc import Iterator
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "rbcli"

# What each part of rbcli (a subpackage, or a module at the top: "__init__" is rbcli itself) may import
# from the other parts, anywhere in its files (imports inside functions and under TYPE_CHECKING count).
# Data flows one way: scene YAML -> scene -> physics, run by runner, recorded by record, offered by api,
# driven by cli. A part missing here fails test_every_part_of_rbcli_has_a_rule: a new one needs a line.
ALLOWED_IMPORTS: dict[str, frozenset[str]] = {
    "_version": frozenset(),
    "physics": frozenset(),  # numpy and numba only (test_physics_imports_only_numpy_and_numba)
    "scene": frozenset({"physics"}),
    "record": frozenset({"physics", "scene"}),
    "analysis": frozenset({"physics", "scene", "record"}),
    "runner": frozenset({"_version", "physics", "scene", "record", "analysis"}),  # never api: api is above it
    "api": frozenset({"physics", "scene", "record", "runner"}),
    "sweeps": frozenset({"_version", "scene", "record", "analysis", "runner"}),  # many runs of the public objects
    "cli": frozenset({"_version", "api", "runner", "scene", "record", "sweeps"}),  # not physics: it is in api
    "__init__": frozenset({"_version", "api", "record", "sweeps"}),
    "__main__": frozenset({"cli"}),
}


# Optional third-party engines: the one module of rbcli that may import each, always inside a function
# (lazily), so rbcli imports and runs without them (mujoco is the `[bench]` extra: the study's MuJoCo rows).
OPTIONAL_ENGINE_OWNERS: dict[str, str] = {
    "mujoco": "rbcli/runner/mujoco_twin.py",
}


def _parts() -> set[str]:
    """rbcli's subpackages and top-level modules, from the tree."""
    packages = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    return packages | {p.stem for p in PACKAGE.glob("*.py")}


def _part_of(module: str, parts: set[str]) -> str | None:
    """The part of rbcli a dotted name lies in (None outside rbcli): `rbcli.physics.step` -> physics;
    `rbcli` itself, or a name defined in rbcli/__init__.py, -> __init__."""
    names = module.split(".")
    if names[0] != "rbcli":
        return None
    return names[1] if len(names) > 1 and names[1] in parts else "__init__"


def _imported_names(path: Path) -> Iterator[tuple[str, int]]:
    """(dotted name, line) of everything the file imports; `from a import b` gives a.b; relative
    imports resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join([*package[: len(package) - node.level + 1], *filter(None, [node.module])])
            for alias in node.names:
                yield (base if alias.name == "*" else f"{base}.{alias.name}"), node.lineno


def _imports_between_parts() -> list[tuple[str, str, str]]:
    """(importing part, imported part, file:line) for every import of one part of rbcli by another."""
    parts = _parts()
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        source = _part_of(".".join(path.relative_to(ROOT).with_suffix("").parts), parts)
        for name, line in _imported_names(path):
            target = _part_of(name, parts)
            if target is not None and target != source:
                found.append((str(source), target, f"{path.relative_to(ROOT)}:{line}"))
    return found


def test_every_part_of_rbcli_has_a_rule():
    assert _parts() == set(ALLOWED_IMPORTS), "give each new part of rbcli a line in ALLOWED_IMPORTS"


def test_the_rules_are_layers():
    """No cycle, even through several parts: the table is an order, top (cli) to bottom (physics)."""
    try:
        order = list(TopologicalSorter(ALLOWED_IMPORTS).static_order())
    except CycleError as exc:
        pytest.fail(f"ALLOWED_IMPORTS has a cycle: {exc.args[1]}")
    assert order.index("physics") < order.index("scene") < order.index("runner") < order.index("api")
    assert order.index("api") < order.index("cli") < order.index("__main__")


def test_each_part_imports_only_the_parts_below_it():
    wrong = [
        f"{where}: {source} imports {target} (allowed: {', '.join(sorted(ALLOWED_IMPORTS[source])) or 'nothing'})"
        for source, target, where in _imports_between_parts()
        if target not in ALLOWED_IMPORTS[source]
    ]
    assert not wrong, "\n".join(wrong)


def test_cli_does_not_import_physics_directly():
    """cli parses arguments and calls rbcli.api (or runner, scene, record); the integrator registry and
    the kernels reach it only through them."""
    direct = [where for source, target, where in _imports_between_parts() if (source, target) == ("cli", "physics")]
    assert not direct, f"rbcli/cli imports rbcli.physics at {', '.join(direct)}; go through rbcli.api"
    assert {source for source, target, _ in _imports_between_parts() if target == "cli"} == {"__main__"}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_only(tree: ast.Module) -> set[int]:
    """ids of the nodes under `if TYPE_CHECKING:` (never run: they serve the annotations)."""
    inside: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            inside.update(id(n) for statement in node.body for n in ast.walk(statement))
    return inside


@functools.cache
def _module_imports() -> dict[str, dict[str, str]]:
    """module -> {imported rbcli module: file:line} for every import of one rbcli module by another that
    runs: at module level or inside a function (a lazy import between two rbcli modules that need each
    other is still a circle, whichever loads first; the house defers heavy third-party libraries that
    way, never its own order), but not under TYPE_CHECKING. `from a.b import c` names the module a.b.c
    when there is one, else a.b. A module's own packages are left out: Python has run them before it."""
    paths = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}

    def module_of(name: str) -> str | None:
        while name and name not in paths:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, dict[str, str]] = {}
    for module, path in paths.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        skipped = _type_checking_only(tree)
        edges = graph.setdefault(module, {})
        for node in ast.walk(tree):
            if id(node) in skipped or not isinstance(node, ast.Import | ast.ImportFrom):
                continue
            for name, line in _imported_names_of(node, path):
                target = module_of(name)
                if target is not None and target != module and not module.startswith(f"{target}."):
                    edges.setdefault(target, f"{path.relative_to(ROOT)}:{line}")
    return graph


def _imported_names_of(node: ast.Import | ast.ImportFrom, path: Path) -> Iterator[tuple[str, int]]:
    if isinstance(node, ast.Import):
        for alias in node.names:
            yield alias.name, node.lineno
        return
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
    base = node.module or ""
    if node.level:
        base = ".".join([*package[: len(package) - node.level + 1], *filter(None, [node.module])])
    for alias in node.names:
        yield (base if alias.name == "*" else f"{base}.{alias.name}"), node.lineno


def test_no_import_circles_between_modules():
    """Every import inside rbcli runs one way: no module imports (directly or through others) a module
    that imports it. Circles hide order bugs (a name used before its module has finished) and make two
    modules one."""
    graph = _module_imports()
    try:
        list(TopologicalSorter({m: set(edges) for m, edges in graph.items()}).static_order())
    except CycleError as exc:
        circle = exc.args[1][::-1]  # graphlib lists it against the edges' direction
        steps = [f"{a} imports {b} ({graph[a][b]})" for a, b in zip(circle, circle[1:], strict=False)]
        pytest.fail("an import circle: " + "; ".join(steps))


def test_the_circle_test_sees_lazy_imports():
    """The finder sees imports inside functions and skips TYPE_CHECKING ones (on this very tree)."""
    graph = _module_imports()
    assert "rbcli.runner.loop" in graph["rbcli.runner.simulation"]  # inside Simulation.run
    assert "rbcli.scene.checks" in graph["rbcli.scene.compile"]  # inside CompiledScene.warnings
    assert "rbcli.scene.compile" not in graph["rbcli.scene.checks"]  # under TYPE_CHECKING only


def _modules_after(code: str) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", code + "\nimport sys; print('\\n'.join(sys.modules))"],
        capture_output=True, text=True, check=True, cwd=ROOT,
    )  # fmt: skip
    return set(out.stdout.split())


def test_physics_imports_only_numpy_and_numba():
    code = (
        "import pkgutil, importlib, rbcli.physics as p\n"
        "for m in pkgutil.walk_packages(p.__path__, 'rbcli.physics.'): importlib.import_module(m.name)"
    )
    loaded = _modules_after(code)
    rbcli_outside = {m for m in loaded if m.startswith("rbcli.") and not m.startswith("rbcli.physics")}
    assert rbcli_outside <= {"rbcli._version"}, rbcli_outside
    # (yaml and scipy are not on the list: numba itself imports them when they are installed)
    for banned in ("rerun", "mcap", "typer", "rich", "jsonschema", "google.protobuf"):
        assert banned not in loaded, f"rbcli.physics imported {banned}"


# what physics/contact/ may import besides itself: the one-body rotation kernels, the kernel options and
# the kernel cache's guard and linker (they import nothing of rbcli), nothing that uses contact (forces,
# integrators, the pipeline) and no kinematic bodies (physics/kinematic.py)
CONTACT_MAY_IMPORT = (
    "rbcli.physics.rotation",
    "rbcli.physics.rotation_kernels",
    "rbcli.physics.step",
    "rbcli.physics.kernel_cache",
    "rbcli.physics.kernel_link",
)


def test_contact_imports_nothing_above_it():
    wrong = [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for path in sorted((PACKAGE / "physics" / "contact").glob("*.py"))
        for name, line in _imported_names(path)
        if name.startswith("rbcli.")
        and not name.startswith("rbcli.physics.contact.")
        and not any(name == allowed or name.startswith(allowed + ".") for allowed in CONTACT_MAY_IMPORT)
    ]
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("heavy", ["numba", "rerun", "mcap"])
def test_cli_front_door_does_not_import_heavy_libraries(heavy):
    assert heavy not in _modules_after("import rbcli.cli.app")


def test_help_and_version_work():
    out = subprocess.run([sys.executable, "-m", "rbcli", "--help"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0 and "run" in out.stdout and "validate" in out.stdout
    out = subprocess.run([sys.executable, "-m", "rbcli", "--version"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0 and out.stdout.startswith("rbsim ")


def test_code_is_lint_clean():
    ruff = [sys.executable, "-m", "ruff"]
    lint = subprocess.run([*ruff, "check", "rbcli", "tests", "benchmarks"], capture_output=True, text=True, cwd=ROOT)
    assert lint.returncode == 0, lint.stdout
    fmt = subprocess.run([*ruff, "format", "--check", "rbcli", "tests", "benchmarks"], capture_output=True,
                         text=True, cwd=ROOT)  # fmt: skip
    assert fmt.returncode == 0, fmt.stdout


def test_package_type_checks():
    """mypy on rbcli/ (settings in pyproject.toml), as STYLE.md asks."""
    out = subprocess.run([sys.executable, "-m", "mypy"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-4000:]


@pytest.mark.parametrize("engine", sorted(OPTIONAL_ENGINE_OWNERS))
def test_optional_engines_are_imported_by_their_owner_only_and_lazily(engine):
    """Static: only the owner imports the engine, and only inside a function body; at run time: the
    owner and the study import without loading it."""
    owner = OPTIONAL_ENGINE_OWNERS[engine]
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=rel)
        top_level = {id(node) for node in tree.body}
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            if any(name.split(".")[0] == engine for name in names):
                assert rel == owner, f"{rel}:{node.lineno} imports {engine}; only {owner} may"
                assert id(node) not in top_level, f"{rel}:{node.lineno} imports {engine} at module level"
    module = owner.removesuffix(".py").replace("/", ".")
    assert engine not in _modules_after(f"import {module}, rbcli.runner.study, rbcli.cli.study")
