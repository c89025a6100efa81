"""Geo-referencing: a dataset's local map frame -> WGS84 longitude / latitude, and the GeoJSON of a
global map: one schema (``map_geojson``) for every map file the project writes, in the local
frame and, where the frame is located, in WGS84 (RFC 7946).

Each ``GeoFrame`` is one published origin of a dataset's frames, in the ``GEO_FRAMES`` registry:
- Argoverse 2 cities (ATX, DTW, MIA, PAO, PIT, WDC): the city frame is UTM (WGS84 ellipsoid, the
  city's northern zone) shifted by the UTM coordinates of the city origin; converted back with the
  inverse UTM projection (pyproj), as av2-api's ``av2.geometry.utm.convert_city_coords_to_wgs84``
  does (origins and zones from av2-api 0.3.6, ``av2/geometry/utm.py``).
- nuScenes map locations: the map frame's origin is a reference coordinate at the south-western
  corner and x points east, y north; a point is the destination from the reference at bearing
  atan2(x, y) and distance |(x, y)| on a sphere of radius 6,378,137 m, as nuscenes-devkit's
  ``nuscenes/scripts/export_poses.py`` (``derive_latlon``, ``get_coordinate``; devkit 1.2.0)
  computes it (the devkit uses atan(x / y), the same angle in the map's positive quadrant).

Accuracy is the datasets' own: these are the devkits' conversions, not survey-grade.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from icmapper.atomic import write_text_atomic
from icmapper.registry import Registry

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap

#: Earth radius of nuscenes-devkit's export_poses (metres).
NUSCENES_EARTH_RADIUS = 6.378137e6


@dataclass(frozen=True)
class GeoFrame:
    """A local map frame's place on Earth: ``to_lonlat(xy (n, 2) metres) -> (n, 2)`` degrees as
    (longitude, latitude); ``describe`` names the frame and its conversion."""

    name: str
    describe: str
    to_lonlat: Callable[[NDArray[np.float64]], NDArray[np.float64]]


GEO_FRAMES: Registry[GeoFrame] = Registry("geo frame")


def register_geo_frame(frame: GeoFrame) -> GeoFrame:
    """Adds a frame to the registry (ValueError for a name registered twice)."""
    return GEO_FRAMES.register(frame)


def geo_frame(name: str) -> GeoFrame:
    """The registered frame ``name`` (ValueError listing the known ones)."""
    if name not in GEO_FRAMES:
        raise ValueError(f"no geo reference for {name!r}; known: {', '.join(sorted(GEO_FRAMES))}")
    return GEO_FRAMES[name]


def _check_xy(xy: NDArray[np.floating]) -> NDArray[np.float64]:
    pts = np.asarray(xy, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must be (n, 2), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points contain NaN or inf")
    return pts


# ---------------------------------------------------------------------- Argoverse 2 (UTM)
#: city code -> (UTM zone (north), origin latitude, origin longitude): av2-api 0.3.6.
AV2_CITIES: dict[str, tuple[int, float, float]] = {
    "ATX": (14, 30.27464237939507, -97.7404457407424),
    "DTW": (17, 42.29993066912924, -83.17555750783717),
    "MIA": (17, 25.77452579915163, -80.19656914449405),
    "PAO": (10, 37.416065, -122.13571963362166),
    "PIT": (17, 40.44177902989321, -80.01294377242584),
    "WDC": (18, 38.889377, -77.0355047439081),
}


def _av2_converter(zone: int, lat0: float, lon0: float) -> Callable[[NDArray], NDArray]:
    def to_lonlat(xy: NDArray[np.floating]) -> NDArray[np.float64]:
        from pyproj import Proj

        pts = _check_xy(xy)
        proj = Proj(proj="utm", zone=zone, ellps="WGS84", datum="WGS84", units="m")
        e0, n0 = proj(lon0, lat0)  # origin easting, northing
        lon, lat = proj(pts[:, 0] + e0, pts[:, 1] + n0, inverse=True)
        return np.stack([np.asarray(lon), np.asarray(lat)], axis=1)  # (n, 2)

    return to_lonlat


for _code, (_zone, _lat, _lon) in AV2_CITIES.items():
    register_geo_frame(
        GeoFrame(
            _code,
            f"Argoverse 2 city {_code}: UTM zone {_zone}N (WGS84) shifted to the city origin "
            f"({_lat:.6f}, {_lon:.6f})",
            _av2_converter(_zone, _lat, _lon),
        )
    )


# ---------------------------------------------------------------------- nuScenes (bearing/distance)
#: map location -> reference (latitude, longitude) of the map origin: nuscenes-devkit 1.2.0.
NUSCENES_LOCATIONS: dict[str, tuple[float, float]] = {
    "boston-seaport": (42.336849169438615, -71.05785369873047),
    "singapore-onenorth": (1.2882100868743724, 103.78475189208984),
    "singapore-hollandvillage": (1.2993652317780957, 103.78217697143555),
    "singapore-queenstown": (1.2782562240223188, 103.76741409301758),
}


def _nuscenes_converter(lat0: float, lon0: float) -> Callable[[NDArray], NDArray]:
    def to_lonlat(xy: NDArray[np.floating]) -> NDArray[np.float64]:
        pts = _check_xy(xy)
        lat, lon = math.radians(lat0), math.radians(lon0)
        bearing = np.arctan2(pts[:, 0], pts[:, 1])  # (n,) clockwise from north
        ang = np.hypot(pts[:, 0], pts[:, 1]) / NUSCENES_EARTH_RADIUS  # (n,) angular distance
        tlat = np.arcsin(
            math.sin(lat) * np.cos(ang) + math.cos(lat) * np.sin(ang) * np.cos(bearing)
        )  # (n,)
        tlon = lon + np.arctan2(
            np.sin(bearing) * np.sin(ang) * math.cos(lat),
            np.cos(ang) - math.sin(lat) * np.sin(tlat),
        )  # (n,)
        return np.stack([np.degrees(tlon), np.degrees(tlat)], axis=1)  # (n, 2)

    return to_lonlat


for _loc, (_lat, _lon) in NUSCENES_LOCATIONS.items():
    register_geo_frame(
        GeoFrame(
            _loc,
            f"nuScenes map {_loc}: origin ({_lat:.6f}, {_lon:.6f}), x east, y north, "
            "spherical bearing/distance (nuscenes-devkit export_poses)",
            _nuscenes_converter(_lat, _lon),
        )
    )


# ---------------------------------------------------------------------- export
#: The one GeoJSON schema of every map file the project writes (docs/data.md, "GeoJSON"): run
#: folders' ``<seq>.geojson`` / ``<seq>.wgs84.geojson`` and city runs' ``city.geojson`` /
#: ``city.wgs84.geojson``.
GEOJSON_SCHEMA = "icmapper-map-geojson"
GEOJSON_VERSION = 1


def feature_geometry(coords: list[list[float]], closed: bool) -> dict[str, Any]:
    """A LineString, or for a crossing a Polygon whose ring is closed and counter-clockwise (the
    exterior orientation RFC 7946 asks for)."""
    if not closed:
        return {"type": "LineString", "coordinates": coords}
    ring = coords + [coords[0]]
    area2 = sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(ring[:-1], ring[1:], strict=True))
    return {"type": "Polygon", "coordinates": [ring if area2 >= 0 else ring[::-1]]}


def map_geojson(gmap: GlobalMap, local_frame: str = "", wgs84: bool = False) -> dict[str, Any]:
    """The global map as a GeoJSON FeatureCollection, one feature per instance (LineString, or
    Polygon for a crossing), ``id`` on the feature and in its properties; the same properties in
    every file: ``id``, ``class`` (its name), ``class_id`` (0 ped_crossing, 1 divider,
    2 boundary), ``closed``, ``n_points``, ``first_frame``, ``last_frame``, ``observations``,
    ``drives`` (the city drives that observed it; [] in a single run). The foreign member
    ``icmapper`` names the schema and the frame: ``crs``, ``local_frame`` (a ``GEO_FRAMES``
    name, or "" for a synthetic city) and ``conversion``.

    wgs84: longitude / latitude in degrees (RFC 7946; 9 decimals), converted from the located
    ``local_frame``; else the local map frame's metres as stored (not WGS84, so not RFC 7946's
    CRS: GIS tools need the frame named in ``crs``)."""
    from icmapper.data.types import CLASS_NAMES

    gf = geo_frame(local_frame) if wgs84 else None
    features = []
    for i in gmap.ids().tolist():
        cls, pts = gmap.get(int(i))
        info = gmap.info(int(i))
        xy = np.asarray(pts, np.float64)  # (n, 2)
        if gf is None:
            coords = xy.tolist()
        else:
            coords = [[round(float(x), 9), round(float(y), 9)] for x, y in gf.to_lonlat(xy)]
        props: dict[str, Any] = {"id": int(i), "class": CLASS_NAMES[int(cls)], "class_id": int(cls)}
        props.update({k: v for k, v in info.items() if k not in ("id", "cls")})
        features.append(
            {
                "type": "Feature",
                "id": int(i),
                "geometry": feature_geometry(coords, bool(info["closed"])),
                "properties": props,
            }
        )
    return {
        "type": "FeatureCollection",
        "features": features,
        "icmapper": frame_member(local_frame, gf),
    }


def frame_member(local_frame: str, gf: GeoFrame | None = None) -> dict[str, Any]:
    """The foreign member ``icmapper`` of the project's GeoJSON files: the schema and the frame
    (``crs``, ``local_frame``, ``conversion``); ``gf``: the frame converted to WGS84, None for
    the local map frame's metres."""
    if gf is not None:
        crs = "WGS84 longitude, latitude in degrees (RFC 7946; EPSG:4326 axis order lon, lat)"
        conversion = gf.describe
    else:
        where = f"{local_frame}'s" if local_frame else "a synthetic city's (no place on Earth)"
        crs = f"local map frame, metres: {where} x, y (not WGS84)"
        conversion = "none: the map frame's coordinates as stored"
    return {
        "schema": GEOJSON_SCHEMA,
        "version": GEOJSON_VERSION,
        "crs": crs,
        "local_frame": local_frame,
        "conversion": conversion,
    }


