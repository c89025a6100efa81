"""BEV features from multi-camera image features, and the temporal BEV memory.

``ViewTransformer``: BEVFormer-style spatial cross-attention. Each BEV cell is a pillar of points at
a few heights; each point is projected into every camera with its intrinsics/extrinsics; the image
features bilinearly sampled there are combined with learned weights over (camera, height) (softmax
over the valid projections), then projected, with a residual and an FFN. Only the valid samples
are used, and their weighted sums are one sparse matrix product (``weighted_sample_sum``). Which
samples are valid, their bilinear corners and the matrix's pattern depend on the cameras alone;
they are kept while the same cameras come again (``ViewTransformer.geometry``).

``BevNeck``: a few residual 3x3 convolutions on each frame's BEV, so that every cell sees its
neighbours before the temporal memory and the decoder (without it the BEV is a per-cell attention
over image samples).

``TemporalMemory``: the previous BEV warped into the current ego frame by the ego motion and fused
with the current BEV by a convolutional GRU (StreamMapNet).

BEV layout: (B, C, X, Y) with X = ``bev_x`` cells along ego x (forward, -hx..hx) and Y = ``bev_y``
cells along ego y (left, -hy..hy); cell centres at ((i + 0.5) / X, (j + 0.5) / Y) of the range.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn


def bev_cell_centres(bev_x: int, bev_y: int, half_x: float, half_y: float) -> torch.Tensor:
    """Ego-frame (x, y) metres of the BEV cell centres: (X, Y, 2) float32."""
    xs = (torch.arange(bev_x, dtype=torch.float32) + 0.5) / bev_x * 2 * half_x - half_x  # (X,)
    ys = (torch.arange(bev_y, dtype=torch.float32) + 0.5) / bev_y * 2 * half_y - half_y  # (Y,)
    gx, gy = torch.meshgrid(xs, ys, indexing="ij")  # (X, Y)
    return torch.stack([gx, gy], dim=-1)  # (X, Y, 2)


def sample_bev(bev: torch.Tensor, points01: torch.Tensor) -> torch.Tensor:
    """Bilinear samples of a BEV map at normalised points.

    bev (B, C, X, Y); points01 (B, ..., 2) with (x, y) in [0, 1] of the range -> (B, ..., C);
    outside points read zeros.
    """
    b = bev.shape[0]
    lead = points01.shape[1:-1]
    grid = points01.reshape(b, -1, 1, 2).flip(-1) * 2 - 1  # (B, P, 1, 2) as (y -> W, x -> H)
    out = F.grid_sample(bev, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    return out.squeeze(-1).transpose(1, 2).reshape(b, *lead, bev.shape[1])  # (B, ..., C)


class ViewTransformer(nn.Module):
    """Image features -> BEV features by spatial cross-attention at projected pillar points.

    forward(feats (B, N_cam, C_img, h, w), intrinsics (B, N_cam, 3, 3) in pixels of the input image,
    cam_to_ego (B, N_cam, 4, 4), image_size (H, W)) -> BEV (B, C, X, Y).
    """

    def __init__(
        self,
        img_channels: int,
        channels: int,
        bev_x: int,
        bev_y: int,
        half_x: float,
        half_y: float,
        heights: tuple[float, ...],
        num_cameras: int,
    ) -> None:
        super().__init__()
        self.bev_x, self.bev_y = bev_x, bev_y
        self.num_cameras = num_cameras
        self.num_heights = len(heights)
        centres = bev_cell_centres(bev_x, bev_y, half_x, half_y).reshape(-1, 2)  # (N, 2)
        z = torch.tensor(heights, dtype=torch.float32)  # (Z,)
        pillars = torch.cat(
            [
                centres[:, None, :].expand(-1, len(heights), 2),
                z[None, :, None].expand(centres.shape[0], -1, 1),
                torch.ones(centres.shape[0], len(heights), 1),
            ],
            dim=-1,
        )  # (N, Z, 4) homogeneous ego points
        self.register_buffer("pillars", pillars, persistent=False)
        self.query = nn.Parameter(torch.randn(bev_x * bev_y, channels) * 0.02)  # (N, C)
        self.value = nn.Linear(img_channels, channels)
        self.query_logits = nn.Linear(channels, num_cameras * len(heights))
        self.feat_logits = nn.Linear(channels, 1)
        self.proj = nn.Linear(channels, channels)
        self.norm1 = nn.LayerNorm(channels)
        self.ffn = nn.Sequential(
            nn.Linear(channels, 2 * channels), nn.ReLU(), nn.Linear(2 * channels, channels)
        )
        self.norm2 = nn.LayerNorm(channels)
        self._geometry: SampleGeometry | None = None  # the last cameras' (``geometry``)

    def project(
        self, intrinsics: torch.Tensor, cam_to_ego: torch.Tensor, image_size: tuple[int, int]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Pillar points in every camera.

        Returns grid (B, N_cam, N, Z, 2) in [-1, 1] and valid (B, N_cam, N, Z).
        """
        ego_to_cam = torch.linalg.inv(cam_to_ego.float())  # (B, Ncam, 4, 4)
        p = torch.einsum("bcij,nzj->bcnzi", ego_to_cam, self.pillars)[..., :3]  # (B, Ncam, N, Z, 3)
        uvw = torch.einsum("bcij,bcnzj->bcnzi", intrinsics.float(), p)  # (B, Ncam, N, Z, 3)
        depth = uvw[..., 2]  # (B, Ncam, N, Z)
        uv = uvw[..., :2] / depth.clamp(min=1e-3)[..., None]  # (B, Ncam, N, Z, 2) pixels
        h, w = image_size
        grid = torch.stack([uv[..., 0] / w, uv[..., 1] / h], dim=-1) * 2 - 1  # (B, Ncam, N, Z, 2)
        valid = (depth > 0.1) & (grid.abs() <= 1).all(-1)  # (B, Ncam, N, Z)
        return grid, valid

    def geometry(
        self,
        intrinsics: torch.Tensor,
        cam_to_ego: torch.Tensor,
        image_size: tuple[int, int],
        feat_size: tuple[int, int],
    ) -> SampleGeometry:
        """The valid samples of these cameras on feature maps of ``feat_size`` (h, w), their
        bilinear corners and the sparse pattern of their sums (``SampleGeometry``).

        They depend on the cameras only, not on the images or the weights, so the last ones are
        kept and reused while the same cameras come again (every frame of a drive, every clip of
        a fixed rig): an equality test of the camera tensors instead of the projection, the
        selection of the valid samples and two sorts (the pattern and its transpose)."""
        key = Cameras(intrinsics, cam_to_ego, tuple(image_size), tuple(feat_size))
        last = self._geometry
        if last is not None and last.matches(key):
            return last
        # in float32 under autocast too: the sample positions are geometry, and the same cameras
        # must give the same samples with and without autocast
        with torch.autocast(intrinsics.device.type, enabled=False):
            grid, valid = self.project(intrinsics, cam_to_ego, image_size)
        b, ncam, n, _ = valid.shape
        fh, fw = feat_size
        # Only the valid samples (pillar points in front of a camera and inside its image; a
        # small share of all (camera, cell, height) triples) are used, in BEV-cell order.
        ib, icell, ic, iz = valid.permute(0, 2, 1, 3).nonzero(as_tuple=True)  # (V,) each
        idx, bw = bilinear_corners(grid[ib, ic, icell, iz], ib * ncam + ic, fh, fw)  # (V, 4) each
        rows = ib * n + icell  # (V,) output row of each sample
        pattern = sample_pattern(rows, idx, b * n, b * ncam * fh * fw)
        made_for = key._replace(
            intrinsics=intrinsics.detach().clone(), cam_to_ego=cam_to_ego.detach().clone()
        )
        self._geometry = SampleGeometry(made_for, ib, icell, ic, iz, rows, idx, bw, pattern)
        return self._geometry

    def forward(
        self,
        feats: torch.Tensor,
        intrinsics: torch.Tensor,
        cam_to_ego: torch.Tensor,
        image_size: tuple[int, int],
    ) -> torch.Tensor:
        b, ncam, c_img, fh, fw = feats.shape
        if ncam != self.num_cameras:
            raise ValueError(f"expected {self.num_cameras} cameras, got {ncam}")
        geo = self.geometry(intrinsics, cam_to_ego, image_size, (fh, fw))
        ib, icell, ic, iz, idx, bw = geo.ib, geo.icell, geo.ic, geo.iz, geo.idx, geo.bw
        n, z = self.pillars.shape[0], self.num_heights
        # The value projection is linear and bilinear sampling is linear with zero padding, so the
        # image features are projected once per pixel (not once per sample), without the bias,
        # which is added after sampling: the same values as projecting every sample.
        pixels = feats.permute(0, 1, 3, 4, 2).reshape(-1, c_img)  # (B*Ncam*h*w, C_img)
        flat = pixels @ self.value.weight.t()  # (B*Ncam*h*w, C) the value map's pixels
        bias = self.value.bias  # (C,) added to every sample's value after sampling
        # feat_logits is linear too: a sample's logit is the bilinear sample of a one-channel map.
        a, a0 = self.feat_logits.weight[0], self.feat_logits.bias[0]  # (C,), ()
        lmap = flat @ a.to(flat.dtype)  # (B*Ncam*h*w,)
        slog = (lmap[idx] * bw.to(lmap.dtype)).sum(1) + (bias @ a + a0).to(lmap.dtype)  # (V,)
        q = self.query  # (N, C)
        k = ic * z + iz  # (V,) column of the (camera, height) pair
        logits = torch.full((b, n, ncam * z), -1e4, dtype=slog.dtype, device=slog.device)
        qlog = self.query_logits(q)  # (N, Ncam*Z)
        logits = logits.index_put(
            (ib, icell, k), (qlog[icell, k] + slog).to(logits.dtype)
        )  # (B, N, Ncam*Z); invalid pairs stay -1e4 (autocast may give the logits another dtype)
        weights = torch.softmax(logits.float(), dim=-1)  # (B, N, Ncam*Z)
        w = weights[ib, icell, k]  # (V,) invalid pairs weigh 0; cells seen by no camera get 0
        with torch.autocast(flat.device.type, enabled=False):
            agg = weighted_sample_sum(flat.float(), w, geo.rows, idx, bw, b * n, geo.pattern)
            wsum = torch.zeros(b * n, device=w.device).index_add(0, geo.rows, w)  # (B*N,)
            agg = agg + wsum[:, None] * bias.float()  # (B*N, C)
        agg = agg.to(flat.dtype).reshape(b, n, -1)  # (B, N, C)
        x = self.norm1(q[None] + self.proj(agg))  # (B, N, C)
        x = self.norm2(x + self.ffn(x))  # (B, N, C)
        return x.transpose(1, 2).reshape(b, -1, self.bev_x, self.bev_y)  # (B, C, X, Y)


