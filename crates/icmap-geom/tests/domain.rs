//! The coordinate domain at every entry point (issue 14, point 3): inside `|x|, |y| <= MAX_COORD`
//! every result is finite (extreme but valid values: the domain's edges, tiny and subnormal
//! coordinates); outside it, every entry point refuses the input with an error naming it, where
//! finite inputs once gave `inf`, NaN or wrong geometry.

mod common;

use common::{finite, p};
use icmap_geom::types::MAX_COORD;
use icmap_geom::{
    chamfer_distance, chamfer_matrix, clip_polygon, clip_polyline, fit_curve, merge_polygon,
    merge_polyline, polygon_union, resample, resample_spacing, GeomError, GlobalMap, MapClass,
    MapConfig, Patch, Point, Pose2,
};
use proptest::prelude::*;

/// A coordinate anywhere in the domain, with its extremes over-represented: the edges, zero,
/// tiny and subnormal magnitudes.
fn coord() -> impl Strategy<Value = f64> {
    prop_oneof![
        -MAX_COORD..=MAX_COORD,
        -100.0f64..100.0,
        Just(MAX_COORD),
        Just(-MAX_COORD),
        Just(0.0),
        (-320i32..-1, -1.0f64..1.0).prop_map(|(e, m)| m * 10f64.powi(e)),
        Just(f64::MIN_POSITIVE),
        Just(-5e-324),
    ]
}

fn points(min: usize, max: usize) -> impl Strategy<Value = Vec<Point>> {
    prop::collection::vec((coord(), coord()), min..max)
        .prop_map(|v| v.into_iter().map(|(x, y)| p(x, y)).collect())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Every function on any points of the domain: an error or a finite result.
    #[test]
    fn prop_results_in_the_domain_are_finite(
        a in points(2, 12),
        b in points(3, 12),
        pose in (coord(), coord(), -10.0f64..10.0),
        ext in (0.0f64..=MAX_COORD, 0.0f64..=MAX_COORD),
        s in prop_oneof![Just(0.0), 0.0f64..10.0, Just(1e12)],
        spacing in prop_oneof![0.1f64..10.0, Just(MAX_COORD)],
    ) {
        let patch = Patch::new(Pose2::new(pose.0, pose.1, pose.2).unwrap(), ext.0, ext.1, 0.0).unwrap();
        // At least 1e-4 of the points' extent: at most some 1e4 output points (a 1e7 m line at
        // 0.1 m is ten million points, legitimate but slow for a property test).
        let extent = a.iter().chain(&b).fold(0.0f64, |e, q| e.max(q.x.abs()).max(q.y.abs()));
        let spacing = spacing.max(extent * 1e-4);
        if let Ok(out) = resample(&a, 17, false) { prop_assert!(finite(&out)); }
        if let Ok(out) = resample(&b, 17, true) { prop_assert!(finite(&out)); }
        if let Ok(out) = resample_spacing(&a, spacing, false) { prop_assert!(finite(&out)); }
        for piece in clip_polyline(&a, &patch) { prop_assert!(finite(&piece)); }
        prop_assert!(finite(&clip_polygon(&b, &patch)));
        if let Ok(out) = fit_curve(&a, s, spacing) { prop_assert!(finite(&out)); }
        if let Ok(out) = merge_polyline(&a, &b, s, spacing) { prop_assert!(finite(&out)); }
        if let Ok(out) = merge_polygon(&b, &a, spacing) { prop_assert!(finite(&out)); }
        if let Ok(out) = polygon_union(&[a.clone(), b.clone()]) {
            prop_assert!(out.iter().all(|r| finite(r)));
        }
        let d = chamfer_distance(&a, &b).unwrap();
        prop_assert!(d.is_finite() && d >= 0.0);
        prop_assert!(chamfer_matrix(std::slice::from_ref(&a), &[b.clone(), a.clone()]).unwrap().iter().all(|v| v.is_finite()));
        // (Stored at 1e4 m spacing: a 1e7 m line stored at 1 m would be ten million points, a
        // legitimate but slow case for a property test.)
        let mut m = GlobalMap::new(MapConfig { smoothing: 0.5, spacing: 1e4 }).unwrap();
        if let Ok(id) = m.insert(MapClass::Divider, &a, 0) {
            let _ = m.merge(id, &b, 1);
        }
        if let Ok(id) = m.insert(MapClass::PedCrossing, &b, 0) {
            let _ = m.merge(id, &a, 1);
        }
        let _ = m.query(&patch);
        if let Ok(sample) = m.sample_patch(&patch, 20) {
            prop_assert!(finite(&sample.points));
            // The ego-frame points also fit float32 (the binding's output type).
            prop_assert!(sample.points.iter().all(|q| (q.x as f32).is_finite() && (q.y as f32).is_finite()));
        }
    }

    /// One coordinate outside the domain (finite but too large, or NaN / inf) is refused by
    /// every function that takes points, whatever the others are.
    #[test]
    fn prop_outside_the_domain_is_refused(
        good in points(4, 8),
        at in 0usize..4,
        bad in prop_oneof![
            (1.0000001f64..1e300).prop_map(|f| f * MAX_COORD),
            (1.0000001f64..1e300).prop_map(|f| -f * MAX_COORD),
            Just(f64::MAX),
            Just(f64::NAN),
            Just(f64::INFINITY),
        ],
        y_axis in any::<bool>(),
    ) {
        let mut pts = good.clone();
        if y_axis { pts[at].y = bad } else { pts[at].x = bad }
        let refused = |r: Result<(), GeomError>| matches!(r, Err(GeomError::OutOfDomain { .. } | GeomError::NonFinite { .. }));
        prop_assert!(refused(resample(&pts, 5, false).map(|_| ())));
        prop_assert!(refused(resample_spacing(&pts, 1.0, true).map(|_| ())));
        prop_assert!(refused(fit_curve(&pts, 0.5, 1.0).map(|_| ())));
        prop_assert!(refused(merge_polyline(&good, &pts, 0.5, 1.0).map(|_| ())));
        prop_assert!(refused(merge_polyline(&pts, &good, 0.5, 1.0).map(|_| ())));
        prop_assert!(refused(merge_polygon(&good, &pts, 1.0).map(|_| ())));
        prop_assert!(refused(polygon_union(&[good.clone(), pts.clone()]).map(|_| ())));
        prop_assert!(refused(polygon_union(&[pts.clone()]).map(|_| ())));
        prop_assert!(refused(chamfer_distance(&good, &pts).map(|_| ())));
        prop_assert!(refused(chamfer_matrix(std::slice::from_ref(&good), std::slice::from_ref(&pts)).map(|_| ())));
        let mut m = GlobalMap::new(MapConfig::default()).unwrap();
        prop_assert!(refused(m.insert(MapClass::Divider, &pts, 0).map(|_| ())));
        prop_assert!(refused(m.insert(MapClass::PedCrossing, &pts, 0).map(|_| ())));
        let patch = Patch::new(Pose2::new(0.0, 0.0, 0.0).unwrap(), 100.0, 100.0, 0.0).unwrap();
        // Clipping is total: points outside the domain lie outside every patch.
        prop_assert!(clip_polygon(&pts, &patch).iter().all(|q| q.x.is_finite() && q.y.is_finite()));
        for piece in clip_polyline(&pts, &patch) { prop_assert!(finite(&piece)); }
    }
}

