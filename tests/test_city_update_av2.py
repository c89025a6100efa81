"""A city update through real road geometry (issue 32): a copy of a shared Argoverse 2 log
(../shared/data/av2-mini) whose map archive is edited in the test (one pedestrian crossing
removed, one lane divider shifted 1 m sideways) drives through the city map built from the
original log (oracle detections); the update finds the removal and the move and changes nothing
else. Skips when the shared data is not there; nothing of it is written outside tmp_path."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from icmapper.data.types import MapClass

LOG = "3bffdcff-c3a7-38b6-a0f2-64196d130958"
SHIFT = 1.0  # metres, to the divider's left


def _quiet(*_: object) -> None:
    pass


def _archive(log: Path) -> Path:
    return next((log / "map").glob("log_map_archive_*.json"))


def _pick(log: Path) -> tuple[int, int, float]:
    """The world ids of the crossing and of the divider (20-120 m, in view in >= 5 frames) the
    log's drive sees most, and the side (+-SHIFT) to move the divider to: one where its moved
    copy keeps >= 1.8 m from every other line."""
    from icmapper.data.av2 import load_av2_sequence
    from icmapper.data.sim.changes import _min_dist, _visible_counts
    from icmapper.data.types import RANGE_60x30

    seq = load_av2_sequence(log, render=False)
    world = seq.world
    seen = _visible_counts(world, np.asarray(seq.poses), RANGE_60x30)
    order = sorted(seen, key=lambda k: -seen[k])
    crossing = next(k for k in order if world.instances[k].cls == MapClass.PED_CROSSING)
    lines = [m for m in world.instances if m.cls != MapClass.PED_CROSSING]
    for k in order:
        m = world.instances[k]
        length = float(np.linalg.norm(np.diff(m.points, axis=0), axis=1).sum())
        if m.cls != MapClass.DIVIDER or not 20.0 <= length <= 120.0 or seen[k] < 5:
            continue
        others = [o.points for o in lines if o.id != m.id]
        for shift in (SHIFT, -SHIFT):
            if _min_dist(_shifted(m.points, m.points, shift), others) >= 1.8:
                return world.instances[crossing].id, m.id, shift
    raise AssertionError(f"{log.name}: no divider to move")


def _shifted(points: np.ndarray, line: np.ndarray, shift: float = SHIFT) -> np.ndarray:
    """``points`` (n, 2) moved by ``shift`` along the left normal of ``line`` (m, 2) at their
    nearest vertex."""
    d = np.gradient(line, axis=0)  # (m, 2)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    normal = np.stack([-d[:, 1], d[:, 0]], axis=1)  # (m, 2)
    near = np.argmin(np.linalg.norm(points[:, None] - line[None], axis=2), axis=1)  # (n,)
    return points + shift * normal[near]


def _edit(log: Path, crossing: int, divider: np.ndarray, shift: float) -> None:
    """Removes the crossing and shifts every lane boundary lying on ``divider`` (n, 2)."""
    from icmapper import geom

    path = _archive(log)
    data = json.loads(path.read_text())
    keys = [k for k, pc in data["pedestrian_crossings"].items() if int(pc["id"]) == crossing]
    assert len(keys) == 1
    del data["pedestrian_crossings"][keys[0]]
    dense = np.asarray(geom.resample_spacing(divider, 0.25, closed=False))  # (m, 2)
    moved = 0
    for ls in data["lane_segments"].values():
        for side in ("left_lane_boundary", "right_lane_boundary"):
            pts = np.array([[p["x"], p["y"]] for p in ls[side]])  # (k, 2)
            dist = np.min(np.linalg.norm(pts[:, None] - dense[None], axis=2), axis=1)  # (k,)
            if np.all(dist < 0.2):
                new = _shifted(pts, dense, shift)
                for p, (x, y) in zip(ls[side], new.tolist(), strict=True):
                    p["x"], p["y"] = x, y
                moved += 1
    assert moved >= 1
    path.write_text(json.dumps(data))


def test_update_through_an_edited_av2_log(shared_data: Path, tmp_path: Path) -> None:
    from icmapper.city.drives import CitySettings
    from icmapper.city.run import build_city
    from icmapper.city.update_eval import change_distance
    from icmapper.city.update_run import update_city
    from icmapper.data.av2 import load_av2_world
    from icmapper.mapping.config import MapperConfig

    original = shared_data / "av2-mini" / LOG
    if not original.is_dir():
        pytest.skip(f"shared Argoverse 2 log not available: {original}")
    crossing_id, divider_id, shift = _pick(original)
    before = {m.id: m for m in load_av2_world(original).instances}
    edited = tmp_path / "edited" / LOG  # the same log id: the same city
    shutil.copytree(original, edited)
    _edit(edited, crossing_id, before[divider_id].points, shift)
    after = {m.id: m for m in load_av2_world(edited).instances}
    assert crossing_id not in after
    line = before[divider_id].points
    moved_to = [
        m.points for m in after.values()
        if m.cls == MapClass.DIVIDER
        and change_distance(m.points, False, _shifted(line, line, shift), False) < 0.3
    ]  # fmt: skip
    assert moved_to, "the edited archive does not hold the shifted divider"

    city = tmp_path / "city"
    settings = CitySettings("icmapper", "oracle:low", None, MapperConfig().to_dict(), (32, 88))
    build_city(city, [f"av2:{original}"], settings, "60x30", pictures=False, log=_quiet,
               progress=False)  # fmt: skip
    result = update_city(city, [f"av2:{edited}"], "oracle:low", log=_quiet, progress=False)
    road = [c for c in result.changes if c.cause == "road"]
    removed_pts = before[crossing_id].points
    old_line = before[divider_id].points
    found_removal = [
        c for c in road
        if c.change == "removed" and c.cls == MapClass.PED_CROSSING
        and change_distance(c.points, True, removed_pts, True) <= 1.5
    ]  # fmt: skip
    found_move = [
        c for c in road
        if c.change == "moved" and c.cls == MapClass.DIVIDER
        and change_distance(c.before, False, old_line, False) <= 1.5
        and change_distance(c.points, False, moved_to[0], False) <= 0.5
    ]  # fmt: skip
    summary = [(c.change, c.class_name, round(c.offset, 2), len(c.points)) for c in result.changes]
    assert len(found_removal) == 1, summary
    assert len(found_move) >= 1, summary
    assert all(abs(abs(c.offset) - SHIFT) < 0.3 for c in found_move), summary
    others = [c for c in road if c not in found_removal + found_move]
    assert not others, summary  # nothing else changed
    assert (city / "changes.geojson").is_file()
    assert not (original / "updates").exists()  # the shared log is untouched