def bilinear_corners(
    grid: torch.Tensor, which: torch.Tensor, h: int, w: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """The four pixels and weights of bilinear samples (``grid_sample`` semantics:
    ``align_corners=False``, zero padding) of feature maps of size (h, w) stacked as rows
    ``map * h * w + y * w + x``.

    grid (V, 2) as (x, y) in [-1, 1] of the map's width and height; which (V,) the map of each
    point -> idx (V, 4) rows, weight (V, 4) (0 for a corner outside its map).
    """
    grid = grid.float()
    x = ((grid[:, 0] + 1) * w - 1) / 2  # (V,) pixel coordinates
    y = ((grid[:, 1] + 1) * h - 1) / 2
    x0, y0 = torch.floor(x), torch.floor(y)
    fx, fy = x - x0, y - y0  # (V,)
    xs = torch.stack([x0, x0 + 1, x0, x0 + 1], dim=1).long()  # (V, 4)
    ys = torch.stack([y0, y0, y0 + 1, y0 + 1], dim=1).long()  # (V, 4)
    wt = torch.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], dim=1)
    inside = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)  # (V, 4) zero padding outside
    idx = which[:, None] * (h * w) + ys.clamp(0, h - 1) * w + xs.clamp(0, w - 1)  # (V, 4)
    return idx, wt * inside


