//! Map instances from dense BEV class probabilities (HDMapNet-style vectorisation).
//!
//! The detector's segmentation head gives per-class probabilities `(K, X, Y)` on the BEV grid
//! (X cells along ego x over `[-half_x, half_x]`, Y along ego y). This module turns one frame of
//! them into instances, one operation per file:
//!
//! - [`upsample`]: bilinear upsampling (torch `interpolate(bilinear, align_corners=False)`);
//! - [`ridge`]: a divider mask is the ridge of its probabilities (Hessian of the Gaussian-smoothed
//!   probabilities, scikit-image `hessian_matrix` + `hessian_matrix_eigvals`);
//! - [`skeleton`]: one-cell-wide skeletons (scikit-image `skeletonize`, Zhang-Suen);
//! - [`raster`]: labelling, hole filling, distance transform (scipy.ndimage semantics);
//! - [`branches`]: a skeleton cut at its junctions into ordered branches, lines joined through
//!   junctions, spurs dropped;
//! - [`simplify`]: topology-preserving Douglas-Peucker (GEOS `TopologyPreservingSimplifier`,
//!   shapely's `simplify`);
//! - [`hull`], [`buffer`], [`principal`]: convex hulls, mitre offsets and principal axes of cell
//!   sets (GEOS / LAPACK semantics);
//! - [`crossings`]: crossing components, cut into one part per crossing, and their outlines;
//! - [`band`]: a band of two kerbs merged (a median island) drawn as its shrunk outline;
//! - [`bend`]: ridge-class lines cut where they turn sharply (a lane line bends gently);
//! - [`edge`]: ridge lines along the front and back edges of the grid (the zero padding's, not
//!   a line's) dropped;
//! - [`polyline`]: arc-length resampling (numpy `interp` semantics) and polyline lengths.
//!
//! It reproduces `icmapper.testing.vectorise_reference` (numpy / scipy / scikit-image / shapely),
//! the former Python implementation, which is the oracle of its tests. What it must not do: read
//! files, know the network, or panic on any input (every failure is a [`GeomError`]).

pub mod band;
pub mod bend;
pub mod branches;
pub mod buffer;
pub mod crossings;
pub mod edge;
pub mod hull;
pub mod polyline;
pub mod principal;
pub mod raster;
pub mod ridge;
pub mod segments;
pub mod simplify;
pub mod skeleton;
pub mod upsample;

use crate::error::{GeomError, Result};
use crate::types::Point;

/// Class index of crossings (closed contours); the other classes are open polylines.
pub const CROSSING: usize = 0;

/// Largest upsampled grid (cells of all classes together) [`vectorise`] accepts: beyond it the
/// work arrays would not fit a reasonable memory budget (the paper's 100x50 BEV at 4x is 240,000).
pub const MAX_CELLS: usize = 1 << 26;

/// Largest `num_points` (points per instance).
pub const MAX_POINTS: usize = 100_000;

