"""Benchmarks: ``tianim bench NAME``. Each module has ``main(argv) -> int``.

Every benchmark reports ratios against a reference measured in the same run
(a NumPy implementation or a peer library), medians over repeats, and writes
a JSON file with a top-level ``summary`` object when given ``--json PATH``.

The environment benchmark lives with the environments (``python -m envs.bench``):
tianim never imports gymnasium or ``envs``.
"""