def geojson_wgs84(gmap: GlobalMap, frame: str) -> dict[str, Any]:
    """``map_geojson`` in WGS84 from the located ``frame``."""
    return map_geojson(gmap, frame, wgs84=True)


def write_map_geojson(
    gmap: GlobalMap, path: str | Path, local_frame: str = "", wgs84: bool = False
) -> None:
    """Writes ``map_geojson`` to ``path`` atomically."""
    write_text_atomic(path, json.dumps(map_geojson(gmap, local_frame, wgs84)))


def write_geojson_wgs84(gmap: GlobalMap, frame: str, path: str | Path) -> None:
    """Writes ``geojson_wgs84`` to ``path`` atomically (temp file in the folder + rename)."""
    write_map_geojson(gmap, path, frame, wgs84=True)


def write_map_geojsons(gmap: GlobalMap, stem: Path, local_frame: str) -> list[Path]:
    """What a run or city writes for a map: ``<stem>.geojson`` in the local frame, and
    ``<stem>.wgs84.geojson`` where ``local_frame`` is located. Returns the paths written."""
    out = [stem.with_name(stem.name + ".geojson")]
    write_map_geojson(gmap, out[0], local_frame)
    if local_frame in GEO_FRAMES:
        out.append(stem.with_name(stem.name + ".wgs84.geojson"))
        write_map_geojson(gmap, out[1], local_frame, wgs84=True)
    return out
