//! Errors are values: every fallible operation on user input returns [`GeomError`], never panics.

use thiserror::Error;

/// Everything that can go wrong in the geometry core, each variant naming the problem.
#[derive(Debug, Error)]
pub enum GeomError {
    /// A coordinate or parameter is NaN or infinite.
    #[error("{what} contains a non-finite value (NaN or inf)")]
    NonFinite { what: String },
    /// A finite coordinate outside the engine's domain (`|x|, |y| <= MAX_COORD`, see
    /// [`crate::types::MAX_COORD`]).
    #[error("{what} has a coordinate {value:e} outside the valid domain |x|, |y| <= 1e7 m")]
    OutOfDomain { what: String, value: f64 },
    /// Geometry with fewer points than the operation needs (empty, one point, ...).
    #[error("{what} has {got} point(s); at least {min} are required")]
    TooFewPoints {
        what: String,
        got: usize,
        min: usize,
    },
    /// Geometry that has enough points but no extent (all points identical, zero area ...).
    #[error("{what} is degenerate: {reason}")]
    Degenerate { what: String, reason: String },
    /// A class index outside 0 (ped_crossing), 1 (divider), 2 (boundary).
    #[error("unknown map class {0}; expected 0 (ped_crossing), 1 (divider) or 2 (boundary)")]
    UnknownClass(i64),
    /// An instance id that is not in the map.
    #[error("no instance with id {0} in the map")]
    UnknownId(u64),
    /// An instance id that is already in the map (insert with an explicit id).
    #[error("an instance with id {0} already exists in the map")]
    DuplicateId(u64),
    /// A parameter outside its valid range (negative extents, zero points, s < 0 ...).
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter { name: &'static str, reason: String },
    /// A file-system error while reading or writing a map file.
    #[error("I/O error on {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A file that is not a valid map file (wrong magic, unknown version, truncated, corrupt).
    #[error("{path} is not a valid icmapper map file: {reason}")]
    Format { path: String, reason: String },
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, GeomError>;