/// Settings of [`vectorise`] (metres unless said), as the Python `VectoriseParams`.
#[derive(Debug, Clone, PartialEq)]
pub struct VectoriseParams {
    /// Bilinear upsampling of the probabilities before thresholding.
    pub upsample: usize,
    /// Probability above which a cell belongs to the class (compared in float32).
    pub threshold: f64,
    /// Shorter line branches are dropped.
    pub min_length: f64,
    /// Smaller crossing components (m^2) are dropped.
    pub min_area: f64,
    /// Crossing outlines shrink by this (the target's line radius).
    pub shrink: f64,
    /// A crossing mask filling less of its rectangle is split (0: never).
    pub rectangularity: f64,
    /// Douglas-Peucker tolerance that finds a split mask's corners.
    pub corner_tolerance: f64,
    /// A crossing's outline: the convex hull of its cells simplified by this tolerance (0: their
    /// minimum rotated rectangle), then shrunk by `shrink`.
    pub hull_simplify: f64,
    /// A crossing mask around a hole of larger inscribed radius is split.
    pub max_hole: f64,
    /// Douglas-Peucker tolerance of line branches before resampling.
    pub simplify: f64,
    /// Degrees; a line goes on through a skeleton junction where two branches continue each
    /// other within this of straight (0: lines are cut at junctions).
    pub through: f64,
    /// A branch ending at a junction without continuing there, shorter than this, is dropped.
    pub spur: f64,
    /// Line classes whose mask is their ridge.
    pub ridge_classes: Vec<usize>,
    /// Probability above which a ridge cell may belong to the class.
    pub ridge_threshold: f64,
    /// Metres; Gaussian scale of the Hessian.
    pub ridge_sigma: f64,
    /// 1/m^2; a ridge curves down across the line by more than this.
    pub ridge_curvature: f64,
    /// Points per instance.
    pub num_points: usize,
    /// Metres; a ridge-class line within this of the front or back edge of the grid (and
    /// spanning more than `edge_span` across it) is the padding's ridge and is dropped (0: kept).
    pub edge_margin: f64,
    /// Metres a dropped edge line spans across the edge at least.
    pub edge_span: f64,
    /// Degrees; a ridge-class line turning by more than this within [`bend::BEND_ARC`] metres
    /// on either side of a vertex is cut there (0: never).
    pub bend: f64,
    /// A component of a line class that is not a ridge class (the kerbs) whose skeleton lies
    /// farther than `band` times `shrink` from its edge over at least half its cells is two kerbs
    /// merged into one band (a median island): drawn as its outline shrunk by `shrink` (0: never).
    pub band: f64,
}

impl Default for VectoriseParams {
    fn default() -> Self {
        Self {
            upsample: 4,
            threshold: 0.5,
            min_length: 2.0,
            min_area: 2.0,
            shrink: 0.9,
            rectangularity: 0.6,
            corner_tolerance: 2.0,
            hull_simplify: 0.5,
            max_hole: 2.0,
            simplify: 0.2,
            through: 45.0,
            spur: 4.0,
            ridge_classes: vec![1],
            ridge_threshold: 0.3,
            ridge_sigma: 0.6,
            ridge_curvature: 0.22,
            num_points: 20,
            edge_margin: 1.5,
            edge_span: 3.0,
            bend: 45.0,
            band: 1.8,
        }
    }
}

fn invalid(name: &'static str, reason: String) -> GeomError {
    GeomError::InvalidParameter { name, reason }
}

impl VectoriseParams {
    /// Checks every setting (the Python `VectoriseParams.__post_init__` rules, plus upper bounds
    /// that keep the work finite).
    pub fn validate(&self) -> Result<()> {
        if self.upsample < 1 || self.upsample > 64 {
            return Err(invalid(
                "upsample",
                format!("must be in [1, 64], got {}", self.upsample),
            ));
        }
        if self.num_points < 2 || self.num_points > MAX_POINTS {
            return Err(invalid(
                "num_points",
                format!("must be in [2, {MAX_POINTS}], got {}", self.num_points),
            ));
        }
        for (name, v) in [
            ("threshold", self.threshold),
            ("ridge_threshold", self.ridge_threshold),
        ] {
            if !(v > 0.0 && v < 1.0) {
                return Err(invalid(name, format!("must be in (0, 1), got {v}")));
            }
        }
        if !(self.ridge_sigma > 0.0 && self.ridge_sigma.is_finite()) {
            return Err(invalid(
                "ridge_sigma",
                format!("must be > 0, got {}", self.ridge_sigma),
            ));
        }
        if self.ridge_classes.contains(&CROSSING) {
            return Err(invalid(
                "ridge_classes",
                "must be line class indices (crossings are closed)".into(),
            ));
        }
        if !(0.0..=1.0).contains(&self.rectangularity) {
            return Err(invalid(
                "rectangularity",
                format!("must be in [0, 1], got {}", self.rectangularity),
            ));
        }
        if !(0.0..=180.0).contains(&self.bend) {
            return Err(invalid(
                "bend",
                format!("must be in [0, 180] degrees, got {}", self.bend),
            ));
        }
        if !(0.0..=90.0).contains(&self.through) {
            return Err(invalid(
                "through",
                format!("must be in [0, 90] degrees, got {}", self.through),
            ));
        }
        for (name, v) in [
            ("min_length", self.min_length),
            ("min_area", self.min_area),
            ("shrink", self.shrink),
            ("simplify", self.simplify),
            ("corner_tolerance", self.corner_tolerance),
            ("max_hole", self.max_hole),
            ("hull_simplify", self.hull_simplify),
            ("ridge_curvature", self.ridge_curvature),
            ("spur", self.spur),
            ("edge_margin", self.edge_margin),
            ("edge_span", self.edge_span),
            ("band", self.band),
        ] {
            // NaN fails too; +inf is allowed where Python allows it (it drops everything)
            if v.is_nan() || v < 0.0 {
                return Err(invalid(name, format!("must be >= 0, got {v}")));
            }
        }
        Ok(())
    }
}

