"""What the installed package holds: no benchmark modules, test helpers only under
``icmapper.testing`` and never imported by the runtime modules, the shipped checkpoint as package
data that resolves and loads."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import icmapper
import pytest

PACKAGE = Path(icmapper.__file__).resolve().parent

#: Runtime modules a user imports to map, train and evaluate (each imported in a fresh process).
RUNTIME_MODULES = (
    "icmapper",
    "icmapper.cli",
    "icmapper.data.sources",
    "icmapper.data.nuscenes",
    "icmapper.training.loop",
    "icmapper.mapping.mapper",
    "icmapper.mapping.cli",
    "icmapper.eval.evaluate",
)


def test_no_benchmark_modules_in_the_package() -> None:
    bench = sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("bench*.py"))
    assert bench == [], f"benchmark modules belong in benchmarks/, found {bench}"


def test_runtime_modules_do_not_import_the_testing_helpers() -> None:
    code = (
        "import importlib, sys\n"
        f"for name in {RUNTIME_MODULES!r}:\n"
        "    importlib.import_module(name)\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('icmapper.testing'))\n"
        "print(','.join(loaded))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(PACKAGE.parent)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"runtime imports test helpers: {out.stdout.strip()}"


def test_synthetic_source_builds_clips_from_the_testing_package() -> None:
    from icmapper.testing.clips import SyntheticClips
    from icmapper.training.config import config_from_dict
    from icmapper.training.loop import build_dataset

    cfg = config_from_dict(
        {"data": {"source": "synthetic:3", "clip_len": 2, "image_size": [16, 32]}}
    )
    ds, _collate = build_dataset(cfg, stage=1)
    assert isinstance(ds, SyntheticClips) and len(ds) == 3


def test_default_checkpoint_is_package_data_and_loads() -> None:
    from icmapper.checkpoints import DEFAULT_CHECKPOINT
    from icmapper.mapping.cli import DEFAULT_CHECKPOINT as cli_default
    from icmapper.models.checkpoint import load_checkpoint

    assert cli_default == DEFAULT_CHECKPOINT
    assert DEFAULT_CHECKPOINT.is_file(), f"shipped checkpoint missing: {DEFAULT_CHECKPOINT}"
    assert DEFAULT_CHECKPOINT.resolve().is_relative_to(PACKAGE), "not inside the package"
    blob = load_checkpoint(DEFAULT_CHECKPOINT)
    assert blob["config"]["model"]["num_cameras"] == 6 and blob["model"], "not the small config"
    from icmapper import Mapper

    Mapper.from_checkpoint(DEFAULT_CHECKPOINT)  # the weights fit the network they describe


def test_export_replaces_the_mapper_settings(tmp_path: Path) -> None:
    """``export_checkpoint(..., mapper=...)`` (``python -m icmapper.models.checkpoint SRC DST
    --mapper-from CONFIG``): the [mapper] table is replaced, the weights stay bit for bit."""
    import torch
    from icmapper.models.checkpoint import export_checkpoint, load_checkpoint, save_checkpoint
    from icmapper.models.network import checkpoint_mapper_settings

    src, dst = tmp_path / "a.pt", tmp_path / "b.pt"
    w = {"w": torch.arange(6, dtype=torch.float32)}
    save_checkpoint(
        src, model=w, optimizer=None, stage=2, step=7, config={"mapper": {"min_hits": 1}}
    )
    export_checkpoint(src, dst, {"min_hits": 1, "assoc_threshold": 0.3})
    assert checkpoint_mapper_settings(dst) == {"min_hits": 1, "assoc_threshold": 0.3}
    assert torch.equal(load_checkpoint(dst)["model"]["w"], w["w"])
    with pytest.raises(ValueError, match="must be a table"):
        export_checkpoint(src, dst, [("min_hits", 1)])  # type: ignore[arg-type]


def test_export_takes_a_module_from_another_checkpoint(tmp_path: Path) -> None:
    """``export_checkpoint(..., take={"fusion.": OTHER})`` (``--take fusion.=OTHER``): the
    tensors under the prefix come from the other checkpoint, the rest from the source; a prefix
    the other lacks, or other names or shapes under it, is an error naming the file. The command
    line composes the same file."""
    import torch
    from icmapper.models.checkpoint import export_checkpoint, load_checkpoint, save_checkpoint

    def ckpt(path: Path, fill: float, shape: tuple[int, ...] = (3,)) -> Path:
        model = {
            "association.w": torch.full((2,), fill),
            "fusion.a": torch.full(shape, fill),
            "fusion.b": torch.full((1,), fill),
        }
        save_checkpoint(path, model=model, optimizer=None, stage=2, step=1, config={})
        return path

    src, other = ckpt(tmp_path / "src.pt", 1.0), ckpt(tmp_path / "other.pt", 2.0)
    dst = tmp_path / "out.pt"
    export_checkpoint(src, dst, take={"fusion.": other})
    got = load_checkpoint(dst)["model"]
    assert torch.equal(got["association.w"], torch.full((2,), 1.0))
    assert torch.equal(got["fusion.a"], torch.full((3,), 2.0))
    assert torch.equal(got["fusion.b"], torch.full((1,), 2.0))
    with pytest.raises(ValueError, match="no tensor under 'decoder.'"):
        export_checkpoint(src, dst, take={"decoder.": other})
    wide = ckpt(tmp_path / "wide.pt", 3.0, (4,))
    with pytest.raises(ValueError, match="wide.pt.*names or shapes"):
        export_checkpoint(src, dst, take={"fusion.": wide})
    cli = tmp_path / "cli.pt"
    subprocess.run(
        [sys.executable, "-m", "icmapper.models.checkpoint", str(src), str(cli), "--take",
         f"fusion.={other}"],
        check=True,
    )  # fmt: skip
    assert all(torch.equal(v, load_checkpoint(cli)["model"][k]) for k, v in got.items())
