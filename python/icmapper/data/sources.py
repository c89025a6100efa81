"""Source specs: one string names a list of sequences, so runs and evaluations can recompute
their inputs and ground truth. Each kind is one ``SourceKind`` in the ``SOURCE_KINDS`` registry: a
new dataset is a module with an opener plus one ``register_source`` call; the command line's help
and errors list the registry.

    sim:val            4 synthetic validation drives (cities of sim.CITY_SEEDS["val"])
    sim:<split>:N      N synthetic drives of split train / val / test
    sim-varied:<split>:N
                       N synthetic drives of the same cities with real-road variety (wide lanes,
                       shoulders, unmarked lanes: domain randomisation for training)
    sim-junction:<split>:N
                       N drives of the varied cities with the crossings of each junction at its
                       edge, ringing it (some skewed), as in Argoverse 2 (for training)
    sim-city:<split>:INDEX:N
                       N drives through one synthetic city (city INDEX of the split)
    sim-city-changed:<split>:INDEX:N[:SEED]
                       the same N drives through that city after changes near them (crossings
                       added and removed, lane lines removed, added, moved, a kerb moved; seeded;
                       ``data.sim.changes``: the true changes)
    av2:PATH[:split]   the drive of an Argoverse 2 log, or of every log in a folder of logs (a
                       split keeps the logs named in a split file: `split_file=` or
                       <PATH>/splits.json)
    av2-drives:PATH:N  N synthetic drives along the lane graph of each log under PATH
    nuscenes:PATH[:split]
                       the scenes of a nuScenes dataroot (version: v1.0-trainval if present, else
                       the only v1.0-* folder); the split needs a split file: `split_file=` or
                       <PATH>/splits.json

Options follow the spec as `:NAME=VALUE` segments, e.g. `av2:PATH:images=render`,
`nuscenes:PATH:val:images=real` (`SPEC_OPTIONS`):

    images=auto|real|render   real-data kinds (av2, nuscenes): "real" reads the log's own camera
                              JPEGs and its cameras (7 AV2 ring cameras, 6 nuScenes cameras),
                              with full SE(3) poses and per-keyframe camera parameters; "render"
                              renders synthetic images over the map (planar poses); "auto" (the
                              default): real where the data has images, else render
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from icmapper.data.types import Sequence
from icmapper.registry import Registry

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


#: Options a spec may carry as trailing `:NAME=VALUE` segments, with their accepted values.
SPEC_OPTIONS: dict[str, tuple[str, ...]] = {"images": ("auto", "real", "render")}


@dataclass(frozen=True)
class SourceOptions:
    """What every source kind's opener gets besides the spec: the image size (H, W) of the
    images (rendered, or real ones resized), the seed of synthetic drives and renderers, a split
    file, whether the sequences need images at all (`render`; False: geometry and ground truth
    only) and where images come from (`images`: auto | real | render, see the module docstring;
    kinds without real images ignore it)."""

    image_size: tuple[int, int] = (128, 352)
    seed: int = 0
    split_file: str | Path | None = None
    render: bool = True
    images: str = "auto"


def split_options(spec: str) -> tuple[str, dict[str, str]]:
    """`"av2:PATH:images=render"` -> (`"av2:PATH"`, {"images": "render"}). Trailing segments of
    the form NAME=VALUE are options; an unknown name or value raises ValueError."""
    base, opts = spec, {}
    while True:
        head, sep, last = base.rpartition(":")
        m = re.fullmatch(r"([A-Za-z_]+)=(.*)", last) if sep else None
        if m is None:
            break
        name, value = m.group(1), m.group(2)
        if name not in SPEC_OPTIONS:
            raise ValueError(
                f"bad source spec {spec!r}: unknown option {name!r} "
                f"(known: {', '.join(SPEC_OPTIONS)})"
            )
        if value not in SPEC_OPTIONS[name]:
            raise ValueError(
                f"bad source spec {spec!r}: {name} must be one of "
                f"{'|'.join(SPEC_OPTIONS[name])}, got {value!r}"
            )
        opts.setdefault(name, value)
        base = head
    return base, opts


@dataclass(frozen=True)
class SourceKind:
    """One kind of source spec ("KIND:REST"): ``usage`` and ``help`` for errors and the command
    line; ``open(spec, rest, options)`` returns the sequences; ``path_tag``: the spec names a
    path on disk (run folders are named after its last component); ``real_images``: its
    sequences may carry a camera's own images (not rendered ones)."""

    name: str
    usage: str
    help: str
    open: Callable[[str, str, SourceOptions], list[Sequence]]
    path_tag: bool = False
    real_images: bool = False


