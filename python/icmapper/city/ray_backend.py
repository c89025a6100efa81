"""Drives of a city run as Ray tasks (optional: ``pip install icmapper[ray]``).

A pool of actors, each holding one ``DriveMapper`` (the method and the networks of a checkpoint
loaded once per worker), maps the drives; each returns its drive map as native bytes; the city
map is built by a tree of ``merge_map`` tasks over those bytes in drive order (the same pairs as
in-process: ``reduce.tree_reduce``). Actors are restarted once and their calls retried once when a
worker dies; a drive that fails with an error is reported (not retried) and left out.

Without ``address`` a local Ray instance with ``workers`` CPUs is started (and shut down after);
with ``address`` the run joins that cluster.
"""

from __future__ import annotations

from typing import Any

from icmapper.city.drives import CitySettings, DriveMapper, DriveOutcome, DriveTask
from icmapper.city.reduce import merge_bytes, tree_reduce

INSTALL_HINT = "Ray is not installed: pip install 'icmapper[ray]' (or: pip install ray)"


def ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


class _DriveActor:
    def __init__(self, settings: CitySettings) -> None:
        self.mapper = DriveMapper(settings)

    def map_drive(self, task: DriveTask) -> DriveOutcome:
        return self.mapper.map_drive(task)


def run_on_ray(
    settings: CitySettings,
    tasks: list[DriveTask],
    workers: int,
    address: str | None = None,
    gate: float = 1.5,
    min_overlap: float = 0.5,
    tolerance: float = 3.0,
) -> tuple[list[DriveOutcome], bytes | None]:
    """Maps ``tasks`` on ``workers`` Ray actors and merges the drive maps by a tree of Ray tasks.
    Returns the outcomes (in task order; map bytes dropped) and the merged map's bytes (None when
    no drive succeeded). ImportError with the install hint without Ray."""
    try:
        import ray
        from ray.util import ActorPool
    except ImportError:
        raise ImportError(INSTALL_HINT) from None
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    started = not ray.is_initialized()
    if started:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
        if address:
            ray.init(address=address, **kwargs)
        else:
            ray.init(num_cpus=workers, **kwargs)
    try:
        actor = ray.remote(num_cpus=1, max_restarts=1, max_task_retries=1)(_DriveActor)
        actors = [actor.remote(settings) for _ in range(min(workers, len(tasks)) or 1)]
        outcomes = list(ActorPool(actors).map(lambda a, t: a.map_drive.remote(t), tasks))
        for a in actors:  # an actor holds its CPU while alive: free them for the merges
            ray.kill(a)
        merge = ray.remote(num_cpus=1, max_retries=1)(merge_bytes)
        ok = sorted((o for o in outcomes if o.status == "ok"), key=lambda o: o.index)
        refs = [ray.put(o.map_bytes) for o in ok]
        merged = None
        if refs:
            root = tree_reduce(refs, lambda a, b: merge.remote(a, b, gate, min_overlap, tolerance))
            merged = ray.get(root)
        for o in outcomes:
            o.map_bytes = None
        return outcomes, merged
    finally:
        if started:
            ray.shutdown()