/// The issue's cases, each refused at the boundary with an error naming the value.
#[test]
fn issue_cases_are_refused() {
    let err = chamfer_distance(&[p(0.0, 0.0)], &[p(1e200, 0.0)]).unwrap_err();
    assert!(matches!(err, GeomError::OutOfDomain { .. }));
    assert!(err.to_string().contains("1e200"), "{err}");
    // Poses and patch sizes: sample_patch((1e39, 0, 0), (1e40, 1e40)) returned +-inf.
    assert!(matches!(
        Pose2::new(1e39, 0.0, 0.0),
        Err(GeomError::OutOfDomain { .. })
    ));
    let pose = Pose2::new(0.0, 0.0, 0.0).unwrap();
    for (hx, hy, margin) in [(1e40, 1.0, 0.0), (1.0, 2e7, 0.0), (1.0, 1.0, 1e8)] {
        assert!(matches!(
            Patch::new(pose, hx, hy, margin),
            Err(GeomError::OutOfDomain { .. })
        ));
    }
    // A patch built around the checks (public fields) samples nothing and errors.
    let bad = Patch {
        pose: Pose2 {
            x: 1e39,
            y: 0.0,
            yaw: 0.0,
        },
        half_extents: nalgebra::Vector2::new(1e40, 1e40),
    };
    let mut m = GlobalMap::new(MapConfig::default()).unwrap();
    m.insert(MapClass::Divider, &[p(0.0, 0.0), p(10.0, 0.0)], 0)
        .unwrap();
    assert!(m.query(&bad).is_empty());
    assert!(m.sample_patch(&bad, 20).is_err());
    assert!(clip_polyline(&[p(0.0, 0.0), p(10.0, 0.0)], &bad).is_empty());
    // The domain's edges are in it.
    let edge = [p(-MAX_COORD, -MAX_COORD), p(MAX_COORD, MAX_COORD)];
    let d = chamfer_distance(&edge[..1], &edge[1..]).unwrap();
    assert!((d - 2.0 * MAX_COORD * 2f64.sqrt()).abs() < 1.0);
    assert!(Pose2::new(MAX_COORD, -MAX_COORD, 0.0).is_ok());
    assert!(Patch::new(pose, MAX_COORD, MAX_COORD, MAX_COORD).is_ok());
}
