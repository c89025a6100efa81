"""The backbone's residual block: its strided 1x1 shortcut written as a 1x1 convolution of every
second pixel gives the strided convolution's values, its backward no longer crashes oneDNN on
two threads for the small shapes where the strided form did, and the gradient of its input keeps
the input's channels-last layout (a gradient of the other layout made the ReLU backward before the
block about 30x slower)."""

from __future__ import annotations

import subprocess
import sys

import torch
import torch.nn.functional as F
from icmapper.models.backbone import BasicBlock


def test_shortcut_equals_the_strided_convolution() -> None:
    torch.manual_seed(0)
    block = BasicBlock(8, 16, 2).eval()
    x = torch.randn(3, 8, 9, 17)  # odd sizes: the strided form keeps ceil(H / 2) rows too
    conv, bn = block.down[0], block.down[1]
    ref_short = bn(F.conv2d(x, conv.weight, stride=2))  # the former shortcut
    y = block.bn2(block.conv2(F.relu(block.bn1(block.conv1(x)))))
    torch.testing.assert_close(block(x), F.relu(y + ref_short))


def test_shortcut_backward_on_two_threads_does_not_crash() -> None:
    """The shape that crashed the process (7 images of 8 x 16, 8 -> 16 channels, channels-last,
    2 threads), in a child process so that a crash fails the test instead of the suite."""
    code = (
        "import torch\n"
        "from icmapper.models.backbone import BasicBlock\n"
        "torch.set_num_threads(2)\n"
        "block = BasicBlock(8, 16, 2).to(memory_format=torch.channels_last)\n"
        "x = torch.randn(7, 8, 8, 16).contiguous(memory_format=torch.channels_last)\n"
        "x.requires_grad_()\n"
        "for _ in range(20):\n"
        "    block(x).square().sum().backward()\n"
        "print('ok')\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr[-2000:]


def test_input_gradient_keeps_the_channels_last_layout() -> None:
    torch.manual_seed(0)
    block = BasicBlock(8, 16, 2).to(memory_format=torch.channels_last)
    x = torch.randn(3, 8, 10, 18).contiguous(memory_format=torch.channels_last).requires_grad_()
    y = F.relu(x)  # as the stem's ReLU before the first stage
    out = block(y)  # (3, 16, 5, 9)
    assert out.is_contiguous(memory_format=torch.channels_last)
    (grad,) = torch.autograd.grad(out.square().sum(), y)
    assert grad.is_contiguous(memory_format=torch.channels_last)
