//! The native map file: versioned binary format, atomic writes.

use crate::error::Result;
use crate::store::GlobalMap;
use std::path::Path;

/// Writes `map` to `path` atomically (temp file in the same folder, fsync, rename).
pub fn save(map: &GlobalMap, path: &Path) -> Result<()> {
    let _ = (map, path);
    todo!("persist.rs: save")
}

/// Reads a map file; a foreign, truncated or corrupt file gives `GeomError::Format`.
pub fn load(path: &Path) -> Result<GlobalMap> {
    let _ = path;
    todo!("persist.rs: load")
}