def _csr(
    crow: torch.Tensor, cols: torch.Tensor, values: torch.Tensor, size: tuple[int, int]
) -> torch.Tensor:
    """A sparse CSR matrix of ``size`` (rows' column runs given by ``crow``), built without
    torch's invariant checks and its beta warning (the indices come from ``bilinear_corners``)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Sparse CSR tensor support is in beta")
        return torch.sparse_csr_tensor(
            crow, cols.reshape(-1), values.reshape(-1), size, check_invariants=False
        )


@dataclass(frozen=True)
class SamplePattern:
    """The sparsity pattern of the (rows x pixels) matrix of ``weighted_sample_sum``: the
    (row, pixel) entries of all samples' four corners, sorted, duplicates (two samples of one row
    on the same pixel) once, as torch's sparse CSR kernels assume; and the same for its
    transpose (pixels x rows), which the backward multiplies by."""

    crow: torch.Tensor  # (R + 1,) where each row's entries start
    cols: torch.Tensor  # (U,) the pixel of each entry
    inverse: torch.Tensor  # (4V,) the entry of each corner (idx.reshape(-1) order)
    t_crow: torch.Tensor  # (P + 1,) the transpose's rows (pixels)
    t_cols: torch.Tensor  # (U,) the transpose's columns (rows)
    t_order: torch.Tensor  # (U,) the entry of each entry of the transpose
    num_rows: int  # R
    num_px: int  # P


def sample_pattern(
    rows: torch.Tensor, idx: torch.Tensor, num_rows: int, num_px: int
) -> SamplePattern:
    """The pattern of samples in output rows ``rows`` (V,), in any order, with corners ``idx``
    (V, 4) (from ``bilinear_corners``) among ``num_px`` pixels."""
    key = (rows[:, None] * num_px + idx).reshape(-1)  # (4V,) row-major entry of each corner
    uniq, inverse = torch.unique(key, sorted=True, return_inverse=True)  # (U,), (4V,)
    row, col = uniq // num_px, uniq % num_px  # (U,) each
    crow = torch.cat([row.new_zeros(1), torch.bincount(row, minlength=num_rows).cumsum(0)])
    t_order = torch.argsort(col * num_rows + row)  # (U,) the transpose's row-major order
    t_crow = torch.cat([col.new_zeros(1), torch.bincount(col, minlength=num_px).cumsum(0)])
    return SamplePattern(crow, col, inverse, t_crow, row[t_order], t_order, num_rows, num_px)


class Cameras(NamedTuple):
    """The cameras and sizes the view transformer's samples are made for: intrinsics
    (B, N_cam, 3, 3), cam_to_ego (B, N_cam, 4, 4), the image size and the feature maps' (h, w)."""

    intrinsics: torch.Tensor
    cam_to_ego: torch.Tensor
    image_size: tuple[int, int]
    feat_size: tuple[int, int]


