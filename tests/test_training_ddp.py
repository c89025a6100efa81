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
