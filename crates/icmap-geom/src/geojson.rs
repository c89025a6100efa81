//! GeoJSON export of the global map.
//!
//! Coordinates are the map's world frame in metres (not WGS84 longitude/latitude): the file is for
//! viewing and exchange with GIS tools in a local projected frame. Polygons follow RFC 7946: the
//! ring is closed (first point repeated at the end) and counter-clockwise.

use crate::clip::signed_area2;
use crate::error::Result;
use crate::persist::write_atomic;
use crate::store::{GlobalMap, Instance};
use crate::types::Point;
use std::fmt::Write;
use std::path::Path;

/// Appends `[x,y]` (shortest round-trip decimal form; stored points are always finite).
fn push_point(out: &mut String, p: &Point) {
    let _ = write!(out, "[{:?},{:?}]", p.x, p.y);
}

fn push_feature(out: &mut String, inst: &Instance) {
    out.push_str("{\"type\":\"Feature\",\"geometry\":{");
    if inst.closed {
        out.push_str("\"type\":\"Polygon\",\"coordinates\":[[");
        let mut ring: Vec<Point> = inst.points.clone();
        if signed_area2(&ring) < 0.0 {
            ring[1..].reverse(); // counter-clockwise, same first point
        }
        for p in &ring {
            push_point(out, p);
            out.push(',');
        }
        push_point(out, &ring[0]);
        out.push_str("]]");
    } else {
        out.push_str("\"type\":\"LineString\",\"coordinates\":[");
        for (k, p) in inst.points.iter().enumerate() {
            if k > 0 {
                out.push(',');
            }
            push_point(out, p);
        }
        out.push(']');
    }
    let _ = write!(
        out,
        "}},\"properties\":{{\"id\":{},\"class\":{},\"class_name\":\"{}\",\"observations\":{},\"first_frame\":{},\"last_frame\":{}}}}}",
        inst.id,
        inst.class.index(),
        inst.class.name(),
        inst.observations,
        inst.first_frame,
        inst.last_frame
    );
}

/// The map as a GeoJSON FeatureCollection string: LineString for polylines, Polygon for crossings,
/// properties `id`, `class`, `class_name`, `observations`, `first_frame`, `last_frame`.
pub fn to_geojson(map: &GlobalMap) -> String {
    let mut out = String::from("{\"type\":\"FeatureCollection\",\"features\":[");
    for (k, inst) in map.instances().into_iter().enumerate() {
        if k > 0 {
            out.push_str(",\n");
        } else {
            out.push('\n');
        }
        push_feature(&mut out, inst);
    }
    out.push_str("\n]}\n");
    out
}

/// Writes [`to_geojson`] to `path` atomically.
pub fn write_geojson(map: &GlobalMap, path: &Path) -> Result<()> {
    write_atomic(path, to_geojson(map).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::MapConfig;
    use crate::test_util::p;
    use crate::types::MapClass;

    fn map() -> GlobalMap {
        let instances = vec![
            Instance {
                id: 4,
                class: MapClass::Boundary,
                points: vec![p(0.5, -1.0), p(2.0, 1e-7), p(3.0, 9999999.25)],
                closed: false,
                first_frame: 1,
                last_frame: 8,
                observations: 3,
            },
            Instance {
                id: 1,
                class: MapClass::PedCrossing,
                // Clockwise on purpose.
                points: vec![p(0.0, 0.0), p(0.0, 1.0), p(1.0, 1.0), p(1.0, 0.0)],
                closed: true,
                first_frame: -2,
                last_frame: 0,
                observations: 1,
            },
        ];
        GlobalMap::from_parts(MapConfig::default(), 5, instances).unwrap()
    }

    #[test]
    fn feature_collection_text() {
        let s = to_geojson(&map());
        assert!(s.starts_with("{\"type\":\"FeatureCollection\",\"features\":["));
        // Ascending ids: the crossing (id 1) comes first, closed and counter-clockwise.
        let poly = "{\"type\":\"Feature\",\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[[[0.0,0.0],[1.0,0.0],[1.0,1.0],[0.0,1.0],[0.0,0.0]]]},\"properties\":{\"id\":1,\"class\":0,\"class_name\":\"ped_crossing\",\"observations\":1,\"first_frame\":-2,\"last_frame\":0}}";
        let line = "{\"type\":\"Feature\",\"geometry\":{\"type\":\"LineString\",\"coordinates\":[[0.5,-1.0],[2.0,1e-7],[3.0,9999999.25]]},\"properties\":{\"id\":4,\"class\":2,\"class_name\":\"boundary\",\"observations\":3,\"first_frame\":1,\"last_frame\":8}}";
        assert_eq!(
            s,
            format!("{{\"type\":\"FeatureCollection\",\"features\":[\n{poly},\n{line}\n]}}\n")
        );
        let empty = GlobalMap::new(MapConfig::default()).unwrap();
        assert_eq!(
            to_geojson(&empty),
            "{\"type\":\"FeatureCollection\",\"features\":[\n]}\n"
        );
    }

    #[test]
    fn write_file() {
        let dir = std::env::temp_dir().join(format!("icmap-geojson-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map.geojson");
        write_geojson(&map(), &path).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), to_geojson(&map()));
        assert!(write_geojson(&map(), &dir.join("missing/x.geojson")).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