@dataclass(frozen=True)
class SampleGeometry:
    """What the view transformer's sampling takes from the cameras alone (``ViewTransformer
    .geometry``): the valid samples, as (batch, BEV cell, camera, height) indices (V,) each, in
    BEV-cell order; their output rows (V,); their bilinear corners and weights (V, 4) on the
    stacked feature maps; the pattern of their sums."""

    cameras: Cameras  # the cameras and sizes it was made for
    ib: torch.Tensor
    icell: torch.Tensor
    ic: torch.Tensor
    iz: torch.Tensor
    rows: torch.Tensor
    idx: torch.Tensor
    bw: torch.Tensor
    pattern: SamplePattern

    def matches(self, cameras: Cameras) -> bool:
        """Whether these are the cameras and sizes it was made for (equal values), and it may be
        used here: one made under ``torch.inference_mode`` cannot be saved for a backward."""
        if self.idx.is_inference() and not torch.is_inference_mode_enabled():
            return False
        mine = self.cameras
        return (
            cameras.image_size == mine.image_size
            and cameras.feat_size == mine.feat_size
            and _same(cameras.intrinsics, mine.intrinsics)
            and _same(cameras.cam_to_ego, mine.cam_to_ego)
        )


def _same(a: torch.Tensor, b: torch.Tensor) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and a.device == b.device and torch.equal(a, b)


