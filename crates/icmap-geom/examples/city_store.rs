//! The store at city scale: map file sizes (format 1, format 2 exact and compact), save + load
//! seconds, region loading, and `merge_map` of two maps of n instances each. One run prints every
//! number and ratio; nothing is asserted.
//!
//! `cargo run --release -p icmap-geom --example city_store -- [--sizes 10000,100000]
//! [--merge-sizes 10000,100000] [--dir DIR]`
//!
//! Save and load: three rounds per format (save, then load; the loaded copy dropped), the median
//! round printed with the fastest beside it, and the process's user and kernel CPU seconds of the
//! median round (the kernel share is mostly first-touch page faults of fresh memory, which vary
//! from run to run on a shared VM).
//!
//! The synthetic city: instances on a grid of 25 m cells, 90 % smooth polylines of 20-60 m
//! (dividers and boundaries, heading changing smoothly, stored at 1 m spacing: about 41 points
//! each), 10 % crossings (rectangles of 3-6 x 6-12 m, about 24 points). The second map of a merge
//! re-observes half of the first map's polylines and crossings (a part of 60-100 % of each,
//! offset by up to 0.2 m) and adds as many new instances in cells of its own.

use icmap_geom::merge_map::MergeMapParams;
use icmap_geom::persist_v2::{self, Encoding};
use icmap_geom::{persist, GlobalMap, MapClass, MapConfig, Point};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The allocator of the Python extension (`icmap-py`), so that the program measures what it runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[path = "../src/splitmix.rs"]
mod splitmix;

use splitmix::Rng;

const CELL: f64 = 25.0;
/// Save + load rounds per format.
const REPS: usize = 3;

/// One round: save and load wall seconds, and their (user, kernel) CPU seconds.
type Round = (f64, f64, (f64, f64), (f64, f64));

/// One synthetic instance in the cell at `(cx, cy)`: class and geometry (before resampling).
fn instance(rng: &mut Rng, cx: f64, cy: f64) -> (MapClass, Vec<Point>) {
    let (x0, y0) = (cx + rng.uniform(0.0, CELL), cy + rng.uniform(0.0, CELL));
    if rng.uniform(0.0, 1.0) < 0.1 {
        let (hx, hy) = (rng.uniform(1.5, 3.0), rng.uniform(3.0, 6.0));
        let ring = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
            .iter()
            .map(|&(dx, dy)| Point::new(x0 + dx, y0 + dy))
            .collect();
        return (MapClass::PedCrossing, ring);
    }
    let class = if rng.uniform(0.0, 1.0) < 0.5 {
        MapClass::Divider
    } else {
        MapClass::Boundary
    };
    let len = rng.uniform(20.0, 60.0);
    let mut heading = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
    let mut turn = rng.uniform(-0.02, 0.02);
    let mut p = Point::new(x0, y0);
    let mut pts = vec![p];
    let steps = (len / 0.5) as usize;
    for _ in 0..steps {
        turn = (turn + rng.uniform(-0.002, 0.002)).clamp(-0.03, 0.03);
        heading += turn * 0.5;
        p += nalgebra::Vector2::new(heading.cos(), heading.sin()) * 0.5;
        pts.push(p);
    }
    (class, pts)
}

/// A city of `n` instances, cells in row-major order over a square (ids 0..n).
fn city(n: usize, seed: u64) -> GlobalMap {
    let mut rng = Rng(seed);
    let side = (n as f64).sqrt().ceil() as usize;
    let mut map = GlobalMap::new(MapConfig::default()).expect("valid config");
    for k in 0..n {
        let (cx, cy) = ((k % side) as f64 * CELL, (k / side) as f64 * CELL);
        let (class, pts) = instance(&mut rng, cx, cy);
        map.insert(class, &pts, (k % 1000) as i64)
            .expect("valid instance");
    }
    map.tag_drive(0);
    map
}

