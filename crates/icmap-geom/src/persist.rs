//! The native map file: versioned binary format, atomic writes.
//!
//! Layout (all integers and floats little-endian):
//!
//! ```text
//! magic        8 bytes  b"ICMAPGM\0"
//! version      u32      FORMAT_VERSION (1)
//! smoothing    f64      MapConfig::smoothing
//! spacing      f64      MapConfig::spacing
//! next_id      u64
//! count        u64      number of instances, then per instance (ascending id):
//!   id           u64
//!   class        u8     0 ped_crossing, 1 divider, 2 boundary
//!   closed       u8     0 or 1
//!   first_frame  i64
//!   last_frame   i64
//!   observations u32
//!   n            u64    number of points
//!   coords       n * (f64 x, f64 y)
//! checksum     u64      FNV-1a 64 of every byte before it
//! ```
//!
//! Reading checks, in order: magic, version, structure (truncation / trailing bytes), checksum,
//! then the meaning of the values (classes, finite coordinates, unique ids ...). Every problem is a
//! [`GeomError::Format`] naming it; a missing or unreadable file is a [`GeomError::Io`].

use crate::error::{GeomError, Result};
use crate::persist_v2::cursor::Cursor;
use crate::store::{GlobalMap, Instance};
use crate::types::{MapClass, Point};
use std::ffi::{OsStr, OsString};
use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

/// First bytes of every map file.
pub const MAGIC: &[u8; 8] = b"ICMAPGM\0";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// Bytes of the header after magic and version: smoothing, spacing, next_id, count.
const HEADER_REST: usize = 8 + 8 + 8 + 8;
/// Bytes of an instance record without its coordinates.
const RECORD_FIXED: usize = 8 + 1 + 1 + 8 + 8 + 4 + 8;