#: Registered source kinds by name (``register_source``), in registration order.
SOURCE_KINDS: Registry[SourceKind] = Registry("source kind")


def register_source(kind: SourceKind) -> SourceKind:
    """Adds a source kind (a new dataset: one module with an opener + this one call)."""
    return SOURCE_KINDS.register(kind)


def sources_help() -> str:
    """One line per registered kind: usage and help (for the command line and errors)."""
    lines = [f"  {k.usage:<24} {k.help}" for k in SOURCE_KINDS.values()]
    lines.append(
        "  options: append :images=auto|real|render (real-data kinds; default auto: the log's "
        "own camera images where present)"
    )
    return "\n".join(lines)


def open_source(
    spec: str,
    image_size: tuple[int, int] = (128, 352),
    seed: int = 0,
    split_file: str | Path | None = None,
    render: bool = True,
    images: str | None = None,
) -> list[Sequence]:
    """The sequences a spec names (see the module docstring). `images` (auto | real | render)
    applies where the spec carries no `:images=` option. Raises ValueError for a bad spec and
    DataError (a ValueError) for missing or broken data."""
    usages = ", ".join(repr(k.usage) for k in SOURCE_KINDS.values())
    if not isinstance(spec, str) or ":" not in spec:
        raise ValueError(f"bad source spec {spec!r}: expected one of {usages}")
    full = spec
    spec, opts = split_options(spec)
    if images is not None and images not in SPEC_OPTIONS["images"]:
        raise ValueError(f"images must be one of {SPEC_OPTIONS['images']}, got {images!r}")
    mode = opts.get("images", images or "auto")
    if ":" not in spec:
        raise ValueError(f"bad source spec {full!r}: expected one of {usages}")
    name, rest = spec.split(":", 1)
    kind = SOURCE_KINDS.get(name)
    if kind is None:
        raise ValueError(
            f"bad source spec {spec!r}: unknown kind {name!r} ({', '.join(SOURCE_KINDS)})"
        )
    return kind.open(spec, rest, SourceOptions(image_size, seed, split_file, render, mode))


def resolve_spec(spec: str) -> str:
    """The spec with its path made absolute, so that it names the same data from any working
    folder (what run folders and city manifests store): ``av2:../data:val:images=real`` ->
    ``av2:/abs/data:val:images=real``. The path is the longest ':'-separated head of the rest
    that exists on disk; specs of kinds without a path, or whose path does not exist, come back
    unchanged (opening them reports the problem)."""
    base, _ = split_options(spec)
    name, sep, rest = base.partition(":")
    kind = SOURCE_KINDS.get(name)
    if not sep or kind is None or not kind.path_tag or not rest:
        return spec
    parts = rest.split(":")
    for k in range(len(parts), 0, -1):
        head = ":".join(parts[:k])
        if Path(head).exists():
            tail = rest[len(head) :] + spec[len(base) :]
            return f"{name}:{Path(head).resolve()}{tail}"
    return spec


def may_have_real_images(spec: str) -> bool:
    """Whether a spec (or several joined by " + ", as a training config's ``data.source``) can
    give real camera images: a kind that reads them, not forced to ``images=render``."""
    for one in spec.split(" + "):
        base, opts = split_options(one.strip())
        kind = SOURCE_KINDS.get(base.partition(":")[0])
        if kind is not None and kind.real_images and opts.get("images") != "render":
            return True
    return False


