"""Map instances from the dense BEV segmentation (HDMapNet-style vectorisation).

The segmentation head (``models.segmentation``) reads the BEV far better than the set decoder
(checkpoint README: IoU 80-84 % against decoder AP 10-32), so the detector can take its instances
from the masks instead (``model.instances = "segmentation"``):

- the class probabilities (K, X, Y) are upsampled ``upsample`` times (bilinear) and thresholded;
- a divider mask is the ridge of its probabilities (``ridge_classes``): cells above
  ``ridge_threshold`` where the probability curves downwards across the line (the smaller
  eigenvalue of its Hessian, at scale ``ridge_sigma``, below -``ridge_curvature``). Dividers of
  neighbouring lanes lie 2-3 BEV cells apart, and at the plain threshold their masks merge into one
  blob whose skeleton wanders between them; the valley between two lines curves upwards, so the
  ridge keeps them apart (validation AP_div 57.9 -> 66.7, checkpoint README);
- a divider or boundary mask is thinned to its skeleton (Zhang-Suen, as scikit-image); the
  skeleton is cut at its junctions into branches, each branch is ordered into a polyline. A line
  goes on through a junction: the two branch ends there that continue each other most straightly
  (within ``through`` degrees) are joined, and a branch shorter than ``spur`` that ends at a
  junction without continuing is a spur and is dropped (lane lines and kerbs do not branch: cut
  at every junction, one line became pieces and stubs; validation mAP 75.4 -> 77.9, sim:val:12,
  docs/mapping.md). Each line is simplified and resampled to P points; lines shorter than
  ``min_length`` metres are dropped;
- a ridge line is cut where it bends sharply (``bend``, 45 degrees, measured over ``BEND_ARC``,
  1.5 m, on either side of a vertex of the simplified line; pieces under ``min_length`` dropped,
  each piece scored by its own cells): a painted lane line curves gently, so such a corner is
  a skeleton that ran from one line across the lanes or into another (sim:val:32: divider pieces
  per true line 1.44 -> 1.33, docs/mapping.md, "Lane lines bend gently");
- a band of kerb probability as wide as two kerbs (a median island's, merged on the coarse grid)
  is drawn as its outline shrunk by the targets' line radius, not its skeleton (``band``: a
  component whose skeleton lies farther than ``band * shrink`` from the mask's edge over at least
  half its cells; the cells farther than ``shrink`` from the edge, those of them with a
  4-neighbour inside the grid outside them, cut into branches as a skeleton is): a frame that sees
  the island's nose gives one line round it, as the ground truth holds its kerb
  (docs/mapping.md, "Kerbs round median islands");
- a ridge line along the front or back edge of the grid is dropped (``edge_margin``,
  ``edge_span``): the ridge's Gaussian reads zeros past the grid, so lane lines entering or leaving
  the range leave a ridge across the lanes at the edge, one per frame, moving with the car
  (sim:val:12: 39 of 42 such detections on no true line; divider pieces 1.54 -> 1.40 per true
  line, ID switches 2.19 -> 2.08, mAP unchanged; docs/mapping.md);
- each connected crossing mask becomes the convex hull of its cells (grown by half a cell,
  simplified by ``hull_simplify``; or their minimum rotated rectangle), shrunk by the target's
  line radius (the targets mark cells within that radius of the contour), resampled to P points
  along its closed contour; a mask of several touching crossings (around an intersection,
  or meeting at a corner) is first cut into one part per crossing (the engine's
  ``crossings::crossing_parts``);
- an instance's score is the mean probability of its cells (its skeleton for lines).
- optionally (``subcell``, per line class) each line point then moves across its line to the
  maximum of its class's probabilities between the cells (``models.subcell``, in Python after the
  engine's work): a skeleton runs through cell centres, the paint need not.

The work runs in the native engine (``icmapper._icmap.vectorise``, Rust ``icmap_geom::vectorise``,
one operation per file there), with the GIL released and the classes of a frame in parallel; this
module holds the settings, the result type and the argument checks. The former Python
implementation (numpy / scipy / scikit-image / shapely) is ``icmapper.testing.vectorise_reference``,
the oracle of the engine's tests (same instances on recorded masks of the shipped checkpoint) and
of ``python -m benchmarks vectorise``; it is not part of the runtime.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.models.subcell import subcell_lines

#: Class index of crossings (closed contours); the other classes are open polylines.
CROSSING = 0
#: Class index of dividers (the default ``ridge_classes``).
DIVIDER = 1
#: Metres of a line on either side of a vertex over which ``VectoriseParams.bend`` measures its
#: turn (the engine's ``vectorise::bend::BEND_ARC``).
BEND_ARC = 1.5
#: Whether ``vectorise`` runs the classes of a frame at once on the engine's thread pool (the
#: result is the same either way). Back to back it pays (1.4-1.6x, ``python -m benchmarks
#: vectorise``); inside ``Mapper.step`` it does not: the pool's threads fall asleep during the
#: network between frames and waking them costs more than the classes gain (sim:val:2 on 2
#: cores: 0.88-1.02 ms/frame in parallel against 0.60-0.62 serial; BENCHMARKS.md).
PARALLEL_CLASSES = False


@dataclass(frozen=True)
class VectoriseParams:
    """Settings of ``vectorise`` (metres unless said)."""

    upsample: int = 4  # bilinear upsampling of the probabilities before thresholding
    threshold: float = 0.5  # probability above which a cell belongs to the class
    min_length: float = 2.0  # shorter line branches are dropped
    min_area: float = 2.0  # smaller crossing components (m^2) are dropped
    shrink: float | None = None  # crossing outlines shrink by this; None: the target's line
    # radius on the probabilities' grid (``segmentation.target_line_radius``: 0.9 m on 1.2 m cells)
    rectangularity: float = 0.6  # a crossing mask filling less of its rectangle is split (0: never)
    corner_tolerance: float = 2.0  # Douglas-Peucker tolerance that finds a split mask's corners
    hull_simplify: float = 0.5  # a crossing's outline: the convex hull of its cells simplified
    # by this tolerance (0: their minimum rotated rectangle), then shrunk by ``shrink``
    max_hole: float = 2.0  # a crossing mask around a hole of larger inscribed radius is split
    simplify: float = 0.2  # Douglas-Peucker tolerance of line branches before resampling
    through: float = 45.0  # degrees; a line goes on through a skeleton junction where two
    # branches continue each other within this of straight (0: lines are cut at junctions)
    spur: float = 4.0  # a branch ending at a junction without continuing there, shorter than
    # this, is a spur and is dropped
    ridge_classes: tuple[int, ...] = (DIVIDER,)  # line classes whose mask is their ridge
    ridge_threshold: float = 0.3  # probability above which a ridge cell may belong to the class
    ridge_sigma: float = 0.6  # metres; Gaussian scale of the Hessian
    ridge_curvature: float = 0.22  # 1/m^2; a ridge curves down across the line by more than this
    num_points: int = 20  # points per instance
    edge_margin: float = 1.5  # a ridge-class line within this of the front or back edge of the
    # grid over most of its points, spanning more than ``edge_span`` across it, is dropped (0: kept)
    edge_span: float = 3.0
    bend: float = 45.0  # degrees; a ridge-class line turning by more than this within
    # ``BEND_ARC`` metres on either side of a vertex is cut there (0: never)
    band: float = 1.8  # a component of a line class that is not a ridge class (the kerbs) whose
    # skeleton lies farther than ``band * shrink`` from its edge over at least half its cells is
    # two kerbs merged (a median island): drawn as its outline shrunk by ``shrink`` (0: never)
    subcell: tuple[int, ...] | None = None  # line classes whose points then move across the line
    # to the probabilities' maximum between the cells (``models.subcell``); None: the detector's
    # (``model.subcell``; none when called without one)

    def __post_init__(self) -> None:
        if self.subcell is not None:  # a list from TOML / JSON
            object.__setattr__(self, "subcell", tuple(self.subcell))
        if self.upsample < 1 or self.num_points < 2:
            raise ValueError("vectorise: upsample must be >= 1 and num_points >= 2")
        for key in ("threshold", "ridge_threshold"):
            if not 0.0 < getattr(self, key) < 1.0:
                raise ValueError(f"vectorise: {key} must be in (0, 1), got {getattr(self, key)}")
        if not self.ridge_sigma > 0 or not np.isfinite(self.ridge_sigma):
            raise ValueError(f"vectorise: ridge_sigma must be > 0, got {self.ridge_sigma}")
        for key in ("ridge_classes", "subcell"):
            chosen = getattr(self, key) or ()
            if not all(isinstance(k, int) and k >= 0 and k != CROSSING for k in chosen):
                raise ValueError(
                    f"vectorise: {key} must be line class indices, got {getattr(self, key)}"
                )
        if not 0.0 <= self.rectangularity <= 1.0:
            raise ValueError(
                f"vectorise: rectangularity must be in [0, 1], got {self.rectangularity}"
            )
        if not 0.0 <= self.bend <= 180.0:
            raise ValueError(f"vectorise: bend must be in [0, 180] degrees, got {self.bend}")
        if not 0.0 <= self.through <= 90.0:
            raise ValueError(f"vectorise: through must be in [0, 90] degrees, got {self.through}")
        if self.shrink is not None and not self.shrink >= 0:
            raise ValueError(f"vectorise: shrink must be >= 0, got {self.shrink}")
        for key in ("min_length", "min_area", "simplify", "corner_tolerance", "max_hole",
                    "hull_simplify", "ridge_curvature", "through", "spur", "edge_margin",
                    "edge_span", "band"):  # fmt: skip
            if not getattr(self, key) >= 0:
                raise ValueError(f"vectorise: {key} must be >= 0, got {getattr(self, key)}")

    def for_grid(self, bev_x: int, bev_y: int, half_x: float, half_y: float) -> VectoriseParams:
        """These settings with the grid-dependent ones resolved for probabilities on (X, Y)
        cells over [-half_x, half_x] x [-half_y, half_y] (``shrink`` None: the target's line
        radius there)."""
        if self.shrink is not None:
            return self
        from icmapper.models.segmentation import target_line_radius

        return replace(self, shrink=target_line_radius(bev_x, bev_y, half_x, half_y))

    def engine_settings(self) -> dict[str, Any]:
        """The settings the engine's ``_icmap.vectorise`` takes, by name: all but ``subcell``,
        a step in Python after the engine's (``models.subcell``)."""
        settings = asdict(self)
        del settings["subcell"]
        return settings