/// The instances of one frame: `classes[i]`, `scores[i]` (the mean probability of the
/// instance's cells) and `num_points` points `points[i * num_points..(i + 1) * num_points]` in
/// ego metres (float32, as the network's instances).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VectorInstances {
    /// Class index of each instance.
    pub classes: Vec<i64>,
    /// Score of each instance in [0, 1] for probabilities in [0, 1].
    pub scores: Vec<f32>,
    /// `len() * num_points` points, instance after instance.
    pub points: Vec<[f32; 2]>,
    /// Points per instance.
    pub num_points: usize,
}

impl VectorInstances {
    /// Number of instances.
    pub fn len(&self) -> usize {
        self.classes.len()
    }

    /// Whether there is no instance.
    pub fn is_empty(&self) -> bool {
        self.classes.is_empty()
    }

    fn push(&mut self, class: usize, score: f32, points: Vec<[f32; 2]>) {
        self.classes.push(class as i64);
        self.scores.push(score);
        self.points.extend(points);
    }
}

/// A boolean or numeric raster `(nx, ny)`, row-major (`i` along ego x, `j` along ego y), as a
/// C-ordered numpy array of that shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid<T> {
    /// Cells along the first axis (ego x).
    pub nx: usize,
    /// Cells along the second axis (ego y).
    pub ny: usize,
    /// `nx * ny` values, `data[i * ny + j]`.
    pub data: Vec<T>,
}

impl<T: Copy> Grid<T> {
    /// A grid filled with `value`.
    pub fn filled(nx: usize, ny: usize, value: T) -> Self {
        Self {
            nx,
            ny,
            data: vec![value; nx * ny],
        }
    }

    /// The value at `(i, j)`.
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> T {
        self.data[i * self.ny + j]
    }

    /// Sets the value at `(i, j)`.
    #[inline]
    pub fn set(&mut self, i: usize, j: usize, v: T) {
        self.data[i * self.ny + j] = v;
    }
}

impl Grid<bool> {
    /// The set cells in raster order (numpy `argwhere`).
    pub fn cells(&self) -> Vec<Cell> {
        let mut out = Vec::new();
        for (k, &v) in self.data.iter().enumerate() {
            if v {
                out.push((k / self.ny, k % self.ny));
            }
        }
        out
    }

    /// Whether any cell is set.
    pub fn any(&self) -> bool {
        self.data.iter().any(|&v| v)
    }
}

/// A grid cell `(i, j)`.
pub type Cell = (usize, usize);

/// The metric frame of a grid: cell sizes and the ego-frame extent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Cells along ego x.
    pub nx: usize,
    /// Cells along ego y.
    pub ny: usize,
    /// Half extent along ego x (metres).
    pub half_x: f64,
    /// Half extent along ego y (metres).
    pub half_y: f64,
    /// Cell size along x (metres).
    pub sx: f64,
    /// Cell size along y (metres).
    pub sy: f64,
}

impl Frame {
    /// The frame of an `(nx, ny)` grid over `[-half_x, half_x] x [-half_y, half_y]`.
    pub fn new(nx: usize, ny: usize, half_x: f64, half_y: f64) -> Self {
        Self {
            nx,
            ny,
            half_x,
            half_y,
            sx: 2.0 * half_x / nx as f64,
            sy: 2.0 * half_y / ny as f64,
        }
    }

