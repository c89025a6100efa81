"""Shared pytest fixtures.

`shared_data` locates the read-only real-data folder `../shared/data` next to the repository
(Argoverse 2 mini logs, split lists) and skips the test with the reason when it is absent.
`tiny_checkpoint` writes a freshly initialised tiny network checkpoint for learned-path tests.
"""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to `../shared/data` (resolved); skips when the folder is not there."""
    path = SHARED_DATA.resolve()
    if not path.is_dir():
        pytest.skip(f"shared real data not available: {path} does not exist")
    return path


@pytest.fixture(scope="session")
def tiny_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A freshly initialised checkpoint of a tiny version of configs/small.toml (32x88 images),
    for tests of the learned path that need a checkpoint file but not trained weights."""
    import tomllib
    import torch
    from icmapper.models.checkpoint import save_checkpoint
    from icmapper.models.network import ICMapperNet
    from icmapper.training.config import config_from_dict, config_to_dict

    repo = Path(__file__).resolve().parents[1]
    raw = tomllib.loads((repo / "configs" / "small.toml").read_text())
    raw["name"] = "tiny"
    raw["model"].update(
        backbone_widths=[8, 8, 8],
        channels=32,
        bev_x=20,
        bev_y=10,
        num_queries=10,
        num_layers=2,
        topk=5,
        fusion_layers=1,
        instances="decoder",  # untrained masks hold nothing; the queries always give detections
    )
    raw["data"]["image_size"] = [32, 88]
    cfg = config_from_dict(raw)
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    path = tmp_path_factory.mktemp("ckpt") / "tiny.pt"
    save_checkpoint(
        path, model=net.state_dict(), optimizer=None, stage=1, step=0, config=config_to_dict(cfg)
    )
    return path
