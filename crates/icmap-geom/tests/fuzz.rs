//! A bounded fuzzer of the engine (issue 14, "keep it found"): property tests with extreme floats
//! (any bit pattern: NaN, inf, subnormals, the coordinate domain's edges) and huge counts on
//! every entry point, and random and mutated bytes on the map-file parser, including headers
//! that claim huge counts.
//!
//! Checked: no panic; every call returns within a deadline (each case runs on a thread of its
//! own); every result is finite; parsing allocates no more than a small multiple of the file's
//! size (a counting allocator, per thread).
//!
//! The suite runs a bounded number of cases (a few seconds in release). A longer run:
//! `ICMAP_FUZZ_CASES=100000 cargo test --release -p icmap-geom --test fuzz`.

mod common;

use common::{finite, p};
use icmap_geom::persist::{fnv1a64, from_bytes, to_bytes};
use icmap_geom::{
    chamfer_distance, chamfer_matrix, clip_polygon, clip_polyline, fit_curve, merge_polygon,
    merge_polyline, polygon_union, resample, resample_spacing, splice_polyline, GlobalMap,
    Instance, MapClass, MapConfig, Patch, Point, Pose2,
};
use proptest::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::time::Duration;

/// The system allocator, counting the bytes this thread has allocated and not freed, and their
/// peak (for "no allocation beyond what the file holds").
struct Counting;

thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn account(delta: isize) {
    let _ = LIVE.try_with(|live| {
        let v = live.get() + delta;
        live.set(v);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(v)));
    });
}

// SAFETY: every call is forwarded to the system allocator unchanged; the accounting touches only
// const-initialised thread locals (no allocation inside the allocator).
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            account(layout.size() as isize);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        account(-(layout.size() as isize));
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            account(new_size as isize - layout.size() as isize);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The peak of this thread's live allocations during `f`, above what was live before it.
fn peak_alloc<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let out = f();
    let peak = PEAK.with(Cell::get);
    (out, (peak - base).max(0) as usize)
}

/// Cases per property: `ICMAP_FUZZ_CASES`, else `default`.
fn cases(default: u32) -> u32 {
    std::env::var("ICMAP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Runs `f` on a thread of its own and fails unless it returns within 20 seconds.
fn within<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(20))
        .expect("an entry point did not return within 20 s")
}

/// Any float, with the interesting ones over-represented: any bit pattern, the domain's edges
/// and just beyond, tiny and subnormal values, ordinary metres.
fn float() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<f64>(),
        prop::sample::select(vec![
            0.0,
            -0.0,
            1e7,
            -1e7,
            1.0000000000000002e7,
            5e-324,
            -2.2250738585072014e-308,
            1e-300,
            f64::MAX,
            f64::MIN,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ]),
        -100.0f64..100.0,
        (-320i32..8, -1.0f64..1.0).prop_map(|(e, m)| m * 10f64.powi(e)),
    ]
}

fn points(max: usize) -> impl Strategy<Value = Vec<Point>> {
    prop::collection::vec((float(), float()), 0..max)
        .prop_map(|v| v.into_iter().map(|(x, y)| p(x, y)).collect())
}

