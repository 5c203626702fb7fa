"""The layers of ``docs/architecture.md``, checked by package (layers go one way).

- the core (``lti_motion`` outside ``lti_motion.app``) imports numpy, scipy and itself:
  neither ``fusion`` nor ``drivers``, nor an adapter's library;
- ``fusion`` and ``drivers`` never import each other;
- nothing in the three packages imports ``lti_motion.app``, the application; the
  examples (what users copy) import from it only the route harness
  ``lti_motion.app.route``, the public evaluation on the simulator (``docs/route.md``);
- no package holds an import cycle among its modules (deferred imports included);
- the core's wings follow the flow of data: ``recordings`` and ``model`` stand on the
  base alone, ``calibration`` on the base, ``recordings`` and ``model``; the base imports
  no wing (its door only names them);
- a package keeps few top-level modules besides its wings (the folders show the flow).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("lti_motion", "fusion", "drivers")
ADAPTERS = {"fusion", "drivers", "filterpy", "gtsam", "serial", "cv2", "matplotlib", "numba",
            "rosbags"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """Every absolute module an import statement names, anywhere in the file (also deferred
    imports inside functions); ``from pkg import name`` counts ``pkg.name`` too, in case
    ``name`` is a module."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _package_files(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _in_app(name: str) -> bool:
    return name == "lti_motion.app" or name.startswith("lti_motion.app.")


CORE = [p for p in _package_files("lti_motion") if not _in_app(_module_name(p))]


@pytest.mark.parametrize("path", CORE, ids=lambda p: str(p.relative_to(ROOT)))
def test_core_imports_only_numpy_scipy_and_itself(path):
    top = {name.split(".")[0] for name in _imports(path)}
    assert not top & ADAPTERS, f"{path.name} imports {sorted(top & ADAPTERS)}"


@pytest.mark.parametrize("outer", ["fusion", "drivers"])
def test_fusion_and_drivers_do_not_import_each_other(outer):
    other = {"fusion": "drivers", "drivers": "fusion"}[outer]
    offenders = [str(p.relative_to(ROOT)) for p in _package_files(outer)
                 if other in {name.split(".")[0] for name in _imports(p)}]
    assert not offenders, f"{outer} modules import {other}: {offenders}"


@pytest.mark.parametrize("where", PACKAGES)
def test_nothing_outside_the_application_imports_it(where):
    offenders = [str(p.relative_to(ROOT)) for p in sorted((ROOT / where).rglob("*.py"))
                 if not _in_app(_module_name(p)) and any(map(_in_app, _imports(p)))]
    assert not offenders, f"these import lti_motion.app: {offenders}"


EXAMPLE_APP_IMPORTS = {"lti_motion.app", "lti_motion.app.route"}


@pytest.mark.parametrize("path", sorted((ROOT / "examples").glob("*.py")),
                         ids=lambda p: p.name)
def test_examples_import_from_the_application_only_the_route_harness(path):
    app = {name for name in _imports(path) if _in_app(name)}
    # ``from lti_motion.app.route import X`` also names ``lti_motion.app.route.X``
    outside = {name for name in app if name not in EXAMPLE_APP_IMPORTS
               and not name.startswith("lti_motion.app.route.")}
    assert not outside, f"{path.name} imports application modules {sorted(outside)}"


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of a directed graph, or None (depth-first search)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_cycle_finder_finds_a_cycle_and_accepts_a_tree():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle_between_modules(package):
    """A package's ``__init__`` (its door) may import its modules; no module may import
    its way back to itself through the others."""
    modules = {_module_name(p): p for p in _package_files(package)}
    doors = {name for name, p in modules.items() if p.name == "__init__.py"}
    graph = {}
    for name, path in modules.items():
        if name in doors:
            continue
        targets = set()
        for imported in _imports(path):
            # a module imported through its door counts as the module itself
            while imported and imported not in modules:
                imported = imported.rpartition(".")[0]
            if imported and imported != name and imported not in doors:
                targets.add(imported)
        graph[name] = targets
    assert _cycle(graph) is None, f"import cycle: {' -> '.join(_cycle(graph))}"


CORE_WINGS = {"lti_motion.recordings": set(), "lti_motion.model": set(),
              "lti_motion.calibration": {"lti_motion.recordings", "lti_motion.model"}}


def _wing(name: str) -> str | None:
    return next((w for w in (*CORE_WINGS, "lti_motion.app")
                 if name == w or name.startswith(w + ".")), None)


@pytest.mark.parametrize("path", CORE, ids=lambda p: str(p.relative_to(ROOT)))
def test_core_wings_follow_the_flow_of_data(path):
    """recordings -> calibration <- model, all on the base; the base imports no wing."""
    name = _module_name(path)
    own = _wing(name)
    if path.name == "__init__.py" and own is None:
        return                                  # the package door names every wing
    allowed = CORE_WINGS.get(own, set()) | ({own} if own else set())
    reached = {w for imported in _imports(path) if (w := _wing(imported))}
    assert reached <= allowed, f"{name} imports the wings {sorted(reached - allowed)}"


@pytest.mark.parametrize(("package", "most"), [("lti_motion", 12), ("drivers", 6),
                                               ("fusion", 8)])
def test_few_top_level_modules_besides_the_wings(package, most):
    modules = sorted(p.stem for p in (ROOT / package).glob("*.py") if p.name != "__init__.py")
    assert len(modules) <= most, f"{package} has {len(modules)} top-level modules: {modules}"
    wings = [p.name for p in (ROOT / package).iterdir() if (p / "__init__.py").is_file()]
    assert wings, f"{package} has no wings"


def _door_names() -> dict[str, set[str]]:
    """Each wing's door and the names it re-exports (its ``__all__``)."""
    doors = {}
    for init in ROOT.glob("*/*/__init__.py"):
        name = _module_name(init)
        if name.split(".")[0] in PACKAGES and not _in_app(name):
            tree = ast.parse(init.read_text())
            for node in tree.body:
                if isinstance(node, ast.Assign) and any(
                        getattr(t, "id", None) == "__all__" for t in node.targets):
                    doors[name] = set(ast.literal_eval(node.value))
    return doors


USERS = sorted([*(ROOT / "lti_motion" / "app").glob("*.py"), *(ROOT / "examples").glob("*.py")])


@pytest.mark.parametrize("path", USERS, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_application_and_the_examples_enter_wings_through_their_doors(path):
    """``from lti_motion.model import MotionModel``, not ``from lti_motion.model.motion_model
    import MotionModel``: a name the door re-exports is imported from the door."""
    doors = _door_names()
    behind = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            door = node.module.rpartition(".")[0]
            public = doors.get(door, set())
            behind += [f"{node.module}.{a.name}" for a in node.names if a.name in public]
    assert not behind, f"{path.name} imports past the door: {behind}"
