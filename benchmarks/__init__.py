"""Benchmark programs of icmapper: each prints measured numbers and ratios, and asserts nothing.

Not part of the installed package: run them from the repository root with
``python -m benchmarks NAME [options]`` (``python -m benchmarks`` lists them). One module per
benchmark, each with ``main(argv) -> int``; ``record_merges`` records the geometry workload's
merges for the Rust replay tool (``python -m benchmarks.record_merges FILE``).
"""
