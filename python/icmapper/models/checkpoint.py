"""Checkpoints as plain state dicts (no pickled objects): written atomically, read with
``torch.load(..., weights_only=True)``.

Content: format/version, stage, step, the network state dict, the optimizer state dict, the config
as a plain dict and the torch RNG state.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from icmapper.atomic import atomic_open
from icmapper.versioned import check_versioned

FORMAT = "icmapper-checkpoint"
VERSION = 1


def save_checkpoint(
    path: str | Path,
    *,
    model: dict[str, torch.Tensor],
    optimizer: dict[str, Any] | None,
    stage: int,
    step: int,
    config: dict[str, Any],
) -> None:
    """Writes a checkpoint atomically (``icmapper.atomic``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    blob = {
        "format": FORMAT,
        "version": VERSION,
        "stage": int(stage),
        "step": int(step),
        "model": {k: v.detach().cpu() for k, v in model.items()},
        "optimizer": optimizer,
        "config": config,
        "rng": torch.get_rng_state(),
    }
    with atomic_open(path, "wb") as fh:
        torch.save(blob, fh)


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Reads a checkpoint (weights_only=True); ValueError when it is not an icmapper checkpoint."""
    path = Path(path)
    if not path.is_file():
        raise OSError(f"checkpoint {path} does not exist")
    if path.stat().st_size == 0:
        raise ValueError(f"checkpoint {path} is unreadable: the file is empty (0 bytes)")
    try:
        blob = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # corrupt / foreign file
        # torch's own message suggests weights_only=False, which we never do (untrusted files):
        # name the file and the kind of failure only
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        if "weights_only" in first or "Weights only" in first:
            first = "not a tensors-only (safe to load) torch checkpoint"
        elif not first:  # e.g. a bare EOFError of a truncated file
            first = f"{type(exc).__name__} (truncated or not a torch checkpoint)"
        raise ValueError(f"checkpoint {path} is unreadable: {first}") from None
    return check_versioned(blob, FORMAT, VERSION, f"checkpoint {path}", "checkpoint")


def export_checkpoint(
    src: str | Path,
    dst: str | Path,
    mapper: dict[str, Any] | None = None,
    take: dict[str, str | Path] | None = None,
) -> None:
    """Writes an inference checkpoint: ``src`` without optimizer and RNG state (smaller; what the
    Mapper needs), atomically. ``mapper``: a ``[mapper]`` table (the mapper settings chosen on
    validation for this network) that replaces the checkpoint's, so that settings are retuned
    without retraining. ``take``: {module prefix (e.g. ``"fusion."``): checkpoint} whose
    tensors under that prefix replace ``src``'s (a network composed of separately trained parts:
    an association retrained beside a shipped fusion); ValueError when the other checkpoint has
    no tensor under the prefix, or not the same names and shapes there. Usage: ``python -m
    icmapper.models.checkpoint SRC DST [--mapper-from CONFIG.toml] [--take PREFIX=FILE ...]``
    (the ``[mapper]`` table of a training config, checked as the training run checks it)."""
    blob = load_checkpoint(src)
    config = dict(blob["config"])
    if mapper is not None:
        if not isinstance(mapper, dict):
            raise ValueError(f"the [mapper] settings must be a table, got {type(mapper).__name__}")
        config["mapper"] = dict(mapper)
    model = dict(blob["model"])
    for prefix, path in (take or {}).items():
        other = load_checkpoint(path)["model"]
        mine = {k: v for k, v in model.items() if k.startswith(prefix)}
        theirs = {k: v for k, v in other.items() if k.startswith(prefix)}
        if not theirs:
            raise ValueError(f"checkpoint {path} has no tensor under {prefix!r}")
        shapes = {k: tuple(v.shape) for k, v in theirs.items()}
        if shapes != {k: tuple(v.shape) for k, v in mine.items()}:
            raise ValueError(
                f"checkpoint {path}: the tensors under {prefix!r} differ in names or shapes "
                f"from {src}'s"
            )
        model.update(theirs)
    save_checkpoint(
        dst,
        model=model,
        optimizer=None,
        stage=blob["stage"],
        step=blob["step"],
        config=config,
    )


#: The weights laid out per BEV cell, (X * Y, C) in the cells' raster order (``models.bev``):
#: the only tensors whose shape depends on the grid.
GRID_TENSORS = ("detector.view.query",)


def regrid_state(
    state: dict[str, torch.Tensor], old: tuple[int, int], new: tuple[int, int]
) -> dict[str, torch.Tensor]:
    """``state`` with its per-cell tensors (``GRID_TENSORS``) resampled from a BEV grid of
    ``old`` (X, Y) cells to ``new`` over the same range (bilinear, cell centres aligned), so
    that a fine-tune can start a finer or coarser grid from trained weights. Other tensors are
    shared, not copied."""
    if tuple(old) == tuple(new):
        return state
    (ox, oy), (nx, ny) = old, new
    if min(ox, oy, nx, ny) < 1:
        raise ValueError(f"BEV grids must have >= 1 cell per side, got {old} -> {new}")
    out = dict(state)
    for key in GRID_TENSORS:
        if key not in state:
            continue
        t = state[key]
        if t.ndim != 2 or t.shape[0] != ox * oy:
            raise ValueError(f"{key} has shape {tuple(t.shape)}, not ({ox} * {oy}, C)")
        grid = t.float().t().reshape(1, t.shape[1], ox, oy)  # (1, C, X, Y)
        fine = torch.nn.functional.interpolate(
            grid, size=(nx, ny), mode="bilinear", align_corners=False
        )  # (1, C, X', Y')
        out[key] = fine.reshape(t.shape[1], nx * ny).t().contiguous().to(t.dtype)  # (X'Y', C)
    return out


if __name__ == "__main__":  # pragma: no cover
    import argparse

    ap = argparse.ArgumentParser(
        prog="python -m icmapper.models.checkpoint", description=export_checkpoint.__doc__
    )
    ap.add_argument("src")
    ap.add_argument("dst")
    ap.add_argument("--mapper-from", metavar="CONFIG.toml", help="its [mapper] table")
    ap.add_argument(
        "--take",
        action="append",
        default=[],
        metavar="PREFIX=FILE",
        help="the tensors under PREFIX (e.g. fusion.) from checkpoint FILE (repeatable)",
    )
    a = ap.parse_args()
    mapper = None
    if a.mapper_from:
        from icmapper.training.config import load_config

        mapper = load_config(a.mapper_from).mapper
    take = {}
    for item in a.take:
        prefix, sep, path = item.partition("=")
        if not sep or not prefix or not path:
            ap.error(f"--take wants PREFIX=FILE, got {item!r}")
        take[prefix] = path
    export_checkpoint(a.src, a.dst, mapper, take)
