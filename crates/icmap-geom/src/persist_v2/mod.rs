//! The native map file, format version 2: compact records, provenance, spatial blocks with an
//! index (region loading), per-block checksums; still atomic. Version 1 files (`persist.rs`) are
//! read as before.
//!
//! Layout (integers and floats little-endian):
//!
//! ```text
//! magic        8 bytes  b"ICMAPGM\0"
//! version      u32      2
//! header       64 bytes
//!   smoothing    f64      MapConfig::smoothing
//!   spacing      f64      MapConfig::spacing
//!   next_id      u64
//!   count        u64      number of instances
//!   quantum      f64      metres per unit of quantised coordinates (0: every instance exact)
//!   n_blocks     u64
//!   body_len     u64      bytes of all blocks together
//!   reserved     u64      0
//! index        n_blocks * 64 bytes, per block:
//!   xmin ymin xmax ymax  4 f64   the union of its instances' bounding boxes
//!   offset       u64      from the start of the body (blocks are contiguous, in index order)
//!   len          u64      bytes
//!   count        u64      instances
//!   checksum     u64      hash64 of the block's bytes
//! head_sum     u64      hash64 of every byte before it (magic .. index)
//! body         the blocks: records of `count` instances each
//! ```
//!
//! The file is exactly `12 + 64 + 64 * n_blocks + 8 + body_len` bytes. An instance record
//! (varint = LEB128 unsigned, at most 10 bytes; zigzag for signed values):
//!
//! ```text
//! id           varint
//! flags        u8       bits 0-1 class (0, 1, 2), bit 2 closed, bit 3 exact coordinates; others 0
//! first_frame  zigzag varint
//! frame_span   varint   last_frame - first_frame
//! observations varint   (< 2^32)
//! n_drives     varint, then the drives ascending: the first as a varint, then each gap - 1
//! n_points     varint
//! coordinates  exact: n * (f64 x, f64 y); quantised: zigzag varints, x then y per point, of
//!              X_0 = round(x_0 / quantum), then X_1 - X_0, then for i >= 2 the residual of the
//!              linear prediction, X_i - (2 X_{i-1} - X_{i-2}) (integers, wrapping mod 2^64)
//! ```
//!
//! **Encodings.** [`Encoding::Exact`] stores coordinates as they are (the map loads bit for bit);
//! [`Encoding::Compact`] rounds them to a grid of [`QUANTUM`] = 0.1 mm, so a loaded coordinate
//! differs from the saved one by at most 0.05 mm (plus float rounding, < 1e-9 m for coordinates
//! below 10^5 m): densely sampled smooth polylines then take 2-3 bytes per point instead of 16.
//! (An instance with a coordinate beyond 10^9 m is stored exactly in either encoding.)
//! Loading a compact file and saving it compact again gives the same bytes.
//!
//! **Blocks.** Instances are ordered along a Hilbert curve of their middle points (ties by id) and cut into blocks of [`BLOCK_INSTANCES`]; [`load_region`] reads the header, the index
//! and only the blocks whose box meets the region, and keeps the instances whose own box meets
//! it.
//!
//! **Checks.** Every byte is covered by a checksum (the head's or a block's), then the structure
//! is checked (contiguous blocks, counts, lengths, varints, flags; no allocation larger than the
//! bytes that are there), then the values (the store's instance invariants, unique ids). Every
//! problem is a [`GeomError::Format`] naming the file.

mod codec;
pub(crate) mod cursor;
mod decode;
mod encode;
mod head;
mod load;

pub use codec::hash64;
pub use decode::from_bytes;
pub use encode::{save, to_bytes};
pub use load::{load, load_region, region_box};

/// The format version this module writes.
pub const FORMAT_VERSION_2: u32 = 2;
/// Grid of [`Encoding::Compact`] coordinates, metres (0.1 mm).
pub const QUANTUM: f64 = 1e-4;
/// `1 / QUANTUM`: encoding multiplies by it.
const INV_QUANTUM: f64 = 1e4;
/// Instances per block (the granularity of region loading).
pub const BLOCK_INSTANCES: usize = 256;

