"""DDP: 2 CPU processes (torchrun, gloo, 127.0.0.1, a free port) train a few steps on tiny
synthetic clips; both replicas must end with identical parameters."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest

CONFIG = """
log_every = 1
ckpt_every = 100
[model]
num_cameras = 2
backbone_widths = [8, 16]
backbone_depths = [1, 1]
channels = 32
bev_x = 20
bev_y = 10
num_queries = 8
num_layers = 2
topk = 3
[data]
source = "synthetic:4"
clip_len = 2
image_size = [32, 64]
[stage1]
batch_size = 1
steps = 3
warmup_steps = 0
lr = 2e-3
"""


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.timeout(120)
def test_ddp_two_cpu_replicas_stay_identical(tmp_path: Path) -> None:
    cfg = tmp_path / "ddp.toml"
    cfg.write_text(CONFIG)
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2",
        "--master_addr", "127.0.0.1", "--master_port", str(_free_port()),
        "-m", "icmapper", "train", "--config", str(cfg), "--out", str(tmp_path / "out"),
        "--no-progress",
    ]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=110, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    digests = dict(re.findall(r"rank (\d)/2: parameter digest ([0-9a-f]{64})", proc.stdout))
    assert set(digests) == {"0", "1"}, proc.stdout
    assert digests["0"] == digests["1"]
    assert (tmp_path / "out" / "stage1.pt").is_file()


def _toml(raw: dict) -> str:
    """A TOML text of a config dict (top-level keys, then one table per dict value)."""

    def value(v: object) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    top = [f"{k} = {value(v)}" for k, v in raw.items() if not isinstance(v, dict)]
    tables = [
        f"[{name}]\n" + "\n".join(f"{k} = {value(v)}" for k, v in table.items())
        for name, table in raw.items()
        if isinstance(table, dict)
    ]
    return "\n".join(top) + "\n" + "\n".join(tables) + "\n"


@pytest.mark.timeout(240)
def test_ddp_frozen_encoder_ranks_share_the_bev_cache(tmp_path: Path) -> None:
    """Two CPU ranks training on cached BEVs of a frozen encoder under torchrun: the ranks encode
    their shares, meet at the barrier, read each other's files (one per sequence) and end with
    identical replicas (that each sequence is encoded once: test_training_bevcache)."""
    from icmapper.testing.configs import tiny_raw
    from icmapper.training.config import config_from_dict
    from icmapper.training.loop import train

    raw = tiny_raw(
        model={"num_cameras": 6, "channels": 16},
        data={"source": "sim:val:3", "bev_cache_dir": str(tmp_path / "bev")},
        stage1={"steps": 2},
    )
    train(config_from_dict(raw), 1, tmp_path / "encoder", progress=False)
    cfg = tmp_path / "frozen.toml"
    cfg.write_text(_toml({**raw, "stage1": {**raw["stage1"], "freeze_encoder": True}}))
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2",
        "--master_addr", "127.0.0.1", "--master_port", str(_free_port()),
        "-m", "icmapper", "train", "--config", str(cfg), "--out", str(tmp_path / "out"),
        "--init", str(tmp_path / "encoder" / "stage1.pt"), "--no-progress",
    ]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=220, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    digests = dict(re.findall(r"rank (\d)/2: parameter digest ([0-9a-f]{64})", proc.stdout))
    assert set(digests) == {"0", "1"} and digests["0"] == digests["1"], proc.stdout
    (cache,) = (tmp_path / "bev").glob("bev-*")
    assert len(list(cache.glob("*.pt"))) == 3
