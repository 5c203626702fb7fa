"""Declare what we test: no dependency range admits a release series the suite did not run on.

CI installs the newest version each range allows, so the installed version is
the tested one. A range may not reach past its series (a new major release,
or for 0.x packages and gtsam a new minor one, whose 4.2 and 4.3 differ in
their Python API), nor back into an older major one (OpenCV 4 beside the
tested 5). The lower bounds themselves, the oldest versions the code runs
with, were checked by running the suite on them (see pyproject.toml). These
tests read the environment CI installs; in one built on the lower bounds the
first reports, correctly, that those are not the newest series.
"""

import re
import tomllib
from importlib.metadata import version
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Packages whose minor releases change their API although their major is not 0.
MINOR_SERIES = {"gtsam"}
_SPEC = re.compile(r"^([A-Za-z0-9_.-]+)>=([0-9.]+),<([0-9.]+)$")


def _numbers(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.findall(r"\d+", text)[:3])


def _ranges() -> list[tuple[str, str, tuple[int, ...], tuple[int, ...]]]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    out = []
    for req in [*project["dependencies"], *project["optional-dependencies"]["dev"]]:
        m = _SPEC.match(req)
        assert m, f"{req}: write it as name>=LOW,<HIGH"
        out.append((req, m.group(1), _numbers(m.group(2)), _numbers(m.group(3))))
    return out


def _series(name: str, v: tuple[int, ...]) -> tuple[int, ...]:
    return v[:2] if v[0] == 0 or name in MINOR_SERIES else v[:1]


def _next_series(name: str, v: tuple[int, ...]) -> tuple[int, ...]:
    s = _series(name, v)
    return (*s[:-1], s[-1] + 1)


def test_no_range_admits_a_newer_series_than_the_tested_one():
    bad = [f"{req}: the tested {name} is {version(name)}, so the upper bound is "
           f"<{'.'.join(map(str, _next_series(name, _numbers(version(name)))))}"
           for req, name, _, high in _ranges()
           if high != _next_series(name, _numbers(version(name)))]
    assert not bad, "\n".join(bad)


def test_no_range_admits_an_older_major_series_than_the_tested_one():
    def major(name: str, v: tuple[int, ...]) -> tuple[int, ...]:
        return v[:2] if name in MINOR_SERIES else v[:1]

    bad = [f"{req}: {name} {version(name)} is tested; the lower bound is in an older series"
           for req, name, low, _ in _ranges()
           if major(name, low) != major(name, _numbers(version(name)))]
    assert not bad, "\n".join(bad)


def test_the_installed_versions_are_inside_the_declared_ranges():
    bad = [f"{name} {version(name)} is installed; {req} is declared"
           for req, name, low, high in _ranges()
           if not low <= _numbers(version(name)) < high]
    assert not bad, "\n".join(bad)