/// FNV-1a 64-bit hash.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The map file contents of `map` (instances in ascending id order).
pub fn to_bytes(map: &GlobalMap) -> Vec<u8> {
    let instances = map.instances();
    let n_points: usize = instances.iter().map(|i| i.points.len()).sum();
    let mut out =
        Vec::with_capacity(12 + HEADER_REST + instances.len() * RECORD_FIXED + n_points * 16 + 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    let cfg = map.config();
    out.extend_from_slice(&cfg.smoothing.to_le_bytes());
    out.extend_from_slice(&cfg.spacing.to_le_bytes());
    out.extend_from_slice(&map.next_id().to_le_bytes());
    out.extend_from_slice(&(instances.len() as u64).to_le_bytes());
    for inst in instances {
        out.extend_from_slice(&inst.id.to_le_bytes());
        out.push(inst.class.index());
        out.push(inst.closed as u8);
        out.extend_from_slice(&inst.first_frame.to_le_bytes());
        out.extend_from_slice(&inst.last_frame.to_le_bytes());
        out.extend_from_slice(&inst.observations.to_le_bytes());
        out.extend_from_slice(&(inst.points.len() as u64).to_le_bytes());
        for p in &inst.points {
            out.extend_from_slice(&p.x.to_le_bytes());
            out.extend_from_slice(&p.y.to_le_bytes());
        }
    }
    let sum = fnv1a64(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// Parses map file contents (see the module docs); errors name `<bytes>` as the path.
pub fn from_bytes(bytes: &[u8]) -> Result<GlobalMap> {
    parse(bytes, "<bytes>")
}

/// Writes `map` to `path` atomically (temp file in the same folder, fsync, rename).
pub fn save(map: &GlobalMap, path: &Path) -> Result<()> {
    write_atomic(path, &to_bytes(map))
}

/// Reads a map file; a foreign, truncated or corrupt file gives `GeomError::Format`.
pub fn load(path: &Path) -> Result<GlobalMap> {
    let bytes = fs::read(path).map_err(|source| GeomError::Io {
        path: path.display().to_string(),
        source,
    })?;
    parse(&bytes, &path.display().to_string())
}

/// Writes `bytes` to `path` atomically: a temporary file `.NAME.tmp.<pid>.<n>` in the same folder
/// is written, fsynced and renamed over `path`; the folder is then fsynced (best effort). On error
/// the temporary file is removed and `path` is untouched.
///
/// A writer that is killed mid-save cannot remove its temporary file. So every writer holds an
/// exclusive lock (`flock`) on its temporary file from creating it to the rename, and every save
/// first removes the temporary files of `path` that nobody holds a lock on and that have not been
/// written to for [`STALE_TEMP_AGE`] ([`remove_stale_temps`]): the kernel releases the locks of a
/// dead process, never those of a live one (whatever its PID namespace), and the age covers the
/// instant between creating a file and locking it.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_parts(path, &[bytes])
}

/// [`write_atomic`] of the concatenation of `parts` (written one after the other, without
/// joining them in memory first).
pub fn write_atomic_parts(path: &Path, parts: &[&[u8]]) -> Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let io_err = |p: &Path| {
        let p = p.display().to_string();
        move |source| GeomError::Io { path: p, source }
    };
    let file_name = path.file_name().ok_or_else(|| GeomError::Io {
        path: path.display().to_string(),
        source: std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path has no file name",
        ),
    })?;
    let dir: PathBuf = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    remove_stale_temps(&dir, file_name);
    // A name left by a dead process with this PID (a reused PID) is skipped, not an error.
    let (tmp, mut f) = (|| {
        let mut last = None;
        for _ in 0..64 {
            let mut tmp_name = temp_prefix(file_name);
            tmp_name.push(format!(
                "{}.{}",
                std::process::id(),
                COUNTER.fetch_add(1, Ordering::Relaxed)
            ));
            let tmp = dir.join(tmp_name);
            match OpenOptions::new().write(true).create_new(true).open(&tmp) {
                Ok(f) => return Ok((tmp, f)),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some((tmp, e)),
                Err(e) => return Err(io_err(&tmp)(e)),
            }
        }
        let (tmp, e) = last.expect("at least one attempt");
        Err(io_err(&tmp)(e))
    })()?;
    let result = (|| {
        // (A file system without locks: nobody can tell this file from a dead writer's, and
        // `remove_stale_temps` removes nothing there either.)
        let _ = f.lock();
        for bytes in parts {
            f.write_all(bytes).map_err(io_err(&tmp))?;
        }
        f.sync_all().map_err(io_err(&tmp))?;
        fs::rename(&tmp, path).map_err(io_err(path))
    })();
    drop(f);
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
        return result;
    }
    // Make the rename durable (best effort: not every platform can open a folder).
    if let Ok(d) = File::open(&dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// A temporary file of a save is stale (its writer died) when nobody holds its lock and nothing
/// was written to it for this long (see [`write_atomic`]).
pub const STALE_TEMP_AGE: Duration = Duration::from_secs(60);

/// `.NAME.tmp.`: the start of the temporary files of `NAME`.
fn temp_prefix(file_name: &OsStr) -> OsString {
    let mut s = OsString::from(".");
    s.push(file_name);
    s.push(".tmp.");
    s
}

/// Whether `name` is `prefix` followed by `<digits>.<digits>`.
fn is_temp_name(name: &OsStr, prefix: &OsStr) -> bool {
    let Some(rest) = name
        .as_encoded_bytes()
        .strip_prefix(prefix.as_encoded_bytes())
    else {
        return false;
    };
    let digits = |s: &[u8]| !s.is_empty() && s.iter().all(u8::is_ascii_digit);
    let mut parts = rest.split(|&b| b == b'.');
    matches!(
        (parts.next(), parts.next(), parts.next()),
        (Some(pid), Some(n), None) if digits(pid) && digits(n)
    )
}

/// Removes the temporary files `.NAME.tmp.<pid>.<n>` of saves of `dir/NAME` whose writers died
/// (killed mid-save): those nobody holds a lock on and that were last written
/// [`STALE_TEMP_AGE`] ago or more. A live writer's file is never removed (it holds the lock), nor
/// any other file. Best effort (errors skip a file); returns how many were removed.
pub fn remove_stale_temps(dir: &Path, file_name: &OsStr) -> usize {
    let Ok(entries) = fs::read_dir(dir) else {
        return 0;
    };
    let prefix = temp_prefix(file_name);
    let now = SystemTime::now();
    let mut removed = 0;
    for entry in entries.flatten() {
        if !is_temp_name(&entry.file_name(), &prefix) {
            continue;
        }
        let path = entry.path();
        let Ok(f) = File::open(&path) else {
            continue;
        };
        let stale = f
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| now.duration_since(t).ok())
            .is_some_and(|age| age >= STALE_TEMP_AGE);
        // `try_lock` fails while another open file holds the lock (a live writer), and where
        // locks are unsupported. The file is removed while this lock is held.
        if stale && f.try_lock().is_ok() && fs::remove_file(&path).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// An instance as read, before its values are checked.
struct RawInstance {
    id: u64,
    class: u8,
    closed: u8,
    first_frame: i64,
    last_frame: i64,
    observations: u32,
    points: Vec<Point>,
}

fn parse(bytes: &[u8], path: &str) -> Result<GlobalMap> {
    let fmt = |reason: String| GeomError::Format {
        path: path.to_string(),
        reason,
    };
    // Magic: a short file that starts like a map file is truncated, anything else is foreign.
    let head = &bytes[..bytes.len().min(MAGIC.len())];
    if head != &MAGIC[..head.len()] || (head.is_empty() && !bytes.is_empty()) {
        return Err(fmt("not an icmapper map file (wrong magic bytes)".into()));
    }
    if bytes.is_empty() {
        return Err(fmt("not an icmapper map file (empty file)".into()));
    }
    let mut r = Cursor::whole_file(bytes);
    r.take(MAGIC.len(), "magic").map_err(fmt)?;
    let version = r.u32("format version").map_err(fmt)?;
    if version != FORMAT_VERSION {
        return Err(fmt(format!(
            "unsupported format version {version} (this build reads version {FORMAT_VERSION}; the file may come from a newer icmapper)"
        )));
    }
    // Structure: everything up to the checksum must be present.
    let (config, next_id, raw) = (|| -> std::result::Result<_, String> {
        let (config, next_id, count) = r.map_head()?;
        r.fits(
            count,
            RECORD_FIXED,
            format_args!("{count} instances declared"),
        )?;
        let mut raw = Vec::with_capacity(count as usize);
        for k in 0..count {
            let id = r.u64("instance id")?;
            let class = r.u8("class")?;
            let closed = r.u8("closed flag")?;
            let first_frame = r.i64("first_frame")?;
            let last_frame = r.i64("last_frame")?;
            let observations = r.u32("observations")?;
            let n = r.u64("point count")?;
            r.fits(
                n,
                16,
                format_args!("instance #{k} (id {id}) declares {n} points"),
            )?;
            let mut points = Vec::with_capacity(n as usize);
            for _ in 0..n {
                points.push(r.point()?);
            }
            raw.push(RawInstance {
                id,
                class,
                closed,
                first_frame,
                last_frame,
                observations,
                points,
            });
        }
        Ok((config, next_id, raw))
    })()
    .map_err(fmt)?;
    let body_end = r.pos;
    let stored = r.u64("checksum").map_err(fmt)?;
    if r.remaining() != 0 {
        return Err(fmt(format!(
            "{} unexpected trailing byte(s) after the checksum",
            r.remaining()
        )));
    }
    let computed = fnv1a64(&bytes[..body_end]);
    if stored != computed {
        return Err(fmt(format!("checksum mismatch (stored {stored:#018x}, computed {computed:#018x}): the file is corrupt")));
    }
    // Meaning of the values.
    config
        .validate()
        .map_err(|e| fmt(format!("bad config: {e}")))?;
    let mut instances = Vec::with_capacity(raw.len());
    for ri in raw {
        let class = MapClass::try_from(ri.class as i64)
            .map_err(|_| fmt(format!("invalid class {} for instance {}", ri.class, ri.id)))?;
        let closed = match ri.closed {
            0 => false,
            1 => true,
            v => {
                return Err(fmt(format!(
                    "invalid closed flag {v} for instance {}",
                    ri.id
                )))
            }
        };
        if ri
            .points
            .iter()
            .any(|p| !(p.x.is_finite() && p.y.is_finite()))
        {
            return Err(fmt(format!("non-finite coordinate in instance {}", ri.id)));
        }
        instances.push(Instance {
            id: ri.id,
            class,
            points: ri.points,
            closed,
            first_frame: ri.first_frame,
            last_frame: ri.last_frame,
            observations: ri.observations,
        });
    }
    GlobalMap::from_parts(config, next_id, instances).map_err(|e| fmt(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::MapConfig;
    use crate::test_util::{check_flipped_bytes, check_truncations, p, reason};
    use proptest::prelude::*;

    /// A map built from stored parts (no dependency on resampling), with a gap in the ids.
    fn sample_map() -> GlobalMap {
        let cfg = MapConfig {
            smoothing: 0.25,
            spacing: 0.75,
        };
        let instances = vec![
            Instance {
                id: 0,
                class: MapClass::PedCrossing,
                points: vec![p(0.0, 0.0), p(2.0, 0.0), p(2.0, 1.5), p(0.0, 1.5)],
                closed: true,
                first_frame: -3,
                last_frame: 7,
                observations: 4,
            },
            Instance {
                id: 5,
                class: MapClass::Divider,
                points: vec![p(10.0, -1.0), p(11.0, -1.25), p(12.5, -1.0)],
                closed: false,
                first_frame: 2,
                last_frame: 2,
                observations: 1,
            },
            Instance {
                id: 2,
                class: MapClass::Boundary,
                points: vec![p(-1e6, 3.0), p(1e6, 3.0 + f64::EPSILON)],
                closed: false,
                first_frame: i64::MIN,
                last_frame: i64::MAX,
                observations: u32::MAX,
            },
        ];
        GlobalMap::from_parts(cfg, 9, instances).unwrap()
    }

    fn same(a: &GlobalMap, b: &GlobalMap) {
        assert_eq!(a.config(), b.config());
        assert_eq!(a.next_id(), b.next_id());
        assert_eq!(a.instances(), b.instances());
        b.check_invariants().unwrap();
    }

    /// Issue 14.5: writers killed mid-save left `.NAME.tmp.<pid>.<n>` files (up to 160 MB each)
    /// that no later save removed. A save now removes those of dead writers (unlocked, not
    /// written to for a minute), whatever their PID, and nothing else: not a live writer's
    /// (locked), not one just created, not another file's.
    #[test]
    fn saves_remove_the_temp_files_of_dead_writers_only() {
        let dir = std::env::temp_dir().join(format!("icmap-stale-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map.icmap");
        let hour_ago = SystemTime::now() - Duration::from_secs(3600);
        let make = |name: &str, old: bool| -> File {
            let mut f = File::create(dir.join(name)).unwrap();
            f.write_all(b"partial map").unwrap();
            if old {
                f.set_modified(hour_ago).unwrap();
            }
            f
        };
        let pid = std::process::id();
        let dead = [
            ".map.icmap.tmp.123.0".to_string(),
            ".map.icmap.tmp.99999999.17".to_string(),
            format!(".map.icmap.tmp.{pid}.999999"), // this PID, reused: no lock, so dead
        ];
        for name in &dead {
            make(name, true);
        }
        let live = make(".map.icmap.tmp.42.1", true);
        live.lock().unwrap();
        let keep = [
            ".map.icmap.tmp.42.1",      // a live writer's (locked)
            ".map.icmap.tmp.43.0",      // just created (younger than STALE_TEMP_AGE)
            ".other.icmap.tmp.1.2",     // another map's
            ".map.icmap.tmp.x.1",       // not <pid>.<n>
            ".map.icmap.tmp.1.2.3",     //
            ".map.icmap.tmp.1.",        //
            ".map.icmap.tmp..1",        //
            "map.icmap.tmp.1.2",        // no leading dot
            ".map.icmap.tmp.1.2.extra", //
        ];
        for name in &keep[1..] {
            make(name, !name.contains(".43."));
        }
        save(&sample_map(), &path).unwrap();
        let mut names: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        let mut want: Vec<String> = keep.iter().map(|s| s.to_string()).collect();
        want.push("map.icmap".into());
        want.sort();
        assert_eq!(names, want);
        same(&sample_map(), &load(&path).unwrap());
        // The live writer dies (its lock goes with it): the next save removes its file.
        drop(live);
        assert_eq!(remove_stale_temps(&dir, OsStr::new("map.icmap")), 1);
        assert!(!dir.join(".map.icmap.tmp.42.1").exists());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn fnv_known_values() {
        assert_eq!(fnv1a64(b""), 0xcbf29ce484222325);
        assert_eq!(fnv1a64(b"a"), 0xaf63dc4c8601ec8c);
        assert_eq!(fnv1a64(b"foobar"), 0x85944171f73967e8);
    }

    #[test]
    fn bytes_round_trip() {
        let m = sample_map();
        let bytes = to_bytes(&m);
        let back = from_bytes(&bytes).unwrap();
        same(&m, &back);
        assert_eq!(to_bytes(&back), bytes, "deterministic bytes");
        let empty = GlobalMap::new(MapConfig::default()).unwrap();
        same(&empty, &from_bytes(&to_bytes(&empty)).unwrap());
    }

    #[test]
    fn file_round_trip_and_atomic_overwrite() {
        let dir = std::env::temp_dir().join(format!("icmap-persist-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map.icmap");
        let m = sample_map();
        save(&m, &path).unwrap();
        same(&m, &load(&path).unwrap());
        // Overwrite with a different map; no temporary files are left behind.
        let empty = GlobalMap::new(MapConfig::default()).unwrap();
        save(&empty, &path).unwrap();
        assert!(load(&path).unwrap().is_empty());
        let names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("map.icmap")]);
        // Missing file -> Io; a folder as target -> Io.
        assert!(matches!(
            load(&dir.join("missing.icmap")),
            Err(GeomError::Io { .. })
        ));
        assert!(matches!(save(&m, &dir), Err(GeomError::Io { .. })));
        assert!(matches!(
            save(&m, &dir.join("no/such/dir/map.icmap")),
            Err(GeomError::Io { .. })
        ));
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn wrong_magic_and_version() {
        let bytes = to_bytes(&sample_map());
        let mut b = bytes.clone();
        b[0] = b'X';
        assert!(reason(from_bytes(&b).unwrap_err()).contains("not an icmapper map file"));
        assert!(
            reason(from_bytes(b"{\"type\": \"FeatureCollection\"}").unwrap_err())
                .contains("not an icmapper")
        );
        assert!(reason(from_bytes(b"").unwrap_err()).contains("not an icmapper"));
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&2u32.to_le_bytes());
        assert!(reason(from_bytes(&b).unwrap_err()).contains("unsupported format version 2"));
    }

    #[test]
    fn truncation_is_detected() {
        check_truncations(&to_bytes(&sample_map()), from_bytes);
    }

    #[test]
    fn every_flipped_byte_is_detected() {
        check_flipped_bytes(&to_bytes(&sample_map()), from_bytes);
    }

    /// Rewrites the checksum after an edit, so that the value checks are reached.
    fn reseal(b: &mut [u8]) {
        let n = b.len() - 8;
        let sum = fnv1a64(&b[..n]);
        b[n..].copy_from_slice(&sum.to_le_bytes());
    }

    #[test]
    fn invalid_values_with_valid_checksum() {
        let bytes = to_bytes(&sample_map());
        // First record starts after magic, version and the header; class at +8, first x at +46.
        let rec = 12 + HEADER_REST;
        let mut b = bytes.clone();
        b[rec + 8] = 7;
        reseal(&mut b);
        assert!(reason(from_bytes(&b).unwrap_err()).contains("invalid class 7"));
        let mut b = bytes.clone();
        b[rec + 9] = 0; // a crossing that claims to be open
        reseal(&mut b);
        assert!(matches!(from_bytes(&b), Err(GeomError::Format { .. })));
        let mut b = bytes.clone();
        let x0 = rec + RECORD_FIXED;
        b[x0..x0 + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        reseal(&mut b);
        assert!(reason(from_bytes(&b).unwrap_err()).contains("non-finite"));
        let mut b = bytes.clone();
        b[20..28].copy_from_slice(&(-1.0f64).to_le_bytes()); // spacing
        reseal(&mut b);
        assert!(reason(from_bytes(&b).unwrap_err()).contains("spacing"));
        let mut b = bytes.clone();
        b[28..36].copy_from_slice(&1u64.to_le_bytes()); // next_id below the ids
        reseal(&mut b);
        assert!(reason(from_bytes(&b).unwrap_err()).contains("next_id"));
        let mut b = bytes;
        b[36..44].copy_from_slice(&u64::MAX.to_le_bytes()); // absurd count: no huge allocation
        reseal(&mut b);
        assert!(reason(from_bytes(&b).unwrap_err()).contains("instances declared"));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn arbitrary_bytes_never_panic(mut b in prop::collection::vec(any::<u8>(), 0..300), keep_header in any::<bool>()) {
            if keep_header && b.len() >= 12 {
                b[..8].copy_from_slice(MAGIC);
                b[8..12].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
                if b.len() >= 20 {
                    reseal(&mut b);
                }
            }
            let _ = from_bytes(&b);
        }

        #[test]
        fn round_trip_random_maps(insts in prop::collection::vec(
            (0u8..3, prop::collection::vec((-1e5..1e5f64, -1e5..1e5f64), 3..30), -100i64..100, 0i64..50, 1u32..1000), 0..20)) {
            let instances: Vec<Instance> = insts.into_iter().enumerate().map(|(k, (c, pts, f, d, o))| {
                let class = MapClass::ALL[c as usize];
                Instance {
                    id: (k as u64) * 3,
                    class,
                    points: pts.into_iter().map(|(x, y)| p(x, y)).collect(),
                    closed: class.is_closed(),
                    first_frame: f,
                    last_frame: f + d,
                    observations: o,
                }
            }).collect();
            let next = instances.len() as u64 * 3 + 1;
            let m = GlobalMap::from_parts(MapConfig::default(), next, instances).unwrap();
            let back = from_bytes(&to_bytes(&m)).unwrap();
            prop_assert_eq!(m.instances(), back.instances());
            prop_assert_eq!(m.next_id(), back.next_id());
        }
    }
}