class _WeightedSampleSum(torch.autograd.Function):
    """out[r] = sum over the samples v of row r of w[v] * (bilinear sample v of ``flat``), as one
    sparse (rows x pixels) matrix product; no (samples, C) tensor is made, forward or backward.
    Gradients for ``flat`` and ``w`` (the corners are geometry). The matrix's pattern
    (``SamplePattern``) gives its entries; the weights of a sample's corners are summed into
    them."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: torch.autograd.function.FunctionCtx,
        flat: torch.Tensor,
        w: torch.Tensor,
        bw: torch.Tensor,
        pattern: SamplePattern,
    ) -> torch.Tensor:
        pt = pattern
        values = torch.zeros(pt.cols.shape[0], dtype=flat.dtype, device=flat.device)
        values = values.index_add(0, pt.inverse, (w[:, None] * bw).reshape(-1))  # (U,) summed
        mat = _csr(pt.crow, pt.cols, values, (pt.num_rows, pt.num_px))  # (R, P) rows x pixels
        ctx.save_for_backward(flat, bw, values)
        ctx.mat, ctx.pattern = mat, pt
        return mat @ flat  # (R, C)

    @staticmethod
    def backward(  # type: ignore[override]
        ctx: torch.autograd.function.FunctionCtx, grad: torch.Tensor
    ) -> tuple[torch.Tensor | None, ...]:
        flat, bw, values = ctx.saved_tensors  # type: ignore[attr-defined]
        pt: SamplePattern = ctx.pattern  # type: ignore[attr-defined]
        grad = grad.contiguous()  # (R, C)
        g_flat = g_w = None
        if ctx.needs_input_grad[0]:
            mat_t = _csr(pt.t_crow, pt.t_cols, values[pt.t_order], (pt.num_px, pt.num_rows))
            g_flat = mat_t @ grad  # (P, C)
        if ctx.needs_input_grad[1]:
            # d out[r] / d w[v] = bilinear sample v of flat, dotted with grad[r]: the products
            # grad @ flat.T at the matrix's entries only (a sampled matmul), then per corner.
            dots = torch.sparse.sampled_addmm(ctx.mat, grad, flat.t(), beta=0.0)  # type: ignore[attr-defined]
            g_w = (dots.values()[pt.inverse].reshape(bw.shape) * bw).sum(1)  # (V,)
        return g_flat, g_w, None, None


def weighted_sample_sum(
    flat: torch.Tensor,
    w: torch.Tensor,
    rows: torch.Tensor,
    idx: torch.Tensor,
    bw: torch.Tensor,
    num_rows: int,
    pattern: SamplePattern | None = None,
) -> torch.Tensor:
    """Weighted sums of bilinear samples, one per output row.

    flat (P, C) pixels (float32 or float64; w and bw are cast to its dtype); w (V,) sample
    weights; rows (V,) the output row of each sample, in any order; idx, bw (V, 4) from
    ``bilinear_corners`` -> (num_rows, C). ``pattern``: ``sample_pattern(rows, idx, num_rows,
    P)`` when the caller keeps it (it depends on the geometry only); made here otherwise.
    """
    if pattern is None:
        pattern = sample_pattern(rows, idx, num_rows, flat.shape[0])
    elif (pattern.num_rows, pattern.num_px) != (num_rows, flat.shape[0]):
        raise ValueError(
            f"weighted_sample_sum: the pattern is for {pattern.num_rows} rows x "
            f"{pattern.num_px} pixels, got {num_rows} x {flat.shape[0]}"
        )
    return _WeightedSampleSum.apply(flat, w.to(flat.dtype), bw.to(flat.dtype), pattern)  # type: ignore[no-any-return]


def warp_bev(
    prev_bev: torch.Tensor, cur_to_prev: torch.Tensor, half_x: float, half_y: float
) -> torch.Tensor:
    """The previous BEV resampled on the current BEV grid.

    prev_bev (B, C, X, Y); cur_to_prev (B, 4, 4) maps current ego coordinates to previous ego
    coordinates -> (B, C, X, Y) (zeros where the current cell was outside the previous range).
    """
    b, _, nx, ny = prev_bev.shape
    centres = bev_cell_centres(nx, ny, half_x, half_y).to(prev_bev.device)  # (X, Y, 2)
    r = cur_to_prev[:, :2, :2].to(prev_bev.dtype)  # (B, 2, 2)
    t = cur_to_prev[:, :2, 3].to(prev_bev.dtype)  # (B, 2)
    p = torch.einsum("bij,xyj->bxyi", r, centres.to(prev_bev.dtype)) + t[:, None, None]  # (B,X,Y,2)
    norm = torch.tensor([half_x, half_y], dtype=p.dtype, device=p.device)
    p01 = (p + norm) / (2 * norm)  # (B, X, Y, 2) in [0, 1]
    return sample_bev(prev_bev, p01).permute(0, 3, 1, 2)  # (B, C, X, Y)


class BevNeck(nn.Module):
    """``blocks`` residual blocks (3x3 conv, GroupNorm, ReLU, 3x3 conv, GroupNorm, + input, ReLU):
    forward(bev (B, C, X, Y)) -> (B, C, X, Y); with 0 blocks the identity."""

    def __init__(self, channels: int, blocks: int) -> None:
        super().__init__()
        self.blocks = nn.ModuleList(
            nn.Sequential(
                nn.Conv2d(channels, channels, 3, padding=1, bias=False),
                nn.GroupNorm(1, channels),
                nn.ReLU(),
                nn.Conv2d(channels, channels, 3, padding=1, bias=False),
                nn.GroupNorm(1, channels),
            )
            for _ in range(blocks)
        )

    def forward(self, bev: torch.Tensor) -> torch.Tensor:
        for block in self.blocks:
            bev = F.relu(bev + block(bev))  # (B, C, X, Y)
        return bev


class ConvGRU(nn.Module):
    """Convolutional GRU cell: forward(x (B, C, X, Y), h (B, C, X, Y)) -> new h (B, C, X, Y)."""

    def __init__(self, channels: int, kernel: int = 3) -> None:
        super().__init__()
        pad = kernel // 2
        self.gates = nn.Conv2d(2 * channels, 2 * channels, kernel, padding=pad)
        self.cand = nn.Conv2d(2 * channels, channels, kernel, padding=pad)

    def forward(self, x: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        zr = torch.sigmoid(self.gates(torch.cat([x, h], dim=1)))  # (B, 2C, X, Y)
        z, r = zr.chunk(2, dim=1)  # (B, C, X, Y) each
        cand = torch.tanh(self.cand(torch.cat([x, r * h], dim=1)))  # (B, C, X, Y)
        return (1 - z) * h + z * cand


class TemporalMemory(nn.Module):
    """Fuses the current BEV with the warped previous BEV.

    forward(bev (B, C, X, Y), prev_bev (B, C, X, Y) or None, cur_to_prev (B, 4, 4) or None)
    -> fused BEV (B, C, X, Y); without memory the current BEV passes through a norm only.
    """

    def __init__(self, channels: int, half_x: float, half_y: float) -> None:
        super().__init__()
        self.half_x, self.half_y = half_x, half_y
        self.gru = ConvGRU(channels)
        self.norm = nn.GroupNorm(1, channels)

    def forward(
        self,
        bev: torch.Tensor,
        prev_bev: torch.Tensor | None,
        cur_to_prev: torch.Tensor | None,
    ) -> torch.Tensor:
        if prev_bev is None or cur_to_prev is None:
            return self.norm(bev)
        warped = warp_bev(prev_bev, cur_to_prev, self.half_x, self.half_y)  # (B, C, X, Y)
        return self.norm(self.gru(bev, warped))
