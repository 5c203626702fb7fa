"""The ```python samples of the README and the user guide pages run, as a reader would run them.

Each page's blocks run in order in one namespace (a later block uses what an earlier one
made), in a temporary working folder. Blocks fenced as ```text or ```sh are not run. No
backend is chosen here: what the samples plot, they draw with matplotlib's
object-oriented API, which needs none.
"""

import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"
PAGES = ["log_format.md", "guide_calibrate_real_robot.md", "guide_filterpy.md",
         "guide_gtsam.md", "guide_alarms.md", "replay.md", "guide_ros_bags.md",
         "guide_ros_config.md"]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


README = "../README.md"


def python_blocks(page: str) -> list[str]:
    """The ```python blocks of ``docs/page``, in order."""
    return BLOCK.findall((DOCS / page).read_text())


def test_the_guide_pages_exist_and_link_from_the_readme():
    readme = (DOCS.parent / "README.md").read_text()
    for page in PAGES:
        assert (DOCS / page).is_file(), page
        assert f"docs/{page}" in readme, page


@pytest.mark.parametrize("page", [README] + [p for p in PAGES if python_blocks(p)])
def test_python_samples_run(page, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": f"docs_{page}"}
    for i, block in enumerate(python_blocks(page)):
        code = compile(block, f"docs/{page} block {i + 1}", "exec")
        exec(code, namespace)                     # the docs' own samples
    assert capsys.readouterr().out                # every page's samples print something
