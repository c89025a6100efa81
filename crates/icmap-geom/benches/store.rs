//! Criterion benches of the global map store: `query` and `sample_patch` on synthetic maps of 1e3
//! and 1e5 instances, `merge_polyline`, and `chamfer_matrix` (50 x 50 instances of 20 points).
//!
//! Run: `cargo bench -p icmap-geom --bench store` (add `-- --quick` for a fast pass).

use criterion::measurement::WallTime;
use criterion::{
    black_box, criterion_group, criterion_main, BenchmarkGroup, BenchmarkId, Criterion,
};
use icmap_geom::{
    chamfer_matrix, merge_polyline, GlobalMap, MapClass, MapConfig, Patch, Point, Pose2,
};
use std::time::Duration;

#[path = "../src/splitmix.rs"]
mod splitmix;

use splitmix::Rng;

/// Cell size of the synthetic grid, metres: one instance per cell.
const CELL: f64 = 10.0;

/// A map of `n` instances on a square grid of `CELL`-metre cells: short random polylines
/// (dividers and boundaries, 3 to 6 points over 5 to 20 m) and small crossings (10 %).
fn synthetic_map(n: usize, seed: u64) -> (GlobalMap, f64) {
    let mut rng = Rng(seed);
    let side = (n as f64).sqrt().ceil() as usize;
    let mut map = GlobalMap::new(MapConfig::default()).expect("valid config");
    for k in 0..n {
        let (cx, cy) = ((k % side) as f64 * CELL, (k / side) as f64 * CELL);
        let x0 = cx + rng.uniform(0.0, CELL);
        let y0 = cy + rng.uniform(0.0, CELL);
        if rng.uniform(0.0, 1.0) < 0.1 {
            let (hx, hy) = (rng.uniform(1.0, 3.0), rng.uniform(2.0, 5.0));
            let ring = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
                .map(|(dx, dy)| Point::new(x0 + dx, y0 + dy));
            map.insert(MapClass::PedCrossing, &ring, 0)
                .expect("valid crossing");
        } else {
            let class = if rng.uniform(0.0, 1.0) < 0.5 {
                MapClass::Divider
            } else {
                MapClass::Boundary
            };
            let m = 3 + (rng.next_u64() % 4) as usize;
            let len = rng.uniform(5.0, 20.0);
            let mut heading = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
            let mut p = Point::new(x0, y0);
            let mut pts = vec![p];
            for _ in 1..m {
                heading += rng.uniform(-0.3, 0.3);
                p += nalgebra::Vector2::new(heading.cos(), heading.sin()) * (len / (m - 1) as f64);
                pts.push(p);
            }
            map.insert(class, &pts, 0).expect("valid polyline");
        }
    }
    (map, side as f64 * CELL)
}

/// `k` patches of 60 x 30 m (+ `margin`) at random poses inside a square of side `extent`.
fn patches(k: usize, extent: f64, margin: f64, seed: u64) -> Vec<Patch> {
    let mut rng = Rng(seed);
    (0..k)
        .map(|_| {
            let pose = Pose2::new(
                rng.uniform(0.0, extent),
                rng.uniform(0.0, extent),
                rng.uniform(-std::f64::consts::PI, std::f64::consts::PI),
            )
            .unwrap();
            Patch::new(pose, 30.0, 15.0, margin).unwrap()
        })
        .collect()
}

/// A benchmark group of 10 samples, 0.3 s warm-up and 1 s of measurement.
fn quick_group<'a>(c: &'a mut Criterion, name: &str) -> BenchmarkGroup<'a, WallTime> {
    let mut group = c.benchmark_group(name);
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    group
}

fn bench_store(c: &mut Criterion) {
    let mut group = quick_group(c, "store");
    for n in [1_000usize, 100_000] {
        let (map, extent) = synthetic_map(n, 7);
        let q = patches(64, extent, 0.0, 11);
        let s = patches(64, extent, 20.0, 13);
        let mut i = 0usize;
        group.bench_with_input(BenchmarkId::new("query_60x30", n), &n, |b, _| {
            b.iter(|| {
                i = (i + 1) % q.len();
                black_box(map.query(black_box(&q[i])))
            })
        });
        let mut j = 0usize;
        group.bench_with_input(
            BenchmarkId::new("sample_patch_100x70_n20", n),
            &n,
            |b, _| {
                b.iter(|| {
                    j = (j + 1) % s.len();
                    black_box(map.sample_patch(black_box(&s[j]), 20).unwrap())
                })
            },
        );
    }
    group.finish();
}

fn bench_geometry(c: &mut Criterion) {
    let mut group = quick_group(c, "geometry");
    // A 40 m global polyline (1 m spacing) and a 20 m detection overlapping its last 10 m.
    let global: Vec<Point> = (0..=40)
        .map(|k| Point::new(k as f64, 0.02 * (k as f64 * 0.3).sin()))
        .collect();
    let detected: Vec<Point> = (0..20)
        .map(|k| Point::new(30.0 + k as f64, 0.1 + 0.01 * k as f64))
        .collect();
    group.bench_function("merge_polyline_40m_20m", |b| {
        b.iter(|| {
            black_box(merge_polyline(black_box(&global), black_box(&detected), 0.5, 1.0).unwrap())
        })
    });
    let mut rng = Rng(3);
    let mut set = |n: usize| -> Vec<Vec<Point>> {
        (0..n)
            .map(|_| {
                let (x, y) = (rng.uniform(-30.0, 30.0), rng.uniform(-15.0, 15.0));
                let (dx, dy) = (rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
                (0..20)
                    .map(|k| Point::new(x + dx * k as f64, y + dy * k as f64))
                    .collect()
            })
            .collect()
    };
    let (a, b_) = (set(50), set(50));
    group.bench_function("chamfer_matrix_50x50x20", |b| {
        b.iter(|| black_box(chamfer_matrix(black_box(&a), black_box(&b_)).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench_store, bench_geometry);
criterion_main!(benches);
