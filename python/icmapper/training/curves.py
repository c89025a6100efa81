"""Learning curves of a training run: detection AP per class of every snapshot, plus the training
losses, as a CSV and a picture.

``python -m icmapper.training.curves RUN_DIR [--source sim:val:4] [--stage 1]`` evaluates each
``RUN_DIR/snapshots/stage{n}_step*.pt`` (written by ``snapshot_every``) with the streaming detector
(the ``icmapper-base`` method of ``icmapper compare``, learned detections) on ``--source`` and
writes ``RUN_DIR/curves_stage{n}.csv`` (step, AP per class, mAP; in %) and
``RUN_DIR/curves_stage{n}.png`` (AP per class, and the logged losses of
``stage{n}_metrics.csv``). Snapshots already in the CSV are not evaluated again, so it can run
beside a training run and be called again as snapshots appear.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import re
import tempfile
from pathlib import Path

from icmapper.atomic import write_text_atomic
from icmapper.data.types import CLASS_NAMES

FIELDS = ["step", *[f"AP_{n}" for n in CLASS_NAMES], "mAP"]
_SNAPSHOT = re.compile(r"stage(\d)_step(\d+)\.pt$")


def snapshot_paths(run: Path, stage: int) -> list[tuple[int, Path]]:
    """(step, path) of the run's snapshots of ``stage``, by step."""
    found = []
    for p in (run / "snapshots").glob(f"stage{stage}_step*.pt"):
        m = _SNAPSHOT.search(p.name)
        if m:
            found.append((int(m.group(2)), p))
    return sorted(found)


def evaluate_snapshot(path: Path, source: str) -> dict[str, float]:
    """Detection AP (in %) per class and mAP of one checkpoint on ``source``."""
    from icmapper.cli import main

    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        argv = ["compare", "--source", source, "--methods", "icmapper-base",
                "--checkpoint", str(path), "--out", tmp, "--no-progress"]  # fmt: skip
        if main(argv) != 0:
            raise RuntimeError(f"evaluating {path} on {source} failed")
        det = json.loads((Path(tmp) / "results.json").read_text())["runs"][0]["detection"]
    row = {f"AP_{n}": 100 * float(det["AP_class"][n]) for n in CLASS_NAMES}
    row["mAP"] = 100 * float(det["mAP"])
    return row


def read_rows(path: Path) -> list[dict[str, float]]:
    if not path.is_file():
        return []
    with path.open(newline="") as fh:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def write_rows(path: Path, rows: list[dict[str, float]]) -> None:
    lines = [",".join(FIELDS)]
    for r in sorted(rows, key=lambda r: r["step"]):
        lines.append(",".join(f"{int(r[k])}" if k == "step" else f"{r[k]:.2f}" for k in FIELDS))
    write_text_atomic(path, "\n".join(lines) + "\n")


def plot(rows: list[dict[str, float]], metrics_csv: Path, out: Path, title: str) -> None:
    """AP per class vs step (left) and the logged training losses (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from icmapper.vis.style import CLASS_HEX

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4))
    steps = [r["step"] for r in rows]
    for k, name in enumerate(CLASS_NAMES):
        ax.plot(steps, [r[f"AP_{name}"] for r in rows], "o-", color=CLASS_HEX[k], label=name)
    ax.plot(steps, [r["mAP"] for r in rows], "k--", label="mAP")
    ax.set_xlabel("training step")
    ax.set_ylabel("AP (%) at 60x30, Chamfer 0.5/1/1.5 m")
    ax.set_title("detection on the validation drives")
    ax.grid(alpha=0.3)
    ax.legend()
    logged = read_rows(metrics_csv)
    for key in ("det", "o2m", "seg", "trans", "asso", "fusion"):
        if logged and key in logged[0] and any(r[key] > 0 for r in logged):
            xs = [r["step"] for r in logged]
            ys = [r[key] for r in logged]
            win = max(1, len(ys) // 100)  # moving average over ~1 % of the run
            sm = [sum(ys[max(0, i - win + 1) : i + 1]) / len(ys[max(0, i - win + 1) : i + 1])
                  for i in range(len(ys))]  # fmt: skip
            bx.plot(xs, sm, label=key)
    bx.set_yscale("log")
    bx.set_xlabel("training step")
    bx.set_title("training losses (moving average)")
    bx.grid(alpha=0.3)
    bx.legend()
    fig.suptitle(title)
    fig.tight_layout()
    tmp = out.with_name(out.name + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m icmapper.training.curves", description=__doc__)
    ap.add_argument("run", type=Path, help="training output folder (icmapper train --out)")
    ap.add_argument("--source", default="sim:val:4", help="evaluation source spec")
    ap.add_argument("--stage", type=int, choices=(1, 2), default=1)
    args = ap.parse_args(argv)
    csv_path = args.run / f"curves_stage{args.stage}.csv"
    rows = read_rows(csv_path)
    done = {int(r["step"]) for r in rows}
    snaps = snapshot_paths(args.run, args.stage)
    if not snaps:
        raise SystemExit(f"no snapshots in {args.run / 'snapshots'} (set snapshot_every)")
    for step, path in snaps:
        if step in done:
            continue
        row = {"step": float(step), **evaluate_snapshot(path, args.source)}
        rows.append(row)
        write_rows(csv_path, rows)
        print(f"step {step}: " + ", ".join(f"{k} {row[k]:.1f}" for k in FIELDS[1:]), flush=True)
    metrics = args.run / f"stage{args.stage}_metrics.csv"
    plot(sorted(rows, key=lambda r: r["step"]), metrics, csv_path.with_suffix(".png"),
         f"{args.run.name}: stage {args.stage} on {args.source}")  # fmt: skip
    print(f"wrote {csv_path} and {csv_path.with_suffix('.png')}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
