"""Geometry engine benchmark: the same program as `icmapper bench geometry`.

Run: `.venv/bin/python benchmarks/bench_geometry.py [--sizes 100 1000 10000 100000] [--frames N]`.
"""

from __future__ import annotations

import sys

from icmapper.bench import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