const PREFIX: usize = 12;
const HEADER: usize = 64;
const INDEX_ENTRY: usize = 64;
/// Largest |coordinate| (metres) stored quantised: 10^13 quanta, far inside the exact integers
/// of f64, so rounding, decoding and re-encoding are exact to a fraction of a quantum.
const MAX_QUANTISED: f64 = 1e9;

/// How coordinates are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Encoding {
    /// As they are (bit for bit).
    #[default]
    Exact,
    /// Rounded to [`QUANTUM`] and delta-coded (at most 0.05 mm off).
    Compact,
}

#[cfg(test)]
mod tests {
    use super::codec::*;
    use super::cursor::*;
    use super::decode::*;
    use super::encode::*;
    use super::head::*;
    use super::load::*;
    use super::*;
    use crate::error::GeomError;
    use crate::persist::MAGIC;
    use crate::store::{GlobalMap, Instance, MapConfig};
    use crate::test_util::{check_flipped_bytes, check_truncations, p, reason};
    use crate::types::{MapClass, Point};
    use parry2d_f64::bounding_volume::BoundingVolume;
    use proptest::prelude::*;

    fn inst(
        id: u64,
        class: MapClass,
        points: Vec<Point>,
        frames: (i64, i64),
        obs: u32,
    ) -> Instance {
        Instance {
            id,
            class,
            points,
            closed: class.is_closed(),
            first_frame: frames.0,
            last_frame: frames.1,
            observations: obs,
        }
    }

    /// A map with gaps in the ids, extreme bookkeeping, provenance and far coordinates.
    fn sample_map() -> GlobalMap {
        let cfg = MapConfig {
            smoothing: 0.25,
            spacing: 0.75,
        };
        let wave: Vec<Point> = (0..40)
            .map(|i| p(1000.0 + i as f64 * 0.75, -250.0 + (i as f64 / 5.0).sin()))
            .collect();
        let instances = vec![
            inst(
                0,
                MapClass::PedCrossing,
                vec![p(0.0, 0.0), p(2.0, 0.0), p(2.0, 1.5), p(0.0, 1.5)],
                (-3, 7),
                4,
            ),
            inst(5, MapClass::Divider, wave, (2, 2), 1),
            inst(
                2,
                MapClass::Boundary,
                vec![p(-1e6, 3.0), p(1e6, 3.0 + f64::EPSILON)],
                (i64::MIN, i64::MAX),
                u32::MAX,
            ),
            // At the edge of the coordinate domain (|x| <= 1e7 m, issue 14.3).
            inst(
                7,
                MapClass::Boundary,
                vec![p(9.999_999e6, 0.0), p(-9.999_999e6, 1.0)],
                (0, 1),
                2,
            ),
        ];
        let mut m = GlobalMap::from_parts(cfg, 9, instances).unwrap();
        m.set_drives(0, &[0, 3, u32::MAX]).unwrap();
        m.set_drives(5, &[7]).unwrap();
        m
    }

    fn same(a: &GlobalMap, b: &GlobalMap) {
        assert_eq!(a.config(), b.config());
        assert_eq!(a.next_id(), b.next_id());
        assert_eq!(a.instances(), b.instances());
        for i in a.instances() {
            assert_eq!(a.drives(i.id), b.drives(i.id));
        }
        b.check_invariants().unwrap();
    }

    /// A grid of `n` dividers 10 m apart (for blocks and regions).
    fn grid_map(n: usize, encoding_noise: f64) -> GlobalMap {
        let mut m = GlobalMap::new(MapConfig::default()).unwrap();
        let side = (n as f64).sqrt().ceil() as usize;
        for k in 0..n {
            let (x, y) = ((k % side) as f64 * 10.0, (k / side) as f64 * 10.0);
            let class = MapClass::ALL[k % 3];
            let pts = if class.is_closed() {
                vec![p(x, y), p(x + 3.0, y), p(x + 3.0, y + 2.0), p(x, y + 2.0)]
            } else {
                (0..8)
                    .map(|i| p(x + i as f64, y + encoding_noise * (i as f64 * 1.7).sin()))
                    .collect()
            };
            m.insert(class, &pts, k as i64).unwrap();
        }
        m.tag_drive(3);
        m
    }