    /// The centre of cell `c` in ego metres.
    #[inline]
    pub fn metres(&self, c: Cell) -> Point {
        Point::new(
            (c.0 as f64 + 0.5) * self.sx - self.half_x,
            (c.1 as f64 + 0.5) * self.sy - self.half_y,
        )
    }

    /// The centres of `cells` in ego metres.
    pub fn metres_of(&self, cells: &[Cell]) -> Vec<Point> {
        cells.iter().map(|&c| self.metres(c)).collect()
    }
}

/// The float32 mean of `values` as numpy computes it for a float32 array (pairwise summation in
/// float32, then one float32 division).
pub fn mean_f32(values: &[f32]) -> f32 {
    if values.is_empty() {
        return f32::NAN;
    }
    pairwise_sum_f32(values) / values.len() as f32
}

/// numpy's pairwise summation (`pairwise_sum` in `loops_utils.h`: below 8 values in order,
/// up to 128 with eight accumulators, larger halves recursively).
macro_rules! pairwise_sum {
    ($name:ident, $t:ty) => {
        pub(crate) fn $name(a: &[$t]) -> $t {
            let n = a.len();
            if n < 8 {
                let mut res: $t = 0.0;
                for &v in a {
                    res += v;
                }
                res
            } else if n <= 128 {
                let mut r: [$t; 8] = [0.0; 8];
                r.copy_from_slice(&a[..8]);
                let mut i = 8;
                while i < n - (n % 8) {
                    for (k, rk) in r.iter_mut().enumerate() {
                        *rk += a[i + k];
                    }
                    i += 8;
                }
                let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
                for &v in &a[i..] {
                    res += v;
                }
                res
            } else {
                let mut n2 = n / 2;
                n2 -= n2 % 8;
                $name(&a[..n2]) + $name(&a[n2..])
            }
        }
    };
}
pairwise_sum!(pairwise_sum_f32, f32);
pairwise_sum!(pairwise_sum_f64, f64);

/// Instances of one frame from class probabilities `prob` `(K, X, Y)` (`shape`), row-major, on
/// the BEV grid over `[-half_x, half_x] x [-half_y, half_y]`. Class [`CROSSING`] is closed.
///
/// With `parallel`, the classes of the frame are vectorised at once on rayon's pool (each class is
/// independent); the result is the same either way.
///
/// Errors: a wrong length or an empty shape, non-finite probabilities or extents, bad parameters,
/// an upsampled grid larger than [`MAX_CELLS`].
pub fn vectorise(
    prob: &[f32],
    shape: [usize; 3],
    half_x: f64,
    half_y: f64,
    params: &VectoriseParams,
    parallel: bool,
) -> Result<VectorInstances> {
    params.validate()?;
    let [k_num, nx0, ny0] = shape;
    if k_num == 0 || nx0 == 0 || ny0 == 0 {
        return Err(invalid(
            "prob",
            format!("must be (K, X, Y) with no empty axis, got {shape:?}"),
        ));
    }
    let per_class = nx0
        .checked_mul(ny0)
        .ok_or_else(|| invalid("prob", format!("shape {shape:?} is too large")))?;
    let total = per_class
        .checked_mul(k_num)
        .ok_or_else(|| invalid("prob", format!("shape {shape:?} is too large")))?;
    if prob.len() != total {
        return Err(invalid(
            "prob",
            format!("has {} values, shape {shape:?} needs {total}", prob.len()),
        ));
    }
    let u = params.upsample;
    let up_cells = total.checked_mul(u * u).filter(|&c| c <= MAX_CELLS);
    if up_cells.is_none() {
        return Err(invalid(
            "prob",
            format!("upsampled grid of shape {shape:?} x {u}^2 exceeds {MAX_CELLS} cells"),
        ));
    }
    if prob.iter().any(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite {
            what: "probabilities".into(),
        });
    }
    for (name, h) in [("half_x", half_x), ("half_y", half_y)] {
        if !(h.is_finite() && h > 0.0 && h <= crate::types::MAX_COORD) {
            return Err(invalid(
                name,
                format!("must be finite, > 0 and <= 1e7, got {h}"),
            ));
        }
    }
    let frame = Frame::new(nx0 * u, ny0 * u, half_x, half_y);
    let run = |k: usize| -> VectorInstances {
        let src = &prob[k * per_class..(k + 1) * per_class];
        let up = Grid {
            nx: frame.nx,
            ny: frame.ny,
            data: upsample::bilinear(src, nx0, ny0, u),
        };
        vectorise_class(up, k, &frame, params)
    };
    let per: Vec<VectorInstances> = if parallel && k_num > 1 {
        use rayon::prelude::*;
        (0..k_num).into_par_iter().map(run).collect()
    } else {
        (0..k_num).map(run).collect()
    };
    let mut out = VectorInstances {
        num_points: params.num_points,
        ..Default::default()
    };
    for v in per {
        out.classes.extend(v.classes);
        out.scores.extend(v.scores);
        out.points.extend(v.points);
    }
    Ok(out)
}