@dataclass(frozen=True)
class VectorInstances:
    """classes (N,) int64; scores (N,) float32 in [0, 1]; points (N, P, 2) float32 ego metres."""

    classes: NDArray[np.int64]
    scores: NDArray[np.float32]
    points: NDArray[np.float32]

    def __len__(self) -> int:
        return int(self.classes.shape[0])


def resample_polyline(line: NDArray[np.float64], n: int, closed: bool) -> NDArray[np.float32]:
    """``n`` points evenly spaced along a polyline (L, 2), or along a closed ring (its first
    point is not repeated) -> (n, 2)."""
    pts = np.vstack([line, line[:1]]) if closed else line
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)  # (L - 1,)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    total = cum[-1]
    d = np.linspace(0.0, total, n + 1)[:-1] if closed else np.linspace(0.0, total, n)
    if total <= 0:
        return np.repeat(pts[:1], n, axis=0).astype(np.float32)
    x = np.interp(d, cum, pts[:, 0])
    y = np.interp(d, cum, pts[:, 1])
    return np.stack([x, y], axis=-1).astype(np.float32)


def vectorise(
    prob: NDArray[np.floating],
    half_x: float,
    half_y: float,
    params: VectoriseParams | None = None,
) -> VectorInstances:
    """Instances of one frame from class probabilities ``prob`` (K, X, Y) in [0, 1] on the BEV
    grid (X cells along ego x over [-half_x, half_x], Y along ego y). Class ``CROSSING`` is closed.
    The probabilities are taken as float32 (the network's dtype). ValueError on a wrong shape or
    non-finite probabilities (the engine checks them)."""
    from icmapper import _icmap

    prob = np.asarray(prob)
    if prob.ndim != 3 or min(prob.shape) < 1:
        raise ValueError(f"vectorise: prob must be (K, X, Y), got {prob.shape}")
    p = (params or VectoriseParams()).for_grid(prob.shape[1], prob.shape[2], half_x, half_y)
    subcell = p.subcell or ()  # a step after the engine's (models.subcell)
    classes, scores, points = _icmap.vectorise(
        np.ascontiguousarray(prob, dtype=np.float32),  # (K, X, Y)
        float(half_x),
        float(half_y),
        **p.engine_settings(),  # the settings by name (the engine checks them)
        parallel=PARALLEL_CLASSES,
    )  # (N,) int64, (N,) float32, (N, P, 2) float32
    if subcell:
        points = subcell_lines(classes, points, prob, half_x, half_y, subcell)  # (N, P, 2)
    return VectorInstances(classes, scores, points)
