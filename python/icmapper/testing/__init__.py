"""Test and demo helpers that ship with the package but are not part of the runtime pipeline.

- ``icmapper.testing.clips``: tiny random clips in the ``ClipDataset`` item format
  (``SyntheticClips``, ``collate_clips``, ``default_rig``); the training config's
  ``data.source = "synthetic:N"`` builds them (imported lazily by the training loop).
- ``icmapper.testing.nuscenes_fixture``: ``write_nuscenes_fixture`` writes a tiny nuScenes-format
  dataset to disk.
- ``icmapper.testing.vectorise_reference``: the former Python vectoriser (numpy / scipy /
  scikit-image / shapely), the oracle of the engine's vectoriser in tests and benchmarks.
- ``icmapper.testing.geom_reference``: the shapely / numpy patch polygon and world <-> ego
  transforms, the oracle of the geometry tests and the reference of ``benchmarks/geometry.py``;
  ``icmapper.testing.geom_calls``: every engine function that takes points, as one table of calls
  (``point_entry_points``) for the input-contract and hardening tests.
- ``icmapper.testing.devkits``: the official devkits as test oracles (``require_devkit``);
  ``icmapper.testing.required``: when a missing test tool skips a test and when it fails it
  (``CI=true``, or its distribution installed but broken).

Nothing in the runtime package imports this package at module level, and this ``__init__`` imports
nothing (``clips`` needs torch).
"""
