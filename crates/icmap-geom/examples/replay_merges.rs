//! Replays recorded merges (see `benchmarks/record_merges.py`) through `merge_polygon` /
//! `merge_polyline` and prints the time per merge by class: the engine's merge cost without
//! Python or the store around it.
//!
//! `cargo run --release -p icmap-geom --example replay_merges -- FILE [REPS] [CLASS]`

use icmap_geom::merge::{merge_polygon, merge_polyline};
use icmap_geom::types::Point;
use std::time::Instant;

/// The allocator of the Python extension (`icmap-py`), so that the replay measures what it runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

type Case = (i64, Vec<Point>, Vec<Point>);

/// A little-endian reader over the recorded bytes.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let s = self
            .bytes
            .get(self.at..self.at + n)
            .ok_or("truncated file")?;
        self.at += n;
        Ok(s)
    }

    fn f64(&mut self) -> Result<f64, String> {
        let b: [u8; 8] = self.take(8)?.try_into().map_err(|_| "bad value")?;
        Ok(f64::from_le_bytes(b))
    }

    fn i64(&mut self) -> Result<i64, String> {
        let b: [u8; 8] = self.take(8)?.try_into().map_err(|_| "bad value")?;
        Ok(i64::from_le_bytes(b))
    }

    fn points(&mut self, n: usize) -> Result<Vec<Point>, String> {
        (0..n)
            .map(|_| Ok(Point::new(self.f64()?, self.f64()?)))
            .collect()
    }
}

fn read_cases(bytes: &[u8]) -> Result<Vec<Case>, String> {
    let mut cur = Cursor { bytes, at: 0 };
    let mut cases = Vec::new();
    while cur.at < bytes.len() {
        let cls = cur.i64()?;
        let ng = usize::try_from(cur.i64()?).map_err(|e| e.to_string())?;
        let nd = usize::try_from(cur.i64()?).map_err(|e| e.to_string())?;
        let g = cur.points(ng)?;
        let d = cur.points(nd)?;
        cases.push((cls, g, d));
    }
    Ok(cases)
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .ok_or("usage: replay_merges FILE [REPS] [CLASS]")?;
    let reps: usize = args
        .get(2)
        .map_or(Ok(5), |s| s.parse())
        .map_err(|e| format!("{e}"))?;
    let only: Option<i64> = args
        .get(3)
        .map(|s| s.parse())
        .transpose()
        .map_err(|e| format!("{e}"))?;
    let bytes = std::fs::read(path).map_err(|e| format!("{path}: {e}"))?;
    let cases = read_cases(&bytes)?;
    let mut checksum = 0.0;
    for cls in [0i64, 1, 2] {
        if only.is_some_and(|o| o != cls) {
            continue;
        }
        let sel: Vec<&Case> = cases.iter().filter(|c| c.0 == cls).collect();
        let t = Instant::now();
        for _ in 0..reps {
            for (c, g, d) in &sel {
                let out = if *c == 0 {
                    merge_polygon(g, d, 1.0)
                } else {
                    merge_polyline(g, d, 0.5, 1.0)
                }
                .map_err(|e| e.to_string())?;
                checksum += out[out.len() / 2].x;
            }
        }
        let us = t.elapsed().as_secs_f64() / (reps * sel.len().max(1)) as f64 * 1e6;
        println!("class {cls}: {} merges, {us:.2} us/merge", sel.len());
    }
    println!("checksum {checksum:.9}");
    Ok(())
}
