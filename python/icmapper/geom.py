"""The Python face of the native geometry functions (``icmapper._icmap``, Rust ``icmap-geom``).

Thin re-exports: conversion, validation and GIL release happen in the extension. Inputs are
``(n, 2)`` array-likes of a real dtype (float64/float32 read directly, integers and nested
sequences converted); outputs are float64 numpy arrays. A ``pose`` is ``(x, y, yaw)`` ego -> world,
``half_extents`` is ``(hx, hy)`` along the ego axes. Bad input raises ``ValueError`` (values,
shapes), ``TypeError`` (dtypes, types), never returns garbage. See ``_icmap.pyi`` for the full
typed contract.

Functions
---------
resample(points (n, 2), n, closed=False) -> (n, 2)
    Exactly ``n`` points evenly spaced by arc length.
resample_spacing(points (n, 2), spacing=1.0, closed=False) -> (m, 2)
    Points about ``spacing`` metres apart.
clip_to_patch(points (n, 2), pose, half_extents, margin=0.0, closed=False) -> list[(m, 2)]
    Pieces inside the oriented patch, same frame as the input (closed: ``[ring]`` or ``[]``).
fit_curve(points (n, 2), s=0.5, spacing=1.0) -> (m, 2)
    Smoothing cubic spline with scipy ``splprep(s=s)`` semantics, evaluated ~``spacing`` apart.
merge_polyline(global_pts (n, 2), detected_pts (d, 2), s=0.5, spacing=1.0) -> (m, 2)
    IC-Mapper Algorithm 2: reorder, concatenate, fit; keeps the global direction.
polygon_union(rings: list[(n_i, 2)]) -> list[(m, 2)]
    Outer rings of the union, counter-clockwise, largest first.
chamfer_distance(a (n, 2), b (m, 2)) -> float
    (mean nearest distance a->b + mean b->a) / 2.
chamfer_matrix(a: (A, n, 2) | list[(n_i, 2)], b: ...) -> (A, B)
    All pairwise Chamfer distances.
GlobalMap
    The global vector map store (also ``icmapper.GlobalMap``).
"""

from __future__ import annotations

from icmapper._icmap import (
    GlobalMap,
    chamfer_distance,
    chamfer_matrix,
    clip_to_patch,
    fit_curve,
    merge_polyline,
    polygon_union,
    resample,
    resample_spacing,
)

__all__ = [
    "GlobalMap",
    "chamfer_distance",
    "chamfer_matrix",
    "clip_to_patch",
    "fit_curve",
    "merge_polyline",
    "polygon_union",
    "resample",
    "resample_spacing",
]
