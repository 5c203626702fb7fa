"""Speed and accuracy benchmarks: ``python -m benchmarks [NAME ...] --json PATH``.

Each benchmark module registers functions with :func:`benchmarks.harness.benchmark`;
see :mod:`benchmarks.harness` for the record format.
"""
