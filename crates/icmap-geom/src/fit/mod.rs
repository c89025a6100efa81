//! Smoothing cubic-spline fit of a polyline (the semantics of scipy's `splprep`).
//!
//! A re-implementation of Dierckx's FITPACK `parcur`/`fppara` algorithm (the code behind scipy's
//! `splprep(x, s=s, k=k)` with unit weights), so the fitted curves agree with scipy:
//!
//! 1. chord-length parameter `u` on `[0, 1]`;
//! 2. start from the least-squares polynomial (no interior knots); while the sum of squared
//!    residuals `fp` exceeds `s`, add knots at data points in the knot intervals with the largest
//!    residuals (FITPACK's `fpknot` rule and knot-count schedule) and refit by least squares
//!    (banded Givens QR), falling back to the interpolation knots when all are used;
//! 3. with the knots fixed, find the smoothing weight `p` such that `fp(p) = s` (to FITPACK's
//!    relative tolerance 1e-3) by the rational-interpolation iteration of `fprati`, minimising the
//!    jumps of the k-th derivative at the interior knots (`fpdisc`).
//!
//! The fitted curve is then evaluated about `spacing` apart by arc length.
//!
//! One operation per file:
//!
//! | file | operation |
//! |---|---|
//! | [`fit_curve`](fit_curve()) | the public entry: fit, then points evenly spaced by arc length |
//! | [`fit_spline`](fit_spline()) | the knot loop (step 2) and the overshoot rule |
//! | `smoothing` | the smoothing weight with fixed knots (step 3) |
//! | `knots` | knot placement (`fpknot`, interpolation knots) |
//! | `lsq_qr` | least squares with fixed knots by Givens QR (any degree) |
//! | `lsq_normal` | least squares for cubics by the banded normal equations (Cholesky) |
//! | `lsq_poly` | the least-squares cubic polynomial (no interior knots), unrolled |
//! | `givens` | Givens rotations (three variants) and banded back substitution |
//! | `basis` | B-spline basis values and the design of a fit |
//! | `spline` | the fitted curve in B-spline form ([`SplineCurve`]) |
//! | `arc_length` | arc-length table (adaptive Gauss-Legendre) and its inversion |

mod arc_length;
mod basis;
mod fit_curve;
mod fit_spline;
mod givens;
mod knots;
mod lsq_normal;
mod lsq_poly;
mod lsq_qr;
mod smoothing;
mod spline;
#[cfg(test)]
mod test_util;

pub use fit_curve::fit_curve;
pub use fit_spline::fit_spline;
pub use spline::SplineCurve;

/// FITPACK's relative tolerance on `fp = s` (parcur's `tol`).
const TOL: f64 = 1e-3;
/// FITPACK's maximal number of iterations for the smoothing weight (parcur's `maxit`).
const MAXIT: usize = 20;