/// The second map of a merge: half of `base`'s instances re-observed, half new ones beside.
fn second_drive(base: &GlobalMap, seed: u64) -> GlobalMap {
    let mut rng = Rng(seed);
    let mut map = GlobalMap::new(MapConfig::default()).expect("valid config");
    let n = base.len();
    let side = (n as f64).sqrt().ceil() as usize;
    for (k, inst) in base.instances().into_iter().enumerate() {
        if k % 2 == 0 {
            let (dx, dy) = (rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2));
            let pts: Vec<Point> = if inst.closed {
                inst.points
                    .iter()
                    .map(|q| Point::new(q.x + dx, q.y + dy))
                    .collect()
            } else {
                let m = inst.points.len();
                let keep = ((m as f64 * rng.uniform(0.6, 1.0)) as usize).max(2);
                let start = (rng.next_u64() as usize) % (m - keep + 1);
                inst.points[start..start + keep]
                    .iter()
                    .map(|q| Point::new(q.x + dx, q.y + dy))
                    .collect()
            };
            map.insert(inst.class, &pts, 0).expect("valid instance");
        } else {
            // A new instance in a cell of its own, beyond the first map's square.
            let (cx, cy) = ((k % side) as f64 * CELL, (side + k / side) as f64 * CELL);
            let (class, pts) = instance(&mut rng, cx, cy);
            map.insert(class, &pts, 0).expect("valid instance");
        }
    }
    map.tag_drive(1);
    map
}

fn secs(t: Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

/// This process's (user, kernel) CPU seconds so far, from `/proc/self/stat` (Linux; zeros
/// elsewhere). The kernel share of a save or load is mostly first-touch page faults of fresh
/// memory, which on a shared VM vary from run to run far more than the program's own work.
fn cpu_times() -> (f64, f64) {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return (0.0, 0.0);
    };
    // Fields after the command name (which is in parentheses): utime and stime are fields 14
    // and 15 of the whole line, in clock ticks (100 per second on Linux).
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0) / 100.0;
    (tick(11), tick(12))
}

/// Runs `f`, returning its result, wall seconds and (user, kernel) CPU seconds.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, (f64, f64)) {
    let (u0, k0) = cpu_times();
    let t = Instant::now();
    let out = f();
    let wall = secs(t);
    let (u1, k1) = cpu_times();
    (out, wall, (u1 - u0, k1 - k0))
}

