//! # icmap-geom
//!
//! The geometry core of icmapper: the global vector-map store with its spatial index, patch
//! clipping and even sampling, curve-fit merging and splicing of polylines, polygon union of
//! crossings and Chamfer distances; and the vectoriser that turns the detector's segmentation
//! probabilities into instances ([`vectorise()`]). Pure Rust: no Python in this crate (the binding
//! lives in `icmap-py`).
//!
//! Conventions (see the project's `docs/architecture.md`): metres and radians, world frame
//! coordinates in `f64`, poses as `(x, y, yaw)` ego -> world, classes `0 ped_crossing` (closed
//! polygon), `1 divider`, `2 boundary` (open polylines).

pub mod absorb;
pub mod chamfer;
pub mod clip;
pub mod error;
pub mod fit;
pub mod geojson;
pub mod index;
pub mod merge;
pub mod merge_map;
pub mod persist;
pub mod persist_v2;
pub mod provenance;
pub mod resample;
pub mod splice;
#[cfg(test)]
mod splitmix;
pub mod store;
#[cfg(test)]
mod test_util;
pub mod types;
pub mod union;
mod union_fast;
pub mod vectorise;

pub use chamfer::{chamfer_distance, chamfer_matrix};
pub use clip::{clip_polygon, clip_polyline, sample_pieces};
pub use error::{GeomError, Result};
pub use fit::fit_curve;
pub use merge::{merge_line, merge_polygon, merge_polyline};
pub use merge_map::{MergeMapParams, MergeMapStats};
pub use resample::{dedup, polyline_length, resample, resample_spacing};
pub use splice::{splice_line, splice_polyline, Fold};
pub use store::{GlobalMap, Instance, MapConfig, PatchSample};
pub use types::{validate_points, MapClass, Patch, Point, Pose2};
pub use union::polygon_union;
pub use vectorise::{vectorise, VectorInstances, VectoriseParams};
