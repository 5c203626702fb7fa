"""Docstring examples print what no BLAS, libm or CPU can change.

A value that is zero only after rounding keeps the sign of whatever tiny
number the machine computed: ``np.round(-1e-17, 6)`` is ``-0.0``. One
OpenBLAS kernel gives ``1e-17`` where another gives ``-1e-17``, so an example
printing such a zero passes on one machine and fails on the next. Examples
therefore add ``+ 0.0`` after rounding (IEEE 754: ``-0.0 + 0.0`` is ``+0.0``)
and never show a negative zero. These tests read every docstring example of
the three packages (no import needed) and check both rules. The other half,
values printed unrounded from BLAS, LAPACK or libm (a norm, an inverse, a
solver's pose) whose last digit may differ, is rounded in the examples by
review; the examples pass under OpenBLAS's Prescott, Haswell, Zen, SkylakeX,
Cooperlake and SapphireRapids kernels (``OPENBLAS_CORETYPE``).
"""

import ast
import doctest
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("lti_motion", "fusion", "drivers")

#: A float zero as Python or NumPy prints it: ``0.0``, ``-0.0``, ``0.``, ``-0.``.
_ZERO = re.compile(r"(?<![\w.])(-?)0\.0*(?![\d])")


def _docstrings(path: Path):
    text = path.read_text(encoding="utf-8")
    if ">>>" not in text:                       # no example: nothing to parse
        return
    tree = ast.parse(text)
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            doc = ast.get_docstring(node, clean=True)
            if doc and ">>>" in doc:
                yield getattr(node, "name", "module"), doc


def _examples():
    parser = doctest.DocTestParser()
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for name, doc in _docstrings(path):
                for ex in parser.get_examples(doc):
                    yield f"{path.relative_to(ROOT).as_posix()}:{name}:{ex.lineno + 1}", ex


EXAMPLES = list(_examples())


def _is_round(node: ast.AST) -> bool:
    """A call of ``round``, ``np.round``, ``np.around`` or ``ndarray.round``."""
    if not isinstance(node, ast.Call):
        return False
    f = node.func
    name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
    return name in ("round", "around")


def _adds_positive_zero(node: ast.AST) -> bool:
    return (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add)
            and any(isinstance(side, ast.Constant) and side.value == 0.0
                    and isinstance(side.value, float) for side in (node.left, node.right)))


def _unguarded_rounds(expr: ast.AST) -> list[str]:
    """Rounding calls in ``expr`` whose result no enclosing ``+ 0.0`` makes sign-safe."""
    found = []

    def visit(node: ast.AST, guarded: bool) -> None:
        if _is_round(node) and not guarded:
            found.append(ast.unparse(node))
        guarded = guarded or _adds_positive_zero(node)
        for child in ast.iter_child_nodes(node):
            visit(child, guarded)

    visit(expr, False)
    return found


def _has_zero(value: object) -> bool:
    if isinstance(value, float):
        return value == 0.0
    if isinstance(value, list | tuple):
        return any(_has_zero(v) for v in value)
    if isinstance(value, dict):
        return any(_has_zero(v) for v in value.values())
    return False


def _pairs(ex: doctest.Example):
    """(expression, shown value or None) per element of a tuple the example prints."""
    try:
        tree = ast.parse(ex.source, mode="eval").body
    except SyntaxError:                     # a statement: prints nothing to check
        return []
    try:
        shown = ast.literal_eval(ex.want.strip())
    except (ValueError, SyntaxError):       # e.g. ``array([...])``: check the text
        return [(tree, None)]
    if isinstance(tree, ast.Tuple) and isinstance(shown, tuple) and len(shown) == len(tree.elts):
        return list(zip(tree.elts, shown, strict=True))
    return [(tree, shown)]


def test_no_example_shows_a_negative_zero():
    bad = [f"{where}: shows {ex.want.strip()}; add + 0.0 to what it prints"
           for where, ex in EXAMPLES if any(m.group(1) for m in _ZERO.finditer(ex.want))]
    assert not bad, "\n".join(bad)


def test_zeros_that_come_from_rounding_are_made_positive():
    bad = []
    for where, ex in EXAMPLES:
        for expr, shown in _pairs(ex):
            zero = _has_zero(shown) if shown is not None else bool(_ZERO.search(ex.want))
            rounds = _unguarded_rounds(expr) if zero else []
            if rounds:
                bad.append(f"{where}: prints a zero made by rounding, whose sign the machine "
                           f"decides; add + 0.0 after {', '.join(rounds)}")
    assert not bad, "\n".join(bad)


def test_the_checks_catch_what_they_are_for():
    """The rules flag the example that failed on another BLAS, and pass its repair."""
    parser = doctest.DocTestParser()
    [before] = parser.get_examples(">>> ekf.speeds.round(3).tolist()\n[0.2, 0.0]\n")
    [after] = parser.get_examples(">>> (ekf.speeds.round(3) + 0.0).tolist()\n[0.2, 0.0]\n")
    [nonzero] = parser.get_examples(">>> x.round(3).tolist()\n[0.2, 1.5]\n")
    [pair] = parser.get_examples(">>> round(a, 6), round(b, 6) + 0.0\n(1.1, 0.0)\n")
    [(expr, shown)] = _pairs(before)
    assert _has_zero(shown) and _unguarded_rounds(expr) == ["ekf.speeds.round(3)"]
    assert not _unguarded_rounds(_pairs(after)[0][0])
    assert not _has_zero(_pairs(nonzero)[0][1])
    assert [_has_zero(v) for _, v in _pairs(pair)] == [False, True]
    assert not _unguarded_rounds(_pairs(pair)[1][0])
    assert [bool(m.group(1)) for m in _ZERO.finditer("[-0.0, 0.0, -0., 10.0, 0.05, -0.5]")] == [
        True, False, True]


def test_the_scan_reads_every_package():
    packages = {where.split("/")[0] for where, _ in EXAMPLES}
    assert packages == set(PACKAGES) and len(EXAMPLES) > 200
