"""Source specs: one string names a list of sequences, so runs and evaluations can recompute
their inputs and ground truth.

    sim:val            4 synthetic validation drives (cities of sim.CITY_SEEDS["val"])
    sim:<split>:N      N synthetic drives of split train / val / test
    av2:PATH           the drive of an Argoverse 2 log, or of every log in a folder of logs
    av2-drives:PATH:N  N synthetic drives along the lane graph of each log under PATH
    nuscenes:PATH[:split]
                       the scenes of a nuScenes dataroot (version: v1.0-trainval if present, else
                       the only v1.0-* folder); the split needs a split file: `split_file=` or
                       <PATH>/splits.json
"""

from __future__ import annotations

from pathlib import Path

from icmapper.data.types import Sequence

DEFAULT_SIM_COUNT = 4
SIM_SPLITS = ("train", "val", "test")


def _count(text: str, spec: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise ValueError(f"bad source spec {spec!r}: {text!r} is not a count") from None
    if n < 1:
        raise ValueError(f"bad source spec {spec!r}: the count must be >= 1")
    return n


def _nuscenes_version(root: Path) -> str:
    if (root / "v1.0-trainval").is_dir():
        return "v1.0-trainval"
    found = sorted(d.name for d in root.glob("v1.0-*") if d.is_dir())
    if len(found) != 1:
        raise ValueError(f"cannot pick a nuScenes version in {root}: found {found or 'none'}")
    return found[0]


def open_source(
    spec: str,
    image_size: tuple[int, int] = (128, 352),
    seed: int = 0,
    split_file: str | Path | None = None,
    render: bool = True,
) -> list[Sequence]:
    """The sequences a spec names (see the module docstring). Raises ValueError for a bad spec
    and DataError (a ValueError) for missing or broken data."""
    if not isinstance(spec, str) or ":" not in spec:
        raise ValueError(
            f"bad source spec {spec!r}: expected 'sim:val', 'sim:<split>:N', 'av2:PATH', "
            "'av2-drives:PATH:N' or 'nuscenes:PATH[:split]'"
        )
    kind, rest = spec.split(":", 1)
    if kind == "sim":
        from icmapper.data import sim

        parts = rest.split(":")
        if parts[0] not in SIM_SPLITS or len(parts) > 2:
            raise ValueError(f"bad source spec {spec!r}: expected sim:<{'|'.join(SIM_SPLITS)}>[:N]")
        n = _count(parts[1], spec) if len(parts) == 2 else DEFAULT_SIM_COUNT
        return list(sim.sim_sequences(parts[0], n, seed=seed, image_size=image_size))
    if kind == "av2":
        from icmapper.data import av2

        if not rest:
            raise ValueError(f"bad source spec {spec!r}: no path")
        return [
            av2.load_av2_sequence(log, image_size=image_size, render=render, seed=seed)
            for log in av2.find_av2_logs(rest)
        ]
    if kind == "av2-drives":
        from icmapper.data import av2

        path, _, n = rest.rpartition(":")
        if not path:
            raise ValueError(f"bad source spec {spec!r}: expected av2-drives:PATH:N")
        num = _count(n, spec)
        return [
            s
            for log in av2.find_av2_logs(path)
            for s in av2.av2_drives(log, num, seed=seed, image_size=image_size, render=render)
        ]
    if kind == "nuscenes":
        from icmapper.data import nuscenes

        path, split = rest, None
        if not Path(rest).is_dir() and ":" in rest:
            path, split = rest.rsplit(":", 1)
        root = Path(path)
        if not root.is_dir():
            raise ValueError(f"bad source spec {spec!r}: {root} is not a directory")
        if split is not None and split_file is None:
            split_file = root / "splits.json"
            if not split_file.is_file():
                raise ValueError(
                    f"source {spec!r} names split {split!r} but no split file was given "
                    f"(split_file=...) and {split_file} does not exist"
                )
        return nuscenes.load_nuscenes(
            root,
            version=_nuscenes_version(root),
            split_file=split_file if split is not None else None,
            split=split,
            image_size=image_size,
            render=render,
            seed=seed,
        )
    raise ValueError(
        f"bad source spec {spec!r}: unknown kind {kind!r} (sim, av2, av2-drives, nuscenes)"
    )
