//! GeoJSON export of the global map.

use crate::error::Result;
use crate::store::GlobalMap;
use std::path::Path;

/// The map as a GeoJSON FeatureCollection string: LineString for polylines, Polygon for crossings,
/// properties `id`, `class`, `class_name`, `observations`, `first_frame`, `last_frame`.
pub fn to_geojson(map: &GlobalMap) -> String {
    let _ = map;
    todo!("geojson.rs: to_geojson")
}

/// Writes [`to_geojson`] to `path` atomically.
pub fn write_geojson(map: &GlobalMap, path: &Path) -> Result<()> {
    let _ = (map, path);
    todo!("geojson.rs: write_geojson")
}