/// The instances of class `k` from its (upsampled) probabilities `grid` on `frame`'s grid.
pub fn vectorise_class(
    grid: Grid<f32>,
    k: usize,
    frame: &Frame,
    p: &VectoriseParams,
) -> VectorInstances {
    let mut out = VectorInstances {
        num_points: p.num_points,
        ..Default::default()
    };
    let mask = if p.ridge_classes.contains(&k) {
        ridge::ridge_mask(&grid, frame, p)
    } else {
        let t = p.threshold as f32;
        Grid {
            nx: frame.nx,
            ny: frame.ny,
            data: grid.data.iter().map(|&v| v > t).collect(),
        }
    };
    if !mask.any() {
        return out;
    }
    let score = |cells: &[Cell]| -> f32 {
        let vals: Vec<f32> = cells.iter().map(|&(i, j)| grid.at(i, j)).collect();
        mean_f32(&vals)
    };
    if k == CROSSING {
        for (cells, ring) in crossings::crossing_outlines(&mask, frame, p) {
            let pts = polyline::resample_polyline(&ring, p.num_points, true);
            out.push(k, score(&cells), pts);
        }
        return out;
    }
    let ridge = p.ridge_classes.contains(&k);
    let lines = branches::skeleton_branches(&mask, frame, p.min_length, p.through, p.spur);
    let lines = if ridge {
        lines
    } else {
        band::outline_bands(&mask, frame, lines, p)
    };
    for (path, line) in lines {
        let simple = simplify::simplify_line(&line, p.simplify);
        let spans = if ridge {
            bend::cut_at_bends(&simple, p.bend, p.min_length)
        } else {
            vec![(0, simple.len() - 1)]
        };
        // a piece of a cut line is scored by its own cells: those of its vertices' span
        let cells = (spans.len() > 1).then(|| vertex_cells(&line, &simple));
        for (a, b) in spans {
            let pts = polyline::resample_polyline(&simple[a..=b], p.num_points, false);
            if ridge
                && edge::along_front_or_back_edge(&pts, frame.half_x, p.edge_margin, p.edge_span)
            {
                continue;
            }
            let own = match &cells {
                Some(at) => &path[at[a]..=at[b]],
                None => &path[..],
            };
            out.push(k, score(own), pts);
        }
    }
    out
}

