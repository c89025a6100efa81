"""Geo-referenced export: the local frames of AV2 cities and nuScenes maps to WGS84, against the
official devkits' own conversions, and the RFC 7946 GeoJSON written for a map."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from icmapper.georef import AV2_CITIES, NUSCENES_LOCATIONS, geo_frame, write_geojson_wgs84

PTS = np.array([[0.0, 0.0], [1745.37, -1421.37], [250.5, 3100.25], [-800.0, 40.0]])


def test_av2_cities_match_the_av2_devkit() -> None:
    from icmapper.testing.devkits import require_devkit

    (utm,) = require_devkit("av2.geometry.utm")
    for code in AV2_CITIES:
        ref = utm.convert_city_coords_to_wgs84(PTS, utm.CityName(code))  # (n, 2) lat, lon
        got = geo_frame(code).to_lonlat(PTS)  # (n, 2) lon, lat
        np.testing.assert_allclose(got[:, ::-1], ref, atol=1e-9, rtol=0)


def test_nuscenes_maps_match_the_nuscenes_devkit() -> None:
    from icmapper.testing.devkits import require_devkit

    (ep,) = require_devkit("nuscenes.scripts.export_poses")
    pos = np.abs(PTS[1:])  # the devkit's atan(x / y) holds in the map's positive quadrant
    for loc in NUSCENES_LOCATIONS:
        ref = ep.derive_latlon(loc, [{"timestamp": 0, "translation": [x, y, 0.0]} for x, y in pos])
        got = geo_frame(loc).to_lonlat(pos)
        np.testing.assert_allclose(got[:, 1], [r["latitude"] for r in ref], atol=1e-10, rtol=0)
        np.testing.assert_allclose(got[:, 0], [r["longitude"] for r in ref], atol=1e-10, rtol=0)


def test_metric_scale_is_right() -> None:
    # 1 km east of the origin moves about 1 km along the parallel (checks axes and units)
    for name in ("PIT", "boston-seaport"):
        (lon0, lat0), (lon1, lat1) = geo_frame(name).to_lonlat(np.array([[0.0, 0], [1000.0, 0]]))
        metres = np.radians(lon1 - lon0) * 6.371e6 * np.cos(np.radians(lat0))
        assert abs(metres - 1000.0) < 5.0 and abs(lat1 - lat0) < 3e-4  # UTM grid convergence


def test_wgs84_geojson_of_a_map(tmp_path: Path) -> None:
    from icmapper._icmap import GlobalMap

    m = GlobalMap()
    m.insert(1, np.array([[0.0, 0.0], [30.0, 0.5]]))
    m.insert(0, np.array([[10.0, 10.0], [14.0, 10.0], [14.0, 13.0], [10.0, 13.0]]))
    out = tmp_path / "m.wgs84.geojson"
    write_geojson_wgs84(m, "PIT", out)
    doc = json.loads(out.read_text())
    assert doc["type"] == "FeatureCollection" and "WGS84" in doc["icmapper"]["crs"]
    assert doc["icmapper"]["local_frame"] == "PIT"
    kinds = sorted(f["geometry"]["type"] for f in doc["features"])
    assert kinds == ["LineString", "Polygon"]
    ring = next(f for f in doc["features"] if f["geometry"]["type"] == "Polygon")
    coords = np.array(ring["geometry"]["coordinates"][0])
    assert np.array_equal(coords[0], coords[-1])  # closed
    x, y = coords[:-1, 0], coords[:-1, 1]
    assert np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0  # counter-clockwise exterior
    lon, lat = coords[0]
    assert -80.1 < lon < -79.9 and 40.4 < lat < 40.5  # Pittsburgh
    assert not list(tmp_path.glob("*.tmp"))
    with pytest.raises(ValueError, match="no geo reference"):
        write_geojson_wgs84(m, "atlantis", tmp_path / "x.json")


def test_loaders_name_their_geo_frame(tmp_path: Path) -> None:
    from icmapper.data.av2 import archive_city

    assert archive_city(Path("log_map_archive_abc____PIT_city_71109.json")) == "PIT"
    assert archive_city(Path("log_map_archive_abc.json")) == ""
    from icmapper.data.nuscenes import load_nuscenes
    from icmapper.testing.nuscenes_fixture import write_nuscenes_fixture

    root = write_nuscenes_fixture(tmp_path / "nus", location="boston-seaport")
    seqs = load_nuscenes(root, version="v1.0-mini", render=False)
    assert seqs and all(s.world.geo == "boston-seaport" for s in seqs)


def test_map_writes_wgs84_geojson_for_a_located_source(shared_data: Path, tmp_path: Path) -> None:
    from icmapper.cli import main

    log = next(p for p in sorted((shared_data / "av2-mini").iterdir()) if p.is_dir())
    args = ["map", "--source", f"av2:{log}", "--detections", "oracle:low", "--no-progress"]
    assert main([*args, "--method", "post-track", "--out", str(tmp_path)]) == 0
    doc = json.loads(next((tmp_path / "post-track").glob("*.wgs84.geojson")).read_text())
    assert doc["icmapper"]["local_frame"] == "PIT" and doc["features"]
    line = next(f for f in doc["features"] if f["geometry"]["type"] == "LineString")
    lon, lat = line["geometry"]["coordinates"][0]
    assert -80.2 < lon < -79.8 and 40.3 < lat < 40.6  # Pittsburgh
