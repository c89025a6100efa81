"""ResNet-style image backbone trained from scratch (no downloaded weights).

A stem, ``len(depths)`` residual stages (each halving the resolution) and a light top-down fusion of
the last two stages; the output has stride ``2 ** len(depths)`` divided by 2 (the fused level).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class BasicBlock(nn.Module):
    """Two 3x3 convolutions with a residual connection (ResNet-18 block)."""

    def __init__(self, c_in: int, c_out: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(c_out)
        self.down: nn.Module = nn.Identity()
        self.down_stride = stride
        if stride != 1 or c_in != c_out:
            # A 1x1 convolution of stride s is the 1x1 convolution of every s-th pixel; written
            # so because oneDNN's backward of the strided 1x1 convolution crashes the process
            # (segmentation fault) for some small shapes on more than one thread (8 -> 16
            # channels on 7 images of 8 x 16, torch 2.15; tests/test_models_backbone.py).
            # Every s-th pixel is taken by a pooling of kernel 1 (the same values): unlike the
            # slice x[:, :, ::s, ::s], its output and its gradient keep x's channels-last
            # layout, and a gradient of the other layout made the ReLU backward of x about 30x
            # slower (9 ms of the 200 ms training step of configs/small.toml).
            self.down = nn.Sequential(
                nn.Conv2d(c_in, c_out, 1, 1, bias=False), nn.BatchNorm2d(c_out)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        s = self.down_stride
        return F.relu(y + self.down(F.avg_pool2d(x, 1, s) if s > 1 else x))


class ResNetBackbone(nn.Module):
    """Image features for the view transformer.

    Args:
        widths: channels of each stage, e.g. (16, 32, 64, 128).
        depths: residual blocks per stage, e.g. (1, 1, 1, 1).
        out_channels: channels of the output map.

    forward: (N, 3, H, W) float images (normalised) -> (N, out_channels, H / s, W / s) with
    ``s = 2 ** len(widths)`` (stem stride 2, every stage stride 2, fused with the last stage).
    """

    def __init__(self, widths: tuple[int, ...], depths: tuple[int, ...], out_channels: int) -> None:
        super().__init__()
        if len(widths) != len(depths) or len(widths) < 2:
            raise ValueError("backbone widths and depths must have the same length >= 2")
        if min(widths) <= 0 or min(depths) <= 0:
            raise ValueError("backbone widths and depths must be positive")
        self.stem = nn.Sequential(
            nn.Conv2d(3, widths[0], 3, 2, 1, bias=False), nn.BatchNorm2d(widths[0]), nn.ReLU()
        )
        stages = []
        c_in = widths[0]
        for w, d in zip(widths, depths, strict=True):
            blocks = [BasicBlock(c_in, w, 2)] + [BasicBlock(w, w, 1) for _ in range(d - 1)]
            stages.append(nn.Sequential(*blocks))
            c_in = w
        self.stages = nn.ModuleList(stages)
        self.lateral = nn.Conv2d(widths[-2], out_channels, 1)
        self.top = nn.Conv2d(widths[-1], out_channels, 1)
        self.out = nn.Sequential(
            nn.Conv2d(out_channels, out_channels, 3, 1, 1), nn.GroupNorm(1, out_channels), nn.ReLU()
        )
        self.stride = 2 ** len(widths)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.stem(x)  # (N, w0, H/2, W/2)
        feats = []
        for stage in self.stages:
            x = stage(x)
            feats.append(x)
        c4, c5 = feats[-2], feats[-1]  # (N, w[-2], H/s, W/s), (N, w[-1], H/2s, W/2s)
        up = F.interpolate(self.top(c5), size=c4.shape[-2:], mode="bilinear", align_corners=False)
        return self.out(self.lateral(c4) + up)  # (N, out_channels, H/s, W/s)
