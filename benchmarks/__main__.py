"""Run benchmarks: ``python -m benchmarks [NAME ...] [--json PATH]``."""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys
from pathlib import Path

import benchmarks
from benchmarks.harness import REGISTRY


def _load_all() -> None:
    for mod in pkgutil.iter_modules(benchmarks.__path__):
        if mod.name.startswith("bench_"):
            importlib.import_module(f"benchmarks.{mod.name}")


def main(argv: list[str] | None = None) -> int:
    _load_all()
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help=f"benchmarks to run (default all): {', '.join(sorted(REGISTRY))}")
    parser.add_argument("--json", type=Path, metavar="PATH", help="write the records here")
    args = parser.parse_args(argv)
    unknown = [n for n in args.names if n not in REGISTRY]
    if unknown:
        parser.error(f"unknown benchmark(s) {unknown}; known: {sorted(REGISTRY)}")
    records = []
    print(f"{'figure':44s} {'value':>12s} {'unit':12s} {'target':>10s} {'meets':6s} "
          f"{'ratio':>8s}  baseline")
    for name in args.names or sorted(REGISTRY):
        print(f"running {name} ...", file=sys.stderr, flush=True)
        for fig in REGISTRY[name]():
            rec = fig.record()
            records.append(rec)
            sign = ">=" if fig.better == "higher" else "<="
            target = "" if fig.target is None else f"{sign}{fig.target:g}"
            ratio = "" if fig.ratio is None else f"{fig.ratio:.3g}"
            print(f"{fig.name:44s} {fig.value:12.4g} {fig.unit:12s} {target:>10s} "
                  f"{fig.meets!s:6s} {ratio:>8s}  {fig.baseline or ''}", flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(records, indent=2) + "\n")
        print(f"wrote {len(records)} records to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
