"""What an import costs: each package door resolves every name it lists, and loads only
what the user asked for (docs/architecture.md, Layout).

The checks run in a fresh interpreter and read ``sys.modules``: which modules an
import loads, never how long it takes (the time is a benchmark, ``python -m
benchmarks cli``).
"""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

from lti_motion.lazy import lazy_exports

ROOT = Path(__file__).resolve().parents[1]
DOORS = sorted(".".join(p.parent.relative_to(ROOT).parts)
               for package in ("lti_motion", "fusion", "drivers")
               for p in (ROOT / package).rglob("__init__.py"))


@pytest.mark.parametrize("door", DOORS)
def test_every_name_of_a_package_door_resolves_and_is_listed(door):
    package = importlib.import_module(door)
    names = getattr(package, "__all__", [])
    for name in names:
        assert getattr(package, name) is not None, f"{door}.{name}"
    assert set(names) <= set(dir(package)), f"{door}: dir() misses {set(names) - set(dir(package))}"
    namespace: dict = {}
    exec(f"from {door} import *", namespace)          # the star import a user may write
    assert set(names) <= set(namespace)


def test_lazy_exports_check_the_door_against_its_all():
    with pytest.raises(ValueError, match="must be the same"):
        lazy_exports("pkg", {"json": ("dumps", "loads")}, ["dumps"])
    with pytest.raises(ValueError, match="must be the same"):
        lazy_exports("pkg", {"json": ("dumps",), "pickle": ("dumps",)}, ["dumps"])
    getattr_, _ = lazy_exports("pkg", {"json": ("dumps",)}, ["dumps"])
    with pytest.raises(AttributeError, match="no attribute 'loads'"):
        getattr_("loads")


def loaded_after(code: str, watched: tuple[str, ...]) -> list[str]:
    """The modules of ``watched`` that a fresh interpreter holds after running ``code``."""
    probe = (f"{code}\nimport json, sys\n"
             f"print(json.dumps([m for m in {list(watched)!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


ADAPTERS = ("cv2", "gtsam", "filterpy", "numba", "serial", "matplotlib")
HEAVY = (*ADAPTERS, "scipy.signal", "scipy.stats")


@pytest.mark.parametrize(("code", "absent"), [
    pytest.param(code, absent, id=code) for code, absent in (
        ("import lti_motion", ("numpy", "scipy", *ADAPTERS)),
        ("import fusion", HEAVY),
        ("import drivers", ("numpy", *HEAVY)),
        ("import drivers.sim.config", (*HEAVY, "tomllib")),     # robot files on first use
        ("import lti_motion.model.excitation", HEAVY),
    )])
def test_an_import_loads_only_what_it_needs(code, absent):
    assert loaded_after(code, absent) == []


HELP = """
from lti_motion.app.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
"""


@pytest.mark.parametrize("argv", [["--help"], ["demo", "--help"], ["calibrate", "--help"],
                                  ["replay", "--help"], ["monitor", "--help"],
                                  ["virtual-roomba", "--help"], ["export", "--help"],
                                  ["no-such-command"]],
                         ids=" ".join)
def test_cli_help_loads_no_numerical_machinery(argv):
    assert loaded_after(HELP.format(argv=argv), ("scipy", "tomllib", *HEAVY)) == []


NO_BACKEND = """
import importlib.util, sys
import matplotlib

switched = []
matplotlib.use = lambda *args, **kwargs: switched.append(args)
import lti_motion.app.demo, lti_motion.app.plots, lti_motion.app.replay_plots
for name in ("ekf_plugin", "aruco_end_to_end", "factor_graph", "calibrate_sim"):
    spec = importlib.util.spec_from_file_location(name, f"examples/{name}.py")
    sys.modules[name] = module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
assert not switched, switched
"""


def test_plots_and_examples_choose_no_backend_at_import():
    """The application's plots and the examples draw with matplotlib's object-oriented
    API: importing them neither calls ``matplotlib.use`` nor loads pyplot."""
    assert loaded_after(NO_BACKEND, ("matplotlib.pyplot",)) == []


@pytest.mark.parametrize("door", DOORS)
def test_no_door_re_exports_a_name_of_one_of_its_modules(door):
    """``from pkg import name`` must give the same object whether or not ``pkg.name`` the
    module has been imported: importing a submodule sets it as the package's attribute,
    over a lazily re-exported function of the same name."""
    package = importlib.import_module(door)
    here = Path(package.__file__).parent
    modules = {p.stem for p in here.glob("*.py")} | {p.name for p in here.iterdir()
                                                      if (p / "__init__.py").is_file()}
    assert not set(getattr(package, "__all__", [])) & modules


WINGS = [door for door in DOORS if door.count(".") == 1 and door != "lti_motion.app"]


@pytest.mark.parametrize("door", WINGS)
def test_a_wing_door_re_exports_every_public_name_of_its_modules(door):
    """The doors are the way in (docs/architecture.md, Layout): each lists every name its
    modules declare public, except a module's own name."""
    import ast

    here = ROOT.joinpath(*door.split("."))
    modules = {p.stem for p in here.glob("*.py")}
    public = set()
    for path in here.glob("*.py"):
        if path.name == "__init__.py":
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.Assign, ast.AnnAssign)) and any(
                    getattr(t, "id", None) == "__all__"
                    for t in (node.targets if isinstance(node, ast.Assign) else [node.target])):
                public |= set(ast.literal_eval(node.value))
    listed = set(importlib.import_module(door).__all__)
    assert public - modules <= listed, f"{door} misses {sorted(public - modules - listed)}"