/// Counts from 0 to `usize::MAX`, small ones and the caps' edges over-represented.
fn count() -> impl Strategy<Value = usize> {
    prop_oneof![
        0usize..40,
        prop::sample::select(vec![
            9_999_999,
            10_000_000,
            10_000_001,
            1_000_000,
            1_000_001,
            1_000_000_000_000,
            usize::MAX / 16,
            usize::MAX,
        ]),
        any::<usize>(),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(3000), ..ProptestConfig::default() })]

    /// Every entry point on arbitrary floats and counts: no panic, a deadline met, every result
    /// finite, counts beyond the caps refused.
    #[test]
    fn entry_points_on_arbitrary_input(
        a in points(10),
        b in points(10),
        s in float(),
        spacing in float(),
        n in count(),
        pose in (float(), float(), float()),
        ext in (float(), float(), float()),
        closed in any::<bool>(),
    ) {
        let ok = within(move || {
            let fine = Cell::new(true);
            let require = |c: bool| {
                if !c {
                    fine.set(false);
                }
            };
            let check = |pts: &[Point]| require(finite(pts));
            // Counts up to the cap are allowed and allocate their output: the fuzzer runs the
            // small ones, and checks that those beyond the cap are refused.
            if n <= 100_000 {
                if let Ok(out) = resample(&a, n, closed) { check(&out); }
            } else if n > 10_000_000 {
                require(resample(&a, n, closed).is_err());
            }
            // Likewise a valid spacing is kept to at most ~1e4 points over the input's extent
            // (invalid ones, <= 0 or not finite, go in as they are).
            let reach = a.iter().chain(&b).flat_map(|q| [q.x, q.y]).filter(|v| v.is_finite())
                .fold(0.0f64, |e, v| e.max(v.abs())).min(1e7);
            let sp = if spacing.is_finite() && spacing > 0.0 { spacing.max(reach * 1e-4) } else { spacing };
            if let Ok(out) = resample_spacing(&a, sp, closed) { check(&out); }
            if let Ok(out) = fit_curve(&a, s, sp) { check(&out); }
            if let Ok(out) = merge_polyline(&a, &b, s, sp) { check(&out); }
            if let Ok(out) = merge_polygon(&b, &a, sp) { check(&out); }
            if let Ok(out) = splice_polyline(&a, &b, s) { check(&out); }
            if let Ok(out) = polygon_union(&[a.clone(), b.clone()]) {
                for r in &out { check(r); }
            }
            if let Ok(out) = polygon_union(std::slice::from_ref(&b)) {
                for r in &out { check(r); }
            }
            if let Ok(d) = chamfer_distance(&a, &b) { require(d.is_finite()); }
            if let Ok(m) = chamfer_matrix(&[a.clone(), b.clone()], std::slice::from_ref(&b)) {
                require(m.iter().all(|v| v.is_finite()));
            }
            if let Ok(pose) = Pose2::new(pose.0, pose.1, pose.2) {
                if let Ok(patch) = Patch::new(pose, ext.0, ext.1, ext.2) {
                    for piece in clip_polyline(&a, &patch) { check(&piece); }
                    check(&clip_polygon(&b, &patch));
                    let mut m = GlobalMap::new(MapConfig { smoothing: 0.5, spacing: 1e4 }).unwrap();
                    let _ = m.insert(MapClass::Divider, &a, 0);
                    let _ = m.insert(MapClass::PedCrossing, &b, 0);
                    let _ = m.merge(0, &b, 1);
                    let _ = m.merge(1, &a, 1);
                    let _ = m.splice(0, &b, s, 2);
                    let _ = m.query(&patch);
                    if let Ok(sample) = m.sample_patch(&patch, n.clamp(0, 200)) {
                        check(&sample.points);
                    }
                    if n > 1_000_000 {
                        require(m.sample_patch(&patch, n).is_err());
                    }
                }
            }
            fine.get()
        });
        prop_assert!(ok);
    }
}

/// A valid map file of `k` instances (random shapes from `seed`).
fn map_bytes(k: usize, seed: u64) -> Vec<u8> {
    let mut r = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        r ^= r << 13;
        r ^= r >> 7;
        r ^= r << 17;
        (r >> 11) as f64 / (1u64 << 53) as f64
    };
    let instances: Vec<Instance> = (0..k)
        .map(|i| {
            let class = MapClass::ALL[i % 3];
            let n = 3 + (next() * 20.0) as usize;
            Instance {
                id: i as u64 * 2,
                class,
                points: (0..n)
                    .map(|j| p(j as f64 + next(), 100.0 * next()))
                    .collect(),
                closed: class.is_closed(),
                first_frame: 0,
                last_frame: i as i64,
                observations: 1,
            }
        })
        .collect();
    let m = GlobalMap::from_parts(MapConfig::default(), 2 * k as u64 + 1, instances).unwrap();
    to_bytes(&m)
}

/// Rewrites the checksum so that parsing gets past it (to the meaning of the values).
fn reseal(b: &mut [u8]) {
    if b.len() >= 8 {
        let end = b.len() - 8;
        let sum = fnv1a64(&b[..end]);
        b[end..].copy_from_slice(&sum.to_le_bytes());
    }
}

/// One mutation of a map file.
#[derive(Debug, Clone)]
enum Mutation {
    /// Overwrite the byte at (fraction of the length) with a value.
    Byte(f64, u8),
    /// Flip one bit.
    Bit(f64, u8),
    /// Write a u64 at a position (a count, an id, a coordinate).
    Word(f64, u64),
    /// Cut the file at a fraction of its length.
    Truncate(f64),
    /// Insert bytes at a position.
    Insert(f64, Vec<u8>),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let big = prop::sample::select(vec![
        u64::MAX,
        u64::MAX / 2,
        1 << 40,
        1 << 32,
        (1 << 32) - 1,
        0,
        1,
        0x7FF0_0000_0000_0000, // inf
        0x7FF8_0000_0000_0000, // NaN
        0x4415_AF1D_78B5_8C40, // 1e20
    ]);
    prop_oneof![
        (0.0f64..1.0, any::<u8>()).prop_map(|(f, v)| Mutation::Byte(f, v)),
        (0.0f64..1.0, 0u8..8).prop_map(|(f, v)| Mutation::Bit(f, v)),
        (0.0f64..1.0, prop_oneof![big, any::<u64>()]).prop_map(|(f, v)| Mutation::Word(f, v)),
        (0.0f64..1.0).prop_map(Mutation::Truncate),
        (0.0f64..1.0, prop::collection::vec(any::<u8>(), 1..40))
            .prop_map(|(f, v)| Mutation::Insert(f, v)),
    ]
}