    #[test]
    fn hash_detects_single_word_changes() {
        let a = hash64(b"0123456789abcdef!");
        assert_ne!(a, hash64(b"0123456789abcdeg!"));
        assert_ne!(a, hash64(b"0123456789abcdef!\0"), "length is mixed in");
        assert_ne!(hash64(b""), hash64(b"\0"));
    }

    #[test]
    fn varints_round_trip() {
        for v in [0u64, 1, 127, 128, 300, u32::MAX as u64, u64::MAX] {
            let mut out = Vec::new();
            put_varint(&mut out, v);
            assert!(out.len() <= 10);
            let mut c = Cursor::new(&out);
            assert_eq!(c.varint("v").unwrap(), v);
        }
        for v in [0i64, -1, 1, i64::MIN, i64::MAX] {
            assert_eq!(unzigzag(zigzag(v)), v);
        }
        let bad = [0xffu8; 11];
        assert!(Cursor::new(&bad).varint("v").is_err());
    }

    #[test]
    fn exact_round_trip_with_provenance() {
        let m = sample_map();
        let bytes = to_bytes(&m, Encoding::Exact);
        let back = from_bytes(&bytes).unwrap();
        same(&m, &back);
        assert_eq!(
            to_bytes(&back, Encoding::Exact),
            bytes,
            "deterministic bytes"
        );
        let empty = GlobalMap::new(MapConfig::default()).unwrap();
        same(
            &empty,
            &from_bytes(&to_bytes(&empty, Encoding::Exact)).unwrap(),
        );
        same(
            &empty,
            &from_bytes(&to_bytes(&empty, Encoding::Compact)).unwrap(),
        );
    }

    #[test]
    fn compact_round_trip_within_tolerance() {
        let m = sample_map();
        let bytes = to_bytes(&m, Encoding::Compact);
        let back = from_bytes(&bytes).unwrap();
        back.check_invariants().unwrap();
        assert_eq!(back.ids(), m.ids());
        for a in m.instances() {
            let b = back.get(a.id).unwrap();
            assert_eq!(
                (
                    a.class,
                    a.closed,
                    a.first_frame,
                    a.last_frame,
                    a.observations
                ),
                (
                    b.class,
                    b.closed,
                    b.first_frame,
                    b.last_frame,
                    b.observations
                )
            );
            assert_eq!(m.drives(a.id), back.drives(a.id));
            assert_eq!(a.points.len(), b.points.len());
            for (q, r) in a.points.iter().zip(&b.points) {
                if a.id == 7 {
                    assert_eq!(q, r, "out of the quantised range: exact");
                } else {
                    let tol = QUANTUM / 2.0 + 1e-9;
                    assert!(
                        (q.x - r.x).abs() <= tol && (q.y - r.y).abs() <= tol,
                        "{q:?} {r:?}"
                    );
                }
            }
        }
        assert_eq!(
            to_bytes(&back, Encoding::Compact),
            bytes,
            "compact is idempotent"
        );
        // Smooth dense polylines: far fewer bytes than exact coordinates.
        let g = grid_map(2000, 0.3);
        let (exact, compact) = (
            to_bytes(&g, Encoding::Exact).len(),
            to_bytes(&g, Encoding::Compact).len(),
        );
        let v1 = crate::persist::to_bytes(&g).len();
        assert!(exact < v1, "{exact} vs v1 {v1}");
        assert!(compact * 3 < v1, "{compact} vs v1 {v1}");
    }

