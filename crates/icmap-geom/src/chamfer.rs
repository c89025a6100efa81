//! Chamfer distances between point sets.

use crate::error::Result;
use crate::types::{validate_points, Point};
use rayon::prelude::*;

/// Sum over `a` of the distance to the nearest point of `b` (squared distances in the inner loop,
/// one square root per point of `a`).
fn sum_nearest(a: &[Point], b: &[Point]) -> f64 {
    a.iter()
        .map(|p| {
            let mut best = f64::INFINITY;
            for q in b {
                let dx = p.x - q.x;
                let dy = p.y - q.y;
                let d2 = dx * dx + dy * dy;
                if d2 < best {
                    best = d2;
                }
            }
            best.sqrt()
        })
        .sum()
}

/// Chamfer distance of validated, non-empty point sets.
fn chamfer_unchecked(a: &[Point], b: &[Point]) -> f64 {
    (sum_nearest(a, b) / a.len() as f64 + sum_nearest(b, a) / b.len() as f64) / 2.0
}

/// Chamfer distance: (mean over `a` of the distance to the nearest point of `b` + mean over `b` of
/// the distance to the nearest point of `a`) / 2. For equal sizes N this equals
/// (sum of nearest distances in both directions) / (2 N). Errors on empty or non-finite input.
pub fn chamfer_distance(a: &[Point], b: &[Point]) -> Result<f64> {
    validate_points(a, 1, "chamfer point set a")?;
    validate_points(b, 1, "chamfer point set b")?;
    Ok(chamfer_unchecked(a, b))
}

/// All pairwise Chamfer distances, row-major `(a.len(), b.len())` (parallel over rows).
/// Errors if any set is empty or non-finite (naming `a[i]` / `b[j]`). Empty lists give an empty
/// matrix.
pub fn chamfer_matrix(a: &[Vec<Point>], b: &[Vec<Point>]) -> Result<Vec<f64>> {
    for (i, s) in a.iter().enumerate() {
        validate_points(s, 1, &format!("chamfer point set a[{i}]"))?;
    }
    for (j, s) in b.iter().enumerate() {
        validate_points(s, 1, &format!("chamfer point set b[{j}]"))?;
    }
    let mut out = vec![0.0; a.len() * b.len()];
    if b.is_empty() {
        return Ok(out);
    }
    out.par_chunks_mut(b.len())
        .zip(a.par_iter())
        .for_each(|(row, sa)| {
            for (cell, sb) in row.iter_mut().zip(b) {
                *cell = chamfer_unchecked(sa, sb);
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::GeomError;
    use crate::test_util::p;
    use proptest::prelude::*;

    #[test]
    fn known_values() {
        let a = [p(0.0, 0.0), p(1.0, 0.0)];
        let b = [p(0.0, 1.0), p(1.0, 1.0)];
        assert!((chamfer_distance(&a, &b).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(chamfer_distance(&a, &a).unwrap(), 0.0);
        // Unequal sizes: a->c mean = 0, c->a mean = (0 + 0 + 3) / 3 = 1.
        let c = [p(0.0, 0.0), p(1.0, 0.0), p(4.0, 0.0)];
        assert!((chamfer_distance(&a, &c).unwrap() - 0.5).abs() < 1e-12);
    }

    #[test]
    fn errors() {
        let a = [p(0.0, 0.0)];
        assert!(matches!(
            chamfer_distance(&[], &a),
            Err(GeomError::TooFewPoints { .. })
        ));
        assert!(matches!(
            chamfer_distance(&a, &[p(f64::NAN, 0.0)]),
            Err(GeomError::NonFinite { .. })
        ));
        assert!(chamfer_matrix(&[a.to_vec()], &[vec![]]).is_err());
        assert!(chamfer_matrix(&[], &[a.to_vec()]).unwrap().is_empty());
    }

    #[test]
    fn matrix_matches_pairwise() {
        let sets: Vec<Vec<Point>> = (0..5)
            .map(|i| {
                (0..4)
                    .map(|j| p(i as f64 + j as f64 * 0.3, (i * j) as f64 * 0.1))
                    .collect()
            })
            .collect();
        let m = chamfer_matrix(&sets[..3], &sets).unwrap();
        assert_eq!(m.len(), 15);
        for i in 0..3 {
            for j in 0..5 {
                assert_eq!(m[i * 5 + j], chamfer_distance(&sets[i], &sets[j]).unwrap());
            }
        }
    }

    proptest! {
        #[test]
        fn prop_symmetric_nonnegative(a in prop::collection::vec((-50.0f64..50.0, -50.0f64..50.0), 1..20),
                                      b in prop::collection::vec((-50.0f64..50.0, -50.0f64..50.0), 1..20)) {
            let a: Vec<Point> = a.into_iter().map(|(x, y)| p(x, y)).collect();
            let b: Vec<Point> = b.into_iter().map(|(x, y)| p(x, y)).collect();
            let ab = chamfer_distance(&a, &b).unwrap();
            let ba = chamfer_distance(&b, &a).unwrap();
            prop_assert!(ab >= 0.0 && (ab - ba).abs() <= 1e-12 * (1.0 + ab));
            // Translating b by d moves the distance by at most |d|.
            let d = p(0.5, -0.25).coords;
            let bt: Vec<Point> = b.iter().map(|q| q + d).collect();
            prop_assert!((chamfer_distance(&a, &bt).unwrap() - ab).abs() <= d.norm() + 1e-9);
        }
    }
}
