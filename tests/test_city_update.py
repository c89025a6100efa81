"""Keeping a city map true (issue 32): the changed synthetic worlds, the change detector on small
hand-made maps (each change type, and nothing for an unchanged road), the update mode of a city
run (changes applied with provenance, unchanged instances byte-identical, a drive of another
city and a folder of another format version refused, a failed save losing nothing), the change
report and its evaluation against the true changes."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data.sim.changes import changed_city_drives, spec_true_changes
from icmapper.data.sim.sequences import sim_city_drives
from icmapper.data.sources import open_source
from icmapper.data.types import CHANGE_TYPES


def test_changed_city_is_the_same_city_with_known_changes() -> None:
    base = sim_city_drives("val", 0, 3, (8, 8))
    seqs, changes = changed_city_drives("val", 0, 3, seed=1, image_size=(8, 8))
    again, changes2 = changed_city_drives("val", 0, 3, seed=1, image_size=(8, 8))
    assert [c.to_json() for c in changes] == [c.to_json() for c in changes2]  # deterministic
    other = changed_city_drives("val", 0, 3, seed=2, image_size=(8, 8))[1]
    assert [c.to_json() for c in changes] != [c.to_json() for c in other]
    assert {(c.change, c.cls) for c in changes} >= {
        ("added", 0), ("removed", 0), ("added", 1), ("removed", 1), ("moved", 1), ("moved", 2)
    }  # fmt: skip
    assert {c.change for c in changes} == set(CHANGE_TYPES)
    old, new = base[0].world, seqs[0].world
    assert new.name == old.name and new.lanes.keys() == old.lanes.keys()  # the same city
    for b, s in zip(base, seqs, strict=True):
        np.testing.assert_array_equal(b.poses, s.poses)
        assert s.name != b.name and s.name.endswith(b.name.rsplit("-", 1)[1])
    touched = {c.instance for c in changes}
    old_by_id = {m.id: m for m in old.instances}
    new_by_id = {m.id: m for m in new.instances}
    for i, m in old_by_id.items():  # everything else untouched, bit for bit
        if i not in touched:
            np.testing.assert_array_equal(new_by_id[i].points, m.points)
            assert new_by_id[i].cls == m.cls
    for c in changes:
        if c.change == "removed":
            assert c.instance in old_by_id and c.instance not in new_by_id
        elif c.change == "added":
            assert c.instance not in old_by_id and c.instance in new_by_id
        else:
            shift = np.linalg.norm(c.points - c.before, axis=1).max()
            assert 0.5 <= shift <= 3.0 + 1e-9
    # every change lies where the drives see it: within the 60x30 range of some pose
    xy = np.concatenate([s.poses[:, :2, 3] for s in seqs])
    for c in changes:
        near = np.linalg.norm(c.points[:, None] - xy[None], axis=-1).min()
        assert near < np.hypot(30, 15)
    assert [c.to_json() for c in spec_true_changes("sim-city-changed:val:0:3:1") or []] == [
        c.to_json() for c in changes
    ]
    assert spec_true_changes("sim-city:val:0:3") is None
    assert [s.name for s in open_source("sim-city-changed:val:0:3:1", render=False)] == [
        s.name for s in seqs
    ]
    with pytest.raises(ValueError, match="INDEX:N"):
        open_source("sim-city-changed:val:0")
