"""The core package never imports an outer layer or an adapter's library (STYLE rule 1)."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = {"fusion", "drivers", "filterpy", "gtsam", "serial", "cv2", "matplotlib", "numba"}
APPLICATION = {"cli.py", "experiments.py"}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


CORE = [p for p in sorted((ROOT / "lti_motion").rglob("*.py"))
        if p.name not in APPLICATION and "experiments" not in p.parts]


@pytest.mark.parametrize("path", CORE, ids=lambda p: str(p.relative_to(ROOT)))
def test_core_module_imports_only_numpy_scipy_and_itself(path):
    assert not (_imports(path) & FORBIDDEN), f"{path.name} imports {_imports(path) & FORBIDDEN}"


@pytest.mark.parametrize("outer", ["fusion", "drivers"])
def test_fusion_and_drivers_do_not_import_each_other(outer):
    other = {"fusion": "drivers", "drivers": "fusion"}[outer]
    for path in (ROOT / outer).rglob("*.py"):
        assert other not in _imports(path), f"{path} imports {other}"