fn apply(b: &mut Vec<u8>, m: &Mutation) {
    let at = |f: f64, len: usize| ((f * len as f64) as usize).min(len.saturating_sub(1));
    match m {
        Mutation::Byte(f, v) if !b.is_empty() => {
            let i = at(*f, b.len());
            b[i] = *v;
        }
        Mutation::Bit(f, k) if !b.is_empty() => {
            let i = at(*f, b.len());
            b[i] ^= 1 << k;
        }
        Mutation::Word(f, v) if b.len() >= 8 => {
            let i = at(*f, b.len() - 7);
            b[i..i + 8].copy_from_slice(&v.to_le_bytes());
        }
        Mutation::Truncate(f) => {
            let n = (f * b.len() as f64) as usize;
            b.truncate(n);
        }
        Mutation::Insert(f, v) => {
            let i = at(*f, b.len() + 1);
            b.splice(i..i, v.iter().copied());
        }
        _ => {}
    }
}

/// The most a parse may allocate for a file of `len` bytes: the instances and points it can
/// hold (points are 16 bytes in the file and in memory) with their index and bookkeeping, never
/// what a header claims.
fn parse_budget(len: usize) -> usize {
    24 * len + (64 << 10)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(5000), ..ProptestConfig::default() })]

    /// Valid files with random mutations, checksum kept wrong or resealed: parsing never panics
    /// and allocates at most a small multiple of the file's size.
    #[test]
    fn mutated_map_files(k in 0usize..12, seed in any::<u64>(), muts in prop::collection::vec(mutation(), 1..4), seal in any::<bool>()) {
        let mut b = map_bytes(k, seed);
        for m in &muts {
            apply(&mut b, m);
        }
        if seal {
            reseal(&mut b);
        }
        let len = b.len();
        let (res, peak) = peak_alloc(|| from_bytes(&b));
        prop_assert!(peak <= parse_budget(len), "{peak} bytes allocated for a {len}-byte file ({res:?})");
        if let Ok(m) = res {
            prop_assert!(m.check_invariants().is_ok());
            prop_assert!(m.instances().iter().all(|i| finite(&i.points)));
        }
    }

    /// Random bytes, with and without a valid magic and version and a resealed checksum.
    #[test]
    fn random_map_files(mut b in prop::collection::vec(any::<u8>(), 0..2000), header in any::<bool>()) {
        if header && b.len() >= 12 {
            b[..8].copy_from_slice(b"ICMAPGM\0");
            b[8..12].copy_from_slice(&1u32.to_le_bytes());
            reseal(&mut b);
        }
        let len = b.len();
        let (_, peak) = peak_alloc(|| from_bytes(&b));
        prop_assert!(peak <= parse_budget(len));
    }
}

/// Headers that claim huge counts (instances, points) in small files: refused without
/// allocating for the claim.
#[test]
fn huge_claimed_counts_allocate_nothing_for_the_claim() {
    let good = map_bytes(3, 7);
    // Offsets: magic 8 + version 4 + smoothing, spacing, next_id 24 -> the instance count at 36;
    // the first record's point count 30 bytes into it (id 8, class 1, closed 1, frames 16,
    // observations 4).
    for (offset, value) in [
        (36, u64::MAX),
        (36, 1 << 40),
        (36, 4),
        (44 + 30, u64::MAX),
        (44 + 30, 1 << 36),
        (44 + 30, 1 << 20),
    ] {
        for seal in [false, true] {
            let mut b = good.clone();
            b[offset..offset + 8].copy_from_slice(&value.to_le_bytes());
            if seal {
                reseal(&mut b);
            }
            let (res, peak) = peak_alloc(|| from_bytes(&b));
            assert!(res.is_err(), "offset {offset} value {value}");
            assert!(
                peak <= parse_budget(b.len()),
                "offset {offset} value {value}: {peak} bytes"
            );
        }
    }
}