def source_tag(spec: str) -> str:
    """A folder name for a spec's run: "sim-val-4", "av2-<last path component>", ..."""
    base, opts = split_options(spec)
    name, _, rest = base.partition(":")
    kind = SOURCE_KINDS.get(name)
    if kind is not None and kind.path_tag:
        rest = Path(rest.split(":")[0]).name or "data"
    rest += "".join(f"-{k}-{v}" for k, v in sorted(opts.items()))
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", f"{name}-{rest}").strip("-")


# ---------------------------------------------------------------------- the built-in kinds
def _split_count(kind: str, spec: str, rest: str) -> tuple[str, int]:
    """The split and drive count of a ``kind:<split>[:N]`` spec (N: DEFAULT_SIM_COUNT)."""
    parts = rest.split(":")
    if parts[0] not in SIM_SPLITS or len(parts) > 2:
        raise ValueError(f"bad source spec {spec!r}: expected {kind}:<{'|'.join(SIM_SPLITS)}>[:N]")
    return parts[0], _count(parts[1], spec) if len(parts) == 2 else DEFAULT_SIM_COUNT


def _open_sim(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
    from icmapper.data import sim

    split, n = _split_count("sim", spec, rest)
    return list(sim.sim_sequences(split, n, seed=o.seed, image_size=o.image_size))


def _open_sim_variety(kind: str, **variety: bool) -> Callable[..., list[Sequence]]:
    """The opener of ``kind:<split>[:N]``: synthetic drives of cities with a variety
    (``generate_city``'s ``varied`` / ``junctions``)."""

    def open_(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
        from icmapper.data import sim

        split, n = _split_count(kind, spec, rest)
        return list(sim.sim_sequences(split, n, seed=o.seed, image_size=o.image_size, **variety))

    return open_


def _split_arg(spec: str, rest: str, o: SourceOptions) -> tuple[Path, str | None, Path | None]:
    """PATH[:split] -> (path, split, split file): a split needs `split_file` or PATH/splits.json."""
    path, split = rest, None
    if not Path(rest).is_dir() and ":" in rest:
        path, split = rest.rsplit(":", 1)
    root = Path(path)
    if not root.is_dir():
        raise ValueError(f"bad source spec {spec!r}: {root} is not a directory")
    split_file = Path(o.split_file) if o.split_file is not None else None
    if split is not None and split_file is None:
        split_file = root / "splits.json"
        if not split_file.is_file():
            raise ValueError(
                f"source {spec!r} names split {split!r} but no split file was given "
                f"(split_file=...) and {split_file} does not exist"
            )
    return root, split, split_file if split is not None else None


def _open_sim_city(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
    from icmapper.data import sim

    parts = rest.split(":")
    if len(parts) != 3 or parts[0] not in SIM_SPLITS:
        raise ValueError(
            f"bad source spec {spec!r}: expected sim-city:<{'|'.join(SIM_SPLITS)}>:INDEX:N"
        )
    try:
        index = int(parts[1])
    except ValueError:
        raise ValueError(f"bad source spec {spec!r}: {parts[1]!r} is not a city index") from None
    return sim.sim_city_drives(parts[0], index, _count(parts[2], spec), image_size=o.image_size)


def _open_sim_city_changed(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
    from icmapper.data.sim.changes import changed_city_drives

    parts = rest.split(":")
    if len(parts) not in (3, 4) or parts[0] not in SIM_SPLITS:
        raise ValueError(
            f"bad source spec {spec!r}: expected "
            f"sim-city-changed:<{'|'.join(SIM_SPLITS)}>:INDEX:N[:SEED]"
        )
    try:
        index, seed = int(parts[1]), int(parts[3]) if len(parts) == 4 else 0
    except ValueError:
        raise ValueError(f"bad source spec {spec!r}: the index and seed must be ints") from None
    num = _count(parts[2], spec)
    return changed_city_drives(parts[0], index, num, seed, image_size=o.image_size)[0]


def _open_sim_repainted(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
    from icmapper.data.sim.changes import repainted_sequences

    split, n = _split_count("sim-repainted", spec, rest)
    return repainted_sequences(split, n, seed=o.seed, image_size=o.image_size)


def _open_av2(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
    from icmapper.data import av2
    from icmapper.data.errors import DataError
    from icmapper.data.nuscenes import read_split

    if not rest:
        raise ValueError(f"bad source spec {spec!r}: no path")
    root, split, split_file = _split_arg(spec, rest, o)
    logs = av2.find_av2_logs(root)
    if split is not None and split_file is not None:
        wanted = set(read_split(split_file, split))
        logs = [log for log in logs if log.name in wanted]
        if not logs:
            raise DataError(f"no log of split {split!r} ({split_file}) is in {root}")
    return [
        av2.load_av2_sequence(
            log, image_size=o.image_size, render=o.render, seed=o.seed, images=o.images
        )
        for log in logs
    ]


def _open_av2_drives(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
    from icmapper.data import av2

    path, _, n = rest.rpartition(":")
    if not path:
        raise ValueError(f"bad source spec {spec!r}: expected av2-drives:PATH:N")
    num = _count(n, spec)
    return [
        s
        for log in av2.find_av2_logs(path)
        for s in av2.av2_drives(log, num, seed=o.seed, image_size=o.image_size, render=o.render)
    ]


def _open_nuscenes(spec: str, rest: str, o: SourceOptions) -> list[Sequence]:
    from icmapper.data import nuscenes

    root, split, split_file = _split_arg(spec, rest, o)
    return nuscenes.load_nuscenes(
        root,
        version=_nuscenes_version(root),
        split_file=split_file,
        split=split,
        image_size=o.image_size,
        render=o.render,
        seed=o.seed,
        images=o.images,
    )


register_source(
    SourceKind("sim", "sim:<split>[:N]", "N synthetic drives (split train|val|test)", _open_sim)
)
register_source(
    SourceKind(
        "sim-varied",
        "sim-varied:<split>[:N]",
        "N synthetic drives of cities with real-road variety (wide lanes, shoulders, unmarked "
        "lanes; for training)",
        _open_sim_variety("sim-varied", varied=True),
    )
)
register_source(
    SourceKind(
        "sim-junction",
        "sim-junction:<split>[:N]",
        "N synthetic drives of the varied cities with crossings ringing the junctions (at the "
        "junction's edge, some skewed, as in Argoverse 2; for training)",
        _open_sim_variety("sim-junction", junctions=True),
    )
)
register_source(
    SourceKind(
        "sim-city",
        "sim-city:<split>:INDEX:N",
        "N drives through one synthetic city (city INDEX of the split): a city run",
        _open_sim_city,
    )
)
register_source(
    SourceKind(
        "sim-city-changed",
        "sim-city-changed:<split>:INDEX:N[:SEED]",
        "the N drives of sim-city:<split>:INDEX:N through that city after changes near them "
        "(seeded; the true changes: icmapper.data.sim.changes)",
        _open_sim_city_changed,
    )
)
register_source(
    SourceKind(
        "sim-repainted",
        "sim-repainted:<split>[:N]",
        "the N drives of sim:<split>:N, each through its city with lane lines removed, added and "
        "moved near it (paint that departs from the lane layout; for training)",
        _open_sim_repainted,
    )
)
register_source(
    SourceKind(
        "av2",
        "av2:PATH[:split]",
        "an Argoverse 2 log, or every log in a folder (a split needs a split file)",
        _open_av2,
        path_tag=True,
        real_images=True,
    )
)
register_source(
    SourceKind(
        "av2-drives",
        "av2-drives:PATH:N",
        "N synthetic drives along the lane graph of each AV2 log under PATH",
        _open_av2_drives,
        True,
    )
)
register_source(
    SourceKind(
        "nuscenes",
        "nuscenes:PATH[:split]",
        "the scenes of a nuScenes dataroot (a split needs a split file)",
        _open_nuscenes,
        path_tag=True,
        real_images=True,
    )
)
