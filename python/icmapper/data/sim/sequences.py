"""Synthetic sequences: a city, a drive through it, the nuScenes-like rig and a lazy renderer."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from icmapper.data.sim.city import CITY_SEEDS, generate_city, variety_prefix
from icmapper.data.sim.driver import drive
from icmapper.data.sim.renderer import Renderer
from icmapper.data.sim.rig import nuscenes_rig
from icmapper.data.types import Sequence, WorldMap


def _frame_seed(city_seed: int, drive_seed: int, i: int) -> int:
    return int(np.random.default_rng([city_seed, drive_seed, i, 0xF5]).integers(0, 2**62))


def sim_sequence(
    city_seed: int,
    drive_seed: int,
    image_size: tuple[int, int] = (128, 352),
    world: WorldMap | None = None,
    varied: bool = False,
    junctions: bool = False,
) -> Sequence:
    """The drive `drive_seed` through city `city_seed` as a Sequence named "sim-<city>-<drive>"
    ("sim-varied-<city>-<drive>" in the ``varied`` city, "sim-junction-..." in the ``junctions``
    one: ``generate_city``) (source "sim"). `render(i)` gives frame
    i's images (C, 3, H, W) uint8; one Renderer is made per sequence and paints its world raster on
    the first frame. `world` lets callers pass the already generated city of `city_seed` (it must
    be that city)."""
    if world is None:
        world = generate_city(city_seed, varied, junctions)
    timestamps, poses = drive(world, drive_seed)
    rig = nuscenes_rig(image_size)
    renderer = Renderer(
        world, rig, seed=int(np.random.default_rng([city_seed, drive_seed]).integers(2**31))
    )

    def render(i: int) -> NDArray[np.uint8]:
        if not -len(timestamps) <= i < len(timestamps):
            raise IndexError(f"frame {i} out of range for {len(timestamps)} frames")
        return renderer.render(
            poses[i], frame_seed=_frame_seed(city_seed, drive_seed, i), t=float(timestamps[i])
        )

    name = f"sim-{variety_prefix(varied, junctions)}{city_seed}-{drive_seed}"
    return Sequence(name, "sim", world, timestamps, poses, rig, render)


def sim_city_seeds(split: str, num: int, seed: int = 0) -> list[int]:
    """The city seeds of ``sim_sequences(split, num, seed)``'s drives, in order (drive seed =
    position): drawn from the split's range with ``seed``, without repeats while it has enough."""
    if split not in CITY_SEEDS:
        raise ValueError(f"unknown split {split!r}; expected one of {sorted(CITY_SEEDS)}")
    if num < 0:
        raise ValueError(f"num must be >= 0, got {num}")
    cities = CITY_SEEDS[split]
    rng = np.random.default_rng([int(seed), 0x5E9])
    picks = rng.choice(len(cities), size=num, replace=num > len(cities))
    return [int(cities[int(p)]) for p in picks]


def sim_sequences(
    split: str,
    num: int,
    seed: int = 0,
    image_size: tuple[int, int] = (128, 352),
    varied: bool = False,
    junctions: bool = False,
) -> list[Sequence]:
    """`num` deterministic sequences of `split` ("train" | "val" | "test"): city seeds drawn from
    the split's range with `seed` (without repeats while the split has enough cities), one drive
    each (drive seed = position in the list). Each city is generated once (``varied``: the cities
    with real-road variety; ``junctions``: those with crossings ringing the junctions;
    ``generate_city``)."""
    worlds: dict[int, WorldMap] = {}
    out = []
    for k, city in enumerate(sim_city_seeds(split, num, seed)):
        if city not in worlds:
            worlds[city] = generate_city(city, varied, junctions)
        out.append(
            sim_sequence(
                city, k, image_size, world=worlds[city], varied=varied, junctions=junctions
            )
        )
    return out


def sim_city_drives(
    split: str,
    index: int,
    num: int,
    image_size: tuple[int, int] = (128, 352),
    world: WorldMap | None = None,
) -> list[Sequence]:
    """`num` drives through ONE synthetic city: city ``CITY_SEEDS[split][index]``, drive seeds
    0..num-1 (random start lanes, turns and lengths along the same lane graph, so routes overlap
    and cross each other in both directions), each starting at its own time of day (timestamps
    offset by a seeded start in [0, 12 h)). Named "sim-<city>-<k>"; all share one WorldMap
    (``world``: that city as given, e.g. changed by ``sim.changes``; its lane graph must be the
    city's, so that the drives are the same)."""
    if split not in CITY_SEEDS:
        raise ValueError(f"unknown split {split!r}; expected one of {sorted(CITY_SEEDS)}")
    cities = CITY_SEEDS[split]
    if not 0 <= index < len(cities):
        raise ValueError(f"city index {index} out of range for split {split!r} ({len(cities)})")
    if num < 1:
        raise ValueError(f"num must be >= 1, got {num}")
    city = cities[index]
    world = generate_city(city) if world is None else world
    out = []
    for k in range(num):
        seq = sim_sequence(city, k, image_size, world=world)
        start = float(np.random.default_rng([city, k, 0x57A]).uniform(0.0, 12 * 3600.0))
        seq.timestamps = seq.timestamps + round(start, 1)  # (T,) seconds of the day
        out.append(seq)
    return out