/// For each vertex of `simple` (a simplification of `line`, whose vertices are copies of
/// `line`'s points in order) the index of its point in `line`, found forward.
fn vertex_cells(line: &[Point], simple: &[Point]) -> Vec<usize> {
    let mut at = Vec::with_capacity(simple.len());
    let mut k = 0;
    for v in simple {
        while k + 1 < line.len() && line[k] != *v {
            k += 1;
        }
        at.push(k);
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairwise_sum_matches_the_blocked_order() {
        let v: Vec<f32> = (0..300).map(|i| 0.1 + (i as f32) * 1e-3).collect();
        let s = pairwise_sum_f32(&v);
        let exact: f64 = v.iter().map(|&x| x as f64).sum();
        assert!((s as f64 - exact).abs() < 1e-4);
        assert_eq!(mean_f32(&[0.5, 0.25]), 0.375);
        assert!(mean_f32(&[]).is_nan());
    }

    #[test]
    fn bad_input_is_an_error() {
        let p = VectoriseParams::default();
        assert!(vectorise(&[0.0; 5], [1, 2, 3], 30.0, 15.0, &p, false).is_err());
        assert!(vectorise(&[], [0, 2, 3], 30.0, 15.0, &p, false).is_err());
        assert!(vectorise(&[f32::NAN; 6], [1, 2, 3], 30.0, 15.0, &p, false).is_err());
        assert!(vectorise(&[0.0; 6], [1, 2, 3], f64::NAN, 15.0, &p, false).is_err());
        assert!(vectorise(&[0.0; 6], [1, 2, 3], 30.0, -1.0, &p, false).is_err());
        let huge = [usize::MAX, 2, 3];
        assert!(vectorise(&[0.0; 6], huge, 30.0, 15.0, &p, false).is_err());
        for bad in [
            VectoriseParams {
                upsample: 0,
                ..p.clone()
            },
            VectoriseParams {
                num_points: 1,
                ..p.clone()
            },
            VectoriseParams {
                threshold: 1.5,
                ..p.clone()
            },
            VectoriseParams {
                ridge_threshold: 0.0,
                ..p.clone()
            },
            VectoriseParams {
                ridge_sigma: 0.0,
                ..p.clone()
            },
            VectoriseParams {
                ridge_classes: vec![0],
                ..p.clone()
            },
            VectoriseParams {
                rectangularity: 1.5,
                ..p.clone()
            },
            VectoriseParams {
                through: 91.0,
                ..p.clone()
            },
            VectoriseParams {
                spur: f64::NAN,
                ..p.clone()
            },
            VectoriseParams {
                corner_tolerance: -1.0,
                ..p.clone()
            },
            VectoriseParams {
                edge_margin: f64::NAN,
                ..p.clone()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn empty_and_full_masks() {
        let p = VectoriseParams::default();
        let empty = vectorise(&[0.0; 3 * 50 * 25], [3, 50, 25], 30.0, 15.0, &p, false).unwrap();
        assert!(empty.is_empty() && empty.num_points == 20);
        // every cell sure: a full crossing mask is one crossing; a full line mask thins to a line
        let full = vectorise(&[0.95; 3 * 50 * 25], [3, 50, 25], 30.0, 15.0, &p, true).unwrap();
        assert_eq!(full.points.len(), full.len() * 20);
        assert_eq!(full.classes.iter().filter(|&&c| c == 0).count(), 1);
        assert!(full.scores.iter().all(|s| (s - 0.95).abs() < 1e-6));
        let serial = vectorise(&[0.95; 3 * 50 * 25], [3, 50, 25], 30.0, 15.0, &p, false).unwrap();
        assert_eq!(full, serial);
    }

    #[test]
    fn single_pixels_give_nothing() {
        // one sure cell per class on a 0.3 m grid, no upsampling: too small for any instance
        let p = VectoriseParams {
            upsample: 1,
            ..Default::default()
        };
        let (nx, ny) = (200, 100);
        let mut prob = vec![0.0f32; 3 * nx * ny];
        for k in 0..3 {
            prob[k * nx * ny + 50 * ny + 50] = 0.9;
        }
        let out = vectorise(&prob, [3, nx, ny], 30.0, 15.0, &p, false).unwrap();
        assert!(out.is_empty());
        // a single cell of 3 x 3 m is a crossing of its own (a shrunk 64-gon)
        let mut cell = vec![0.0f32; 3 * 20 * 10];
        cell[5 * 10 + 5] = 0.9;
        let coarse = vectorise(&cell, [3, 20, 10], 30.0, 15.0, &p, false).unwrap();
        assert_eq!(coarse.classes, vec![0]);
    }

    /// No panic and consistent output on any mask and settings. A long run under a memory and a
    /// time limit (30,000 cases each, about 30 s):
    /// `(ulimit -v 4000000; PROPTEST_CASES=30000 timeout 900 cargo test -p icmap-geom --release
    /// vectorise::tests::properties)`.
    mod properties {
        use super::super::*;
        use proptest::prelude::*;

        fn params() -> impl Strategy<Value = VectoriseParams> {
            (
                (
                    1usize..=4,
                    0.0f64..90.0,
                    0.0f64..8.0,
                    0.0f64..=1.0,
                    0usize..3,
                ),
                (
                    0.0f64..3.0,
                    0.0f64..4.0,
                    0.0f64..4.0,
                    0.0f64..3.0,
                    0.0f64..1.0,
                ),
                (0usize..4, 0.0f64..2.0, 2usize..30),
            )
                .prop_map(|(a, b, c)| VectoriseParams {
                    upsample: a.0,
                    through: a.1,
                    spur: a.2,
                    rectangularity: a.3,
                    hull_simplify: [0.0, 0.5, 2.0][a.4],
                    shrink: b.0,
                    min_length: b.1,
                    min_area: b.2,
                    corner_tolerance: b.3,
                    simplify: b.4,
                    ridge_classes: [vec![], vec![1], vec![2], vec![1, 2]][c.0].clone(),
                    max_hole: c.1,
                    num_points: c.2,
                    ..Default::default()
                })
        }

        /// Probabilities of `k` classes on an `nx x ny` grid: cells from a few levels (sure,
        /// unsure, empty, out of [0, 1]), so that masks have blobs, lines, holes and junctions.
        fn probabilities() -> impl Strategy<Value = (usize, usize, usize, Vec<f32>)> {
            (1usize..=3, 1usize..=28, 1usize..=28).prop_flat_map(|(k, nx, ny)| {
                let level =
                    prop::sample::select(vec![0.0f32, 0.05, 0.35, 0.55, 0.95, 1.0, -3.0, 7.5]);
                (
                    Just(k),
                    Just(nx),
                    Just(ny),
                    prop::collection::vec(level, k * nx * ny),
                )
            })
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(400))]

            #[test]
            fn never_panics_and_returns_consistent_instances(
                (k, nx, ny, prob) in probabilities(),
                p in params(),
                half in prop::sample::select(vec![0.01f64, 1.0, 15.0, 30.0, 1e4]),
                parallel in any::<bool>(),
            ) {
                let out = vectorise(&prob, [k, nx, ny], half, half * 0.5, &p, parallel).unwrap();
                prop_assert_eq!(out.points.len(), out.len() * p.num_points);
                prop_assert_eq!(out.scores.len(), out.len());
                prop_assert!(out.classes.iter().all(|&c| (c as usize) < k));
                prop_assert!(out.points.iter().all(|q| q[0].is_finite() && q[1].is_finite()));
                prop_assert!(out.scores.iter().all(|s| s.is_finite()));
                // classes come out in index order
                prop_assert!(out.classes.windows(2).all(|w| w[0] <= w[1]));
            }

            #[test]
            fn random_binary_masks_at_full_resolution(
                (nx, ny) in (1usize..=40, 1usize..=40),
                seed in any::<u64>(),
                density in 0.05f64..0.95,
            ) {
                // a sure/empty mask per class from a seeded generator, at the native grid
                let mut state = seed | 1;
                let prob: Vec<f32> = (0..3 * nx * ny)
                    .map(|_| {
                        state ^= state << 13;
                        state ^= state >> 7;
                        state ^= state << 17;
                        if (state % 1000) as f64 / 1000.0 < density { 0.95 } else { 0.05 }
                    })
                    .collect();
                let p = VectoriseParams { upsample: 1, min_area: 0.0, min_length: 0.0, ..Default::default() };
                let serial = vectorise(&prob, [3, nx, ny], 6.0, 3.0, &p, false).unwrap();
                let par = vectorise(&prob, [3, nx, ny], 6.0, 3.0, &p, true).unwrap();
                prop_assert_eq!(serial, par);
            }
        }
    }
}