    #[test]
    fn version_1_still_loads() {
        let m = sample_map();
        let v1 = crate::persist::to_bytes(&m);
        let back = from_bytes(&v1).unwrap();
        assert_eq!(back.instances(), m.instances());
        assert!(back.drives(0).is_empty(), "version 1 has no provenance");
        let mut bad = v1.clone();
        let n = bad.len();
        bad[n - 1] ^= 1;
        assert!(reason(from_bytes(&bad).unwrap_err()).contains("checksum"));
    }

    #[test]
    fn files_round_trip_and_regions() {
        let dir = std::env::temp_dir().join(format!("icmap-persist2-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("city.icmap");
        let m = grid_map(3000, 0.2);
        // The file written in parts is byte for byte the joined bytes, in both encodings.
        for encoding in [Encoding::Compact, Encoding::Exact] {
            save(&m, &path, encoding).unwrap();
            assert_eq!(std::fs::read(&path).unwrap(), to_bytes(&m, encoding));
        }
        same(&m, &load(&path).unwrap());
        let regions = [
            [0.0, 0.0, 40.0, 40.0],
            [-1e9, -1e9, 1e9, 1e9],
            [f64::NEG_INFINITY, 100.0, f64::INFINITY, 100.0],
            [5000.0, 5000.0, 6000.0, 6000.0],
            [123.4, 77.0, 301.0, 250.5],
        ];
        for r in regions {
            let region = region_box(r).unwrap();
            let got = load_region(&path, r).unwrap();
            got.check_invariants().unwrap();
            let want: Vec<&Instance> = m
                .instances()
                .into_iter()
                .filter(|i| region.intersects(&i.aabb()))
                .collect();
            assert_eq!(got.instances(), want, "{r:?}");
            assert_eq!(got.next_id(), m.next_id());
            for i in got.instances() {
                assert_eq!(got.drives(i.id), &[3]);
            }
        }
        // Compact files and version-1 files give the same regions (v1: read whole).
        save(&m, &path, Encoding::Compact).unwrap();
        let r = [123.4, 77.0, 301.0, 250.5];
        let ids_c = load_region(&path, r).unwrap().ids();
        std::fs::write(&path, crate::persist::to_bytes(&m)).unwrap();
        let ids_1 = load_region(&path, r).unwrap().ids();
        assert_eq!(ids_c, ids_1);
        assert!(!ids_1.is_empty());
        // Bad regions.
        for bad in [
            [f64::NAN, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, f64::NAN],
            [2.0, 0.0, 1.0, 1.0],
            [0.0, 2.0, 1.0, 1.0],
        ] {
            assert!(load_region(&path, bad).is_err(), "{bad:?}");
        }
        assert!(matches!(
            load_region(&dir.join("missing.icmap"), r),
            Err(GeomError::Io { .. })
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A region load reads only the blocks it needs: a corrupt block elsewhere goes unnoticed by
    /// it (and is found by a full load).
    #[test]
    fn region_load_skips_other_blocks() {
        let dir = std::env::temp_dir().join(format!("icmap-persist2r-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.icmap");
        let m = grid_map(4 * BLOCK_INSTANCES, 0.0);
        let mut bytes = to_bytes(&m, Encoding::Exact);
        let head = parse_head(&bytes).unwrap();
        assert_eq!(head.blocks.len(), 4);
        let last = head.blocks[3];
        let at = (head.len() + last.offset + last.len / 2) as usize;
        bytes[at] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        let far = entry_box(&last);
        let region = head
            .blocks
            .iter()
            .map(entry_box)
            .find(|b| !b.intersects(&far))
            .expect("a block away from the last one");
        let r = [region.mins.x, region.mins.y, region.maxs.x, region.maxs.y];
        let got = load_region(&path, r).unwrap();
        assert!(!got.is_empty());
        assert!(reason(load(&path).unwrap_err()).contains("checksum mismatch in block 3"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn truncation_and_flipped_bytes_are_detected() {
        for encoding in [Encoding::Exact, Encoding::Compact] {
            let bytes = to_bytes(&sample_map(), encoding);
            check_truncations(&bytes, from_bytes);
            check_flipped_bytes(&bytes, from_bytes);
        }
        let mut b = to_bytes(&sample_map(), Encoding::Exact);
        b[8..12].copy_from_slice(&3u32.to_le_bytes());
        assert!(reason(from_bytes(&b).unwrap_err()).contains("unsupported format version 3"));
        assert!(reason(from_bytes(b"{\"type\": 1}").unwrap_err()).contains("not an icmapper"));
    }

    /// Rewrites the head checksum after an edit of the header or index. An absurd block count
    /// wraps (as in a release build), so the debug build runs the same tests.
    fn reseal_head(b: &mut [u8]) {
        let n_blocks = u64::from_le_bytes(b[52..60].try_into().unwrap()) as usize;
        let end = (PREFIX + HEADER).wrapping_add(n_blocks.wrapping_mul(INDEX_ENTRY));
        let sum = hash64(&b[..end]);
        b[end..end + 8].copy_from_slice(&sum.to_le_bytes());
    }

    /// Rewrites the checksum of block 0 after an edit of its bytes.
    fn reseal_block0(b: &mut [u8]) {
        let head = PREFIX + HEADER + INDEX_ENTRY + 8;
        let len = u64::from_le_bytes(
            b[PREFIX + HEADER + 40..PREFIX + HEADER + 48]
                .try_into()
                .unwrap(),
        ) as usize;
        let sum = hash64(&b[head..head + len]);
        b[PREFIX + HEADER + 56..PREFIX + HEADER + 64].copy_from_slice(&sum.to_le_bytes());
        reseal_head(b);
    }

    #[test]
    fn a_coordinate_outside_the_domain_is_refused_on_load() {
        // Issue 14.3: a record holding |x| > 1e7 m, with valid checksums, is not a valid map.
        let cfg = MapConfig {
            smoothing: 0.5,
            spacing: 1.0,
        };
        let line = vec![p(1234.5, 0.0), p(1300.25, 1.0)];
        let m = GlobalMap::from_parts(cfg, 1, vec![inst(0, MapClass::Divider, line, (0, 0), 1)])
            .unwrap();
        let mut b = to_bytes(&m, Encoding::Exact);
        assert!(from_bytes(&b).is_ok());
        let needle = 1234.5f64.to_le_bytes();
        let rec = PREFIX + HEADER + INDEX_ENTRY + 8; // block 0's first record
        let at = rec
            + b[rec..]
                .windows(8)
                .position(|w| w == needle)
                .expect("an exact record stores the coordinate's bits");
        b[at..at + 8].copy_from_slice(&5e7f64.to_le_bytes());
        // the block's box in the index (min x, min y, max x, max y) follows the record
        let bx = PREFIX + HEADER;
        b[bx + 16..bx + 24].copy_from_slice(&1e9f64.to_le_bytes());
        reseal_block0(&mut b);
        let err = from_bytes(&b).unwrap_err();
        assert!(
            format!("{err}").contains("outside the valid domain"),
            "unexpected error: {err}"
        );
    }

    #[test]
    fn absurd_headers_and_values_with_valid_checksums() {
        let bytes = to_bytes(&sample_map(), Encoding::Exact);
        let set = |off: usize, v: u64| {
            let mut b = bytes.clone();
            b[off..off + 8].copy_from_slice(&v.to_le_bytes());
            reseal_head(&mut b);
            reason(from_bytes(&b).unwrap_err())
        };
        // Header fields: next_id 28, count 36, quantum 44, n_blocks 52, body_len 60, reserved 68.
        assert!(set(36, u64::MAX).contains("instances"));
        assert!(set(52, u64::MAX >> 1).contains("blocks declared"));
        assert!(set(60, u64::MAX).contains("truncated"));
        assert!(set(68, 1).contains("reserved"));
        assert!(set(44, f64::NAN.to_bits()).contains("quantum"));
        assert!(set(28, 1).contains("next_id"));
        assert!(set(20, (-1.0f64).to_bits()).contains("spacing"));
        // Index entry 0: count 112, box 76.
        assert!(set(PREFIX + HEADER + 48, u64::MAX).contains("instances"));
        assert!(set(PREFIX + HEADER, f64::NAN.to_bits()).contains("box"));
        // Block 0 starts with the first record; its first byte is the id varint, then flags.
        let rec = PREFIX + HEADER + INDEX_ENTRY + 8;
        let mut b = bytes.clone();
        b[rec + 1] = 0b0111; // class 3
        reseal_block0(&mut b);
        assert!(reason(from_bytes(&b).unwrap_err()).contains("flags"));
        let mut b = bytes.clone();
        b[rec + 1] ^= 0b100; // closed flag against the class
        reseal_block0(&mut b);
        assert!(matches!(from_bytes(&b), Err(GeomError::Format { .. })));
        // A point count of 2^63 with a valid checksum: an error, no allocation.
        let mut b = bytes.clone();
        let mut c = Cursor::new(&b[rec..]);
        c.varint("id").unwrap();
        c.u8("flags").unwrap();
        for what in ["first", "span", "obs"] {
            c.varint(what).unwrap();
        }
        let nd = c.varint("drives").unwrap();
        for _ in 0..nd {
            c.varint("drive").unwrap();
        }
        let at = rec + c.pos;
        let mut huge = Vec::new();
        put_varint(&mut huge, 1 << 62);
        b.splice(at..at + 1, huge.iter().copied());
        // (Lengths now disagree with the index as well; either check may fire first.)
        assert!(matches!(from_bytes(&b), Err(GeomError::Format { .. })));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn arbitrary_bytes_never_panic(mut b in prop::collection::vec(any::<u8>(), 0..400), keep in 0u8..3) {
            if keep > 0 && b.len() >= PREFIX + HEADER + 8 {
                b[..8].copy_from_slice(MAGIC);
                b[8..12].copy_from_slice(&FORMAT_VERSION_2.to_le_bytes());
                b[52..60].copy_from_slice(&((keep - 1) as u64).to_le_bytes());
                if b.len() >= PREFIX + HEADER + 8 + (keep as usize - 1) * INDEX_ENTRY {
                    reseal_head(&mut b);
                }
            }
            let _ = from_bytes(&b);
        }

        #[test]
        fn random_maps_round_trip(insts in prop::collection::vec(
            (0u8..3, prop::collection::vec((-1e5..1e5f64, -1e5..1e5f64), 3..30), -100i64..100, 0i64..50, 1u32..1000,
             prop::collection::vec(0u32..20, 0..4)), 0..40), compact in any::<bool>()) {
            let mut drives = Vec::new();
            let instances: Vec<Instance> = insts.into_iter().enumerate().map(|(k, (c, pts, f, d, o, dr))| {
                drives.push(dr);
                inst(k as u64 * 3, MapClass::ALL[c as usize], pts.into_iter().map(|(x, y)| p(x, y)).collect(), (f, f + d), o)
            }).collect();
            let next = instances.len() as u64 * 3 + 1;
            let mut m = GlobalMap::from_parts(MapConfig::default(), next, instances).unwrap();
            for (k, dr) in drives.iter().enumerate() {
                m.set_drives(k as u64 * 3, dr).unwrap();
            }
            let encoding = if compact { Encoding::Compact } else { Encoding::Exact };
            let back = from_bytes(&to_bytes(&m, encoding)).unwrap();
            prop_assert_eq!(back.ids(), m.ids());
            for a in m.instances() {
                let b = back.get(a.id).unwrap();
                prop_assert_eq!(m.drives(a.id), back.drives(a.id));
                prop_assert_eq!((a.first_frame, a.last_frame, a.observations), (b.first_frame, b.last_frame, b.observations));
                for (q, r) in a.points.iter().zip(&b.points) {
                    let tol = if compact { QUANTUM / 2.0 + 1e-9 } else { 0.0 };
                    prop_assert!((q - r).abs().max() <= tol);
                }
            }
        }
    }
}
