"""One MapperConfig for every method: validation, the command line's flags and --set reaching the
run (and recorded in it), the fusion network's own history settings, the registries of methods and
source kinds, and the tracker's public restore."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from icmapper.cli import main
from icmapper.data.sources import SOURCE_KINDS, SourceKind, open_source, register_source
from icmapper.mapping.config import CLI_FLAGS, MapperConfig
from icmapper.mapping.mapper import Mapper
from icmapper.mapping.methods import MethodInfo, method, methods
from icmapper.mapping.tracker import Track, Tracker

SRC = ["--source", "sim:val:1", "--detections", "oracle:low", "--no-progress"]


def test_config_from_dict_checks_names_types_and_ranges() -> None:
    cfg = MapperConfig.from_dict({"min_hits": 3, "smoothing": 1})
    assert cfg.min_hits == 3 and cfg.smoothing == 1.0 and isinstance(cfg.smoothing, float)
    assert MapperConfig.from_dict(cfg.to_dict()) == cfg  # plain data round trip
    with pytest.raises(ValueError, match="unknown config key.*min_hit"):
        MapperConfig.from_dict({"min_hit": 3})
    with pytest.raises(ValueError, match="min_hits must be an integer"):
        MapperConfig.from_dict({"min_hits": 2.5})
    with pytest.raises(ValueError, match="assoc_threshold must be in"):
        MapperConfig.from_dict({"assoc_threshold": 1.5})
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="reid_overlap must be in"):
            MapperConfig.from_dict({"reid_overlap": bad})
    for bad in (0.0, -1.0):
        with pytest.raises(ValueError, match="city_tolerance must be > 0"):
            MapperConfig.from_dict({"city_tolerance": bad})
    assert MapperConfig.from_dict({"fusion_classes": [0, 1]}).fusion_classes == (0, 1)
    for bad in ([0, 3], [1, 1], [-1]):
        with pytest.raises(ValueError, match="fusion_classes must be distinct class indices"):
            MapperConfig.from_dict({"fusion_classes": bad})
    # every field has help text for the command line, every flag is a field
    helps = MapperConfig.help()
    assert all(h.strip() for h in helps.values()) and set(CLI_FLAGS) <= set(helps)


def test_cli_settings_reach_the_run_and_are_recorded(tmp_path: Path) -> None:
    out = tmp_path / "out"
    args = ["map", *SRC, "--method", "post-track", "--out", str(out), "--smoothing", "0.8"]
    args += ["--set", "gate=2.5", "--set", "max_age=5"]
    assert main(args) == 0
    used = json.loads((out / "post-track" / "mapper_config.json").read_text())
    assert used["smoothing"] == 0.8 and used["gate"] == 2.5 and used["max_age"] == 5
    assert used["min_hits"] == MapperConfig().min_hits  # the rest are the defaults
    from icmapper._icmap import GlobalMap

    gm = GlobalMap.load(next((out / "post-track").glob("*.icmap")))
    assert gm.smoothing == 0.8  # the baseline's map was built with the chosen smoothing


def test_cli_rejects_bad_settings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["map", *SRC, "--out", str(tmp_path / "a"), "--set", "nope=1"]) == 1
    assert "unknown config key" in capsys.readouterr().err
    assert main(["map", *SRC, "--out", str(tmp_path / "b"), "--set", "min_hits"]) == 1
    assert "expected NAME=VALUE" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() or not any((tmp_path / "a").iterdir())


def test_from_checkpoint_takes_the_fusion_networks_history(tiny_checkpoint: Path) -> None:
    m = Mapper.from_checkpoint(tiny_checkpoint)
    assert m.fusion is not None
    assert m.config.fusion_margin == m.fusion.margin
    assert m.config.history_points == m.fusion.history_points
    # a config that sets another value than the network's is an error, not silently ignored
    other = m.fusion.margin + 5.0
    with pytest.raises(ValueError, match="fusion_margin"):
        Mapper.from_checkpoint(tiny_checkpoint, config=MapperConfig(fusion_margin=other))
    cfg = MapperConfig(min_hits=4)
    assert Mapper.from_checkpoint(tiny_checkpoint, config=cfg).config.min_hits == 4


@pytest.mark.parametrize("name", ["use_fusion", "use_association"])
def test_config_switches_a_network_off(name: str, tiny_checkpoint: Path) -> None:
    """Regression: ``--set use_fusion=false`` (docs/mapping.md's example) was overwritten by the
    variant's flags, so the learned mapper fused all the same."""
    off = Mapper.from_checkpoint(tiny_checkpoint, config=MapperConfig(**{name: False}))
    assert getattr(off.config, name) is False
    assert getattr(Mapper.from_checkpoint(tiny_checkpoint).config, name) is True
    # the variant still switches it off whatever the config says
    base = Mapper.from_checkpoint(tiny_checkpoint, config=MapperConfig(), variant="base")
    assert getattr(base.config, name) is False


def test_checkpoint_carries_mapper_settings(tiny_checkpoint: Path, tmp_path: Path) -> None:
    """The training config's [mapper] table travels in the checkpoint and is the mapper's
    starting point (configs/small.toml sets min_hits = 1, reid_alias = false, assoc_threshold =
    0.3, fused_clip = true); --set still overrides it. ``MapperConfig.for_checkpoint`` is that
    starting point."""
    from icmapper.cli import main
    from icmapper.models.network import checkpoint_mapper_settings
    from icmapper.training.config import config_from_dict

    want_table = {"min_hits": 1, "reid_alias": False, "assoc_threshold": 0.3, "fused_clip": True}
    assert checkpoint_mapper_settings(tiny_checkpoint) == want_table
    cfg = Mapper.from_checkpoint(tiny_checkpoint).config
    assert cfg.min_hits == 1 and not cfg.reid_alias and cfg.assoc_threshold == 0.3
    assert cfg.fused_clip and not MapperConfig().fused_clip  # the library default stays off
    assert MapperConfig.for_checkpoint(str(tiny_checkpoint)).assoc_threshold == 0.3
    assert MapperConfig().min_hits == 2  # the library default is unchanged
    with pytest.raises(ValueError, match="unknown"):
        config_from_dict({"mapper": {"min_hitz": 1}})
    with pytest.raises(ValueError, match=r"\[mapper\] must be a table"):
        config_from_dict({"mapper": 3})
    src = ["--source", "sim:val:1", "--checkpoint", str(tiny_checkpoint)]
    for extra, want in (([], 1), (["--set", "min_hits=3"], 3)):
        out = tmp_path / f"run{want}"
        assert main(["map", *src, "--out", str(out), "--no-progress", *extra]) == 0
        used = json.loads((out / "icmapper" / "mapper_config.json").read_text())
        assert used["min_hits"] == want


def test_method_registry() -> None:
    names = list(methods())
    assert names[0] == "icmapper" and {"post-track", "vma", "cluster-fit", "polymerge"} <= set(
        names
    )
    with pytest.raises(ValueError, match="unknown method 'nope'; expected one of icmapper"):
        method("nope")
    with pytest.raises(ValueError, match="exactly one of"):
        MethodInfo("x", "help")
    from icmapper.mapping.methods import register_method

    with pytest.raises(ValueError, match="registered twice"):
        register_method(methods()["vma"])


def test_source_registry_new_kind_is_one_registration() -> None:
    from icmapper.data import sim

    def open_one(spec: str, rest: str, o) -> list:
        return [sim.sim_sequence(10_000, int(rest), image_size=o.image_size)]

    kind = SourceKind("test-one", "test-one:DRIVE", "one synthetic drive (test)", open_one)
    register_source(kind)
    try:
        seqs = open_source("test-one:2", image_size=(32, 88))
        assert len(seqs) == 1 and seqs[0].name.endswith("-2")
        with pytest.raises(ValueError, match="registered twice"):
            register_source(kind)
    finally:
        del SOURCE_KINDS["test-one"]
    with pytest.raises(ValueError, match="unknown kind 'test-one'"):
        open_source("test-one:2")


def test_tracker_restore_is_validated_and_atomic() -> None:
    tr = Tracker()
    good = [Track(3, 1, np.zeros((4, 2)), None), Track(5, 2, np.ones((2, 2)), None, age=1)]
    tr.restore(good, next_id=6)
    assert [t.id for t in tr.tracks] == [3, 5] and tr.next_id == 6
    for bad, match in (
        ([Track(1, 1, np.zeros((2, 2)), None)] * 2, "duplicate"),
        ([Track(1, 1, np.full((2, 2), np.nan), None)], "finite"),
        ([Track(1, 1, np.zeros((2, 2)), None, hits=0)], "hits"),
    ):
        with pytest.raises(ValueError, match=match):
            tr.restore(bad, next_id=9)
        assert [t.id for t in tr.tracks] == [3, 5] and tr.next_id == 6  # unchanged


class _Scripted:
    """A detection source replaying given Detections, one per frame."""

    def __init__(self, frames: list) -> None:
        self.frames = frames

    def reset(self) -> None:
        pass

    def detect(self, frame: object) -> object:
        return self.frames[frame.index]  # type: ignore[attr-defined]


@pytest.mark.parametrize("alias", [True, False])
def test_reid_alias_setting(alias: bool) -> None:
    """A second new piece lying on an instance matched this frame maps into it with
    ``reid_alias``; without, it stays its own instance."""
    from icmapper.data.sim.rig import nuscenes_rig
    from icmapper.data.types import Frame
    from icmapper.mapping.types import Detections

    def line(x0: float, x1: float, y: float) -> np.ndarray:
        return np.stack([np.linspace(x0, x1, 20), np.full(20, y)], -1).astype(np.float32)

    def dets(*lines: np.ndarray) -> Detections:
        n = len(lines)
        return Detections(np.ones(n, np.int64), np.full(n, 0.9, np.float32), np.stack(lines))

    # frame 0: a divider 0..20 m; frame 1: the same divider, and a short piece lying on its end
    script = [dets(line(0, 20, 2.0)), dets(line(0, 20, 2.0), line(14, 20, 2.1))]
    # (absorption off: it would join the piece to the divider either way; min_travel off: both
    # frames are taken at one pose)
    cfg = MapperConfig(
        min_hits=1,
        reid_alias=alias,
        detect_threshold=0.0,
        track_threshold=0.0,
        absorb=False,
        min_travel=0.0,
    )
    m = Mapper(_Scripted(script), config=cfg)
    rig = nuscenes_rig((32, 88))
    for i in range(2):
        m.step(Frame(i, float(i), np.eye(4), rig))
    assert m.stats.aliased == (1 if alias else 0)
    assert len(m.global_map) == (1 if alias else 2)