fn file_len(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

fn store(n: usize, dir: &Path) -> Result<(), String> {
    let t = Instant::now();
    let map = city(n, 7);
    let points: usize = map.instances_iter().map(|i| i.points.len()).sum();
    println!(
        "\n== store, {n} instances ({:.1} points each; built in {:.1} s)",
        points as f64 / n as f64,
        secs(t)
    );
    let path = dir.join(format!("city-{n}.icmap"));
    let err = |e: icmap_geom::GeomError| e.to_string();
    // Per format: REPS rounds of save, then load (the loaded copy dropped before the next round);
    // the median round by save + load is printed, with the fastest beside it.
    let mut v1_size = 0u64;
    for format in ["format 1", "format 2 exact", "format 2 compact"] {
        let mut rounds: Vec<Round> = Vec::new();
        for _ in 0..REPS {
            let (r, save, save_cpu) = timed(|| match format {
                "format 1" => persist::save(&map, &path),
                "format 2 exact" => persist_v2::save(&map, &path, Encoding::Exact),
                _ => persist_v2::save(&map, &path, Encoding::Compact),
            });
            r.map_err(err)?;
            let (back, load, load_cpu) = timed(|| match format {
                "format 1" => persist::load(&path),
                _ => persist_v2::load(&path),
            });
            let back = back.map_err(err)?;
            assert_eq!(back.len(), n);
            drop(back);
            rounds.push((save, load, save_cpu, load_cpu));
        }
        rounds.sort_by(|a, b| (a.0 + a.1).total_cmp(&(b.0 + b.1)));
        let (save, load, save_cpu, load_cpu) = rounds[rounds.len() / 2];
        let best = rounds[0].0 + rounds[0].1;
        let size = file_len(&path);
        if format == "format 1" {
            v1_size = size;
        }
        println!(
            "{format:<17} {:>8.1} MB  {:>4.0} B/instance ({:.3} of format 1)  save {save:.2} s  load {load:.2} s  save+load {:.2} s (fastest of {REPS}: {best:.2} s)",
            size as f64 / 1e6,
            size as f64 / n as f64,
            size as f64 / v1_size as f64,
            save + load,
        );
        println!(
            "{:17} CPU (user + kernel) s: save {:.2} + {:.2}, load {:.2} + {:.2}",
            "", save_cpu.0, save_cpu.1, load_cpu.0, load_cpu.1
        );
    }
    // Region loading from the compact file: a 500 x 500 m square in the middle of the city.
    let side = (n as f64).sqrt().ceil() * CELL;
    let c = side / 2.0;
    let region = [c - 250.0, c - 250.0, c + 250.0, c + 250.0];
    let t = Instant::now();
    let part = persist_v2::load_region(&path, region).map_err(err)?;
    let region_s = secs(t);
    let t = Instant::now();
    let whole = persist_v2::load(&path).map_err(err)?;
    let whole_s = secs(t);
    println!(
        "region 500 x 500 m: {} instances in {:.4} s (whole file {:.3} s: {:.0}x)",
        part.len(),
        region_s,
        whole_s,
        whole_s / region_s
    );
    drop(whole);
    std::fs::remove_file(&path).map_err(|e| e.to_string())?;
    Ok(())
}

fn merge(sizes: &[usize]) -> Result<(), String> {
    println!("\n== merge_map of two maps of n instances each (half re-observed, half new)");
    let mut first: Option<(usize, f64)> = None;
    for &n in sizes {
        let a = city(n, 11);
        let b = second_drive(&a, 12);
        let mut m = a.clone();
        let t = Instant::now();
        let stats = m
            .merge_map(&b, MergeMapParams::default())
            .map_err(|e| e.to_string())?;
        let s = secs(t);
        let per = s / n as f64 * 1e6;
        let scaling = match first {
            None => String::new(),
            Some((n0, s0)) => {
                let nlogn = (n as f64 * (n as f64).ln()) / (n0 as f64 * (n0 as f64).ln());
                format!(
                    "  time x{:.1} for n x{:.0} (n log n: x{nlogn:.1}; n^2: x{:.0})",
                    s / s0,
                    n as f64 / n0 as f64,
                    (n as f64 / n0 as f64).powi(2)
                )
            }
        };
        println!(
            "n = {n:>7}: {s:.2} s ({per:.1} us per instance of other; merged {}, inserted {}, absorbed {}; result {} instances){scaling}",
            stats.merged, stats.inserted, stats.absorbed, m.len()
        );
        first.get_or_insert((n, s));
    }
    Ok(())
}

fn parse_sizes(s: &str) -> Result<Vec<usize>, String> {
    s.split(',')
        .filter(|x| !x.is_empty())
        .map(|x| x.trim().parse::<usize>().map_err(|e| format!("{x}: {e}")))
        .collect()
}

fn main() -> Result<(), String> {
    let mut sizes = vec![10_000, 100_000];
    let mut merge_sizes = vec![10_000, 100_000];
    let mut dir = std::env::temp_dir();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--sizes" => sizes = parse_sizes(&value()?)?,
            "--merge-sizes" => merge_sizes = parse_sizes(&value()?)?,
            "--dir" => dir = PathBuf::from(value()?),
            other => return Err(format!("unknown argument {other}")),
        }
    }
    println!(
        "city_store: threads {} (RAYON_NUM_THREADS), files in {}",
        rayon::current_num_threads(),
        dir.display()
    );
    for &n in &sizes {
        store(n, &dir)?;
    }
    if !merge_sizes.is_empty() {
        merge(&merge_sizes)?;
    }
    Ok(())
}
